"""bag record / play / info and topic echo, run as the separate processes a user starts,
talking over DDS on loopback; bags checked with the independent `rosbags` reader. Their one-line
errors on bad input that needs no recorded bag: test_front_door.py."""
import time
from pathlib import Path

import pytest
import yaml
from common import ROOT, Background, assert_one_line_error, run_mvpose, spin_for, spin_until
from mvpose_msgs.msg import Skeleton
from rosbags.highlevel import AnyReader
from rosgraph_msgs.msg import Clock
from samples import sample_skeleton
from sensor_msgs.msg import CameraInfo

from mvpose_nodes.io.bagfile import BagReader
from mvpose_nodes.io.msgdict import set_message_fields

pytestmark = pytest.mark.dds

SKELETON_TOPIC = '/test/skeleton'
CAMERA_INFO_TOPIC = '/cam3/camera_info'
SKELETON_TYPE = 'mvpose_msgs/msg/Skeleton'
FRAMES = 5
# Play only once this process's subscriptions are matched, so that none of the first messages is lost.
WAIT = ('--wait-for-subscribers',)

# Publishes FRAMES Skeletons (seeds 0..4) and one latched CameraInfo once a subscriber matched.
PUBLISHER_SCRIPT = f'''
import sys
sys.path.insert(0, {str(Path(__file__).parent)!r})
import rclpy
from rclpy.qos import QoSProfile, DurabilityPolicy
from sensor_msgs.msg import CameraInfo
from mvpose_msgs.msg import Skeleton
from common import Publisher
from samples import sample_skeleton
rclpy.init()
node = rclpy.create_node('test_publisher')
skeletons = Publisher(node, Skeleton, {SKELETON_TOPIC!r}, 10)
infos = Publisher(node, CameraInfo, {CAMERA_INFO_TOPIC!r}, QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
skeletons.wait_for_subscribers(timeout=20)
infos.publish(CameraInfo(width=1920, height=1080, distortion_model='plumb_bob'), timeout=20)
skeletons.publish(*(sample_skeleton(seed, stamp_ns=1_700_000_000_000_000_000 + seed * 40_000_000)
                    for seed in range({FRAMES})), interval=0.04)
skeletons.wait_for_acknowledgements()
infos.wait_for_acknowledgements()
'''


@pytest.fixture(scope='module')
def recorded_bag(tmp_path_factory):
    """A bag recorded live by `bag record` from another process's publications."""
    bag = tmp_path_factory.mktemp('bags') / 'recorded'
    script = tmp_path_factory.mktemp('scripts') / 'publish.py'
    script.write_text(PUBLISHER_SCRIPT)
    recorder = Background('bag', 'record', '--topics', SKELETON_TOPIC, CAMERA_INFO_TOPIC, '-o', bag)
    try:
        recorder.wait_for_stderr_line('writing')
        run_mvpose('exec', 'python', script, timeout=60)
        code, _, err = recorder.interrupt()
    finally:
        recorder.kill()
    assert code == 0, err
    return bag


def echoed_skeletons(stdout):
    """The Skeletons a `topic echo` printed, rebuilt as messages."""
    documents = [d for d in yaml.safe_load_all(stdout) if d]
    return [set_message_fields(Skeleton(), d) for d in documents]


def test_record_play_echo_round_trip(recorded_bag, background):
    echo = background('topic', 'echo', SKELETON_TOPIC, SKELETON_TYPE, '--count', FRAMES, '--timeout', 60)
    run_mvpose('bag', 'play', recorded_bag, '--topics', SKELETON_TOPIC, *WAIT)
    code, out, err = echo.finish(timeout=60)
    assert code == 0, err
    assert echoed_skeletons(out) == [sample_skeleton(seed, 1_700_000_000_000_000_000 + seed * 40_000_000)
                                     for seed in range(FRAMES)]


def test_recorded_bag_conforms_for_rosbags(recorded_bag):
    expected = [sample_skeleton(seed, 1_700_000_000_000_000_000 + seed * 40_000_000) for seed in range(FRAMES)]
    with AnyReader([recorded_bag]) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        assert types == {SKELETON_TOPIC: SKELETON_TYPE, CAMERA_INFO_TOPIC: 'sensor_msgs/msg/CameraInfo'}
        counts = {c.topic: c.msgcount for c in reader.connections}
        assert counts == {SKELETON_TOPIC: FRAMES, CAMERA_INFO_TOPIC: 1}
        skeletons = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages()
                     if c.topic == SKELETON_TOPIC]
    for got, want in zip(skeletons, expected):
        assert list(got.joint_names) == list(want.joint_names)
        assert [(p.position.x, p.position.y, p.position.z, p.orientation.w) for p in got.joints] == \
               [(p.position.x, p.position.y, p.position.z, p.orientation.w) for p in want.joints]
        assert got.parameters.tolist() == list(want.parameters)
        assert [(s.name, s.cost, s.evaluations, list(s.cameras), s.fitted) for s in got.stages] == \
               [(s.name, s.cost, s.evaluations, list(s.cameras), s.fitted) for s in want.stages]
        assert (got.header.stamp.sec, got.header.stamp.nanosec, got.status, got.fit_time) == \
               (want.header.stamp.sec, want.header.stamp.nanosec, want.status, want.fit_time)


def test_recorded_metadata_is_rosbag2(recorded_bag):
    metadata = yaml.safe_load((recorded_bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert metadata['version'] == 9 and metadata['storage_identifier'] == 'mcap'
    assert metadata['message_count'] == FRAMES + 1
    topics = {t['topic_metadata']['name']: t for t in metadata['topics_with_message_count']}
    assert topics[CAMERA_INFO_TOPIC]['topic_metadata']['offered_qos_profiles'][0]['durability'] == 'transient_local'
    assert topics[SKELETON_TOPIC]['topic_metadata']['type_description_hash'].startswith('RIHS01_')
    assert (recorded_bag / metadata['relative_file_paths'][0]).is_file()


def test_bag_info(recorded_bag):
    out = run_mvpose('bag', 'info', recorded_bag).stdout
    assert f'Messages:          {FRAMES + 1}' in out
    rows = {line.split('|')[0].split()[-1]: [cell.strip() for cell in line.split('|')[1:]]
            for line in out.splitlines() if line.strip().startswith('Topic:')}
    assert rows[SKELETON_TOPIC] == [f'Type: {SKELETON_TYPE}', f'Count: {FRAMES}', 'Serialization Format: cdr']
    assert rows[CAMERA_INFO_TOPIC][:2] == ['Type: sensor_msgs/msg/CameraInfo', 'Count: 1']


def receive_during_play(topics, play_args, stop_after=None):
    """Subscribe in this process to `topics`, run `bag play ARGS`, return {topic: [messages]}.

    With `stop_after` = (topic, n), the player is interrupted once n messages arrived on topic
    (for --loop, which never ends by itself)."""
    import rclpy
    node = rclpy.create_node('test_receiver')
    received = {topic: [] for topic in topics}
    for topic in topics:
        node.create_subscription(message_class_of(topic), topic, received[topic].append, 100)
    player = Background('bag', 'play', *play_args)
    try:
        spin_until(node, lambda: player.process.poll() is not None
                   or (stop_after and len(received[stop_after[0]]) >= stop_after[1]), 60, f'bag play {play_args} to end')
        if player.process.poll() is None:   # stop_after reached
            player.interrupt()
        spin_for(node, 0.5)
        code, _, err = player.finish()
        assert code == 0 or (stop_after and code == 130), err
    finally:
        player.kill()
        node.destroy_node()
    return received


def message_class_of(topic):
    return {SKELETON_TOPIC: Skeleton, CAMERA_INFO_TOPIC: CameraInfo, '/clock': Clock}[topic]


def test_bare_mcap_plays(recorded_bag, ros_context):
    mcap_file = next(recorded_bag.glob('*.mcap'))
    received = receive_during_play([SKELETON_TOPIC], [mcap_file, *WAIT, '--topics', SKELETON_TOPIC])
    assert [m.status_message for m in received[SKELETON_TOPIC]] == [f'sample {seed}' for seed in range(FRAMES)]


def test_plain_play_loses_nothing_to_a_subscriber_already_running(recorded_bag, ros_context):
    """Issue 15: without --wait-for-subscribers or --delay, play starts once the subscribers already
    running have found its new publishers (discovery settled), so none of the first messages is lost."""
    received = receive_during_play([SKELETON_TOPIC], [recorded_bag, '--topics', SKELETON_TOPIC])
    assert [m.status_message for m in received[SKELETON_TOPIC]] == [f'sample {s}' for s in range(FRAMES)]


def test_play_says_how_many_messages_nobody_received(recorded_bag, background, ros_context):
    """Issue 15: messages played before a topic's first subscriber matched are counted and named at the
    end, not lost silently; the subscriber gets all the others."""
    rate = 0.02   # the skeletons 2 s apart
    with AnyReader([recorded_bag]) as reader:   # the bag starts with its CameraInfo, received before them
        first = min(t for c, t, _ in reader.messages() if c.topic == SKELETON_TOPIC)
        lead = (first - reader.start_time) / 1e9 / rate
    player = background('bag', 'play', recorded_bag, '--topics', SKELETON_TOPIC, '--rate', rate)
    player.wait_for_stderr_line('[play] playing')
    time.sleep(lead + 0.5)   # the first skeleton has gone out, to nobody
    echo = background('topic', 'echo', SKELETON_TOPIC, SKELETON_TYPE, '--field', 'status_message')
    code, _, err = player.finish(timeout=60)
    assert code == 0, err
    _, out, _ = echo.interrupt()
    received = [line for line in out.splitlines() if line.startswith('sample')]
    unheard = FRAMES - len(received)
    assert unheard >= 1 and received == [f'sample {s}' for s in range(unheard, FRAMES)], out
    assert (f'[play] warning: {unheard} messages ({unheard} on {SKELETON_TOPIC}) were published before any '
            'subscriber had matched their topic') in err, err


def test_play_start_offset_and_topics(recorded_bag, ros_context):
    bag = BagReader(recorded_bag)
    skeleton_times = [t for _, t, _ in bag.messages(topics=[SKELETON_TOPIC])]
    offset = (skeleton_times[2] - bag.start_ns) / 1e9 - 0.001  # just before the third skeleton
    received = receive_during_play([SKELETON_TOPIC, CAMERA_INFO_TOPIC],
                                   [recorded_bag, *WAIT, '--topics', SKELETON_TOPIC, '--start-offset', offset])
    assert [m.status_message for m in received[SKELETON_TOPIC]] == [f'sample {s}' for s in range(2, FRAMES)]
    assert received[CAMERA_INFO_TOPIC] == []


def test_play_loop_starts_again(recorded_bag, ros_context):
    received = receive_during_play([SKELETON_TOPIC],
                                   [recorded_bag, *WAIT, '--loop', '--topics', SKELETON_TOPIC],
                                   stop_after=(SKELETON_TOPIC, 2 * FRAMES))
    names = [m.status_message for m in received[SKELETON_TOPIC]]
    assert names[:2 * FRAMES] == [f'sample {s}' for s in range(FRAMES)] * 2


def test_late_subscriber_gets_calibration(recorded_bag, background, ros_context):
    """camera_info is latched on playback: a subscriber that starts after it was played still gets it."""
    player = background('bag', 'play', recorded_bag, '--topics', CAMERA_INFO_TOPIC, SKELETON_TOPIC,
                        '--loop', '--rate', 0.05)
    time.sleep(3.0)  # the CameraInfo (first message) has been published by now, to nobody
    echo = run_mvpose('topic', 'echo', CAMERA_INFO_TOPIC, '--once', '--field', 'width', '--timeout', 30)
    assert echo.stdout.strip().splitlines()[0] == '1920'
    player.interrupt()


def test_play_publishes_clock(recorded_bag, ros_context):
    received = receive_during_play(['/clock', SKELETON_TOPIC],
                                   [recorded_bag, *WAIT, '--topics', SKELETON_TOPIC, '--clock', 100])
    stamps = [m.clock.sec * 10**9 + m.clock.nanosec for m in received['/clock']]
    assert len(stamps) >= 3 and stamps == sorted(stamps)
    bag = BagReader(recorded_bag)
    assert bag.start_ns <= stamps[0] and stamps[-1] <= bag.end_ns


# ---- bad input: one line, non-zero exit, no traceback ------------------------------------------

def test_mcap_cut_inside_its_header_is_one_line_error(recorded_bag, tmp_path):
    data = next(recorded_bag.glob('*.mcap')).read_bytes()
    truncated = tmp_path / 'truncated.mcap'
    truncated.write_bytes(data[:12])
    for verb in ('info', 'play'):
        assert_one_line_error(run_mvpose('bag', verb, truncated, check=False), str(truncated), 'truncated')


# ---- durable recording: a recorder killed at any moment -----------------------------------------

KILL_TOPIC = '/test/kill{trial}/image_raw/compressed'   # a topic per trial: a killed recorder's subscription
                                                          # stays matched until its lease runs out
KILL_RATE = 25.0          # [Hz] a camera's
KILL_SECONDS = 10.0       # the longest a trial records
KILL_TRIALS = 5
# A message is on the disk at the recorder's next flush (bag.FLUSH_PERIOD, 1 s) after it came; it
# comes within this much of being published (DDS and the recorder's executor) on this 2-core machine.
DELIVERY_SLACK = 0.2      # [s]
# Each killed recorder is a DDS participant of its own id (its Fast DDS profile: config/fastdds.xml with
# <participantID>), so none reuses the shared-memory port of one killed before it. A participant SIGKILLed
# leaves its port behind; the next to take the same id finds it a zombie and makes it again, while a writer
# that lived on (this test's publisher) may keep the old one, and the new recorder then gets that writer's
# messages late or never (eProsima/Fast-DDS#5053, #4728; measured here with one publisher living on: reusing
# the ids, a recorder's first message reached the disk 0.7-9.9 s after the match, mostly 2.7-3.5 s, and 3 of 58
# recorders got nothing within 12-15 s; with ids of their own, 0.5-0.9 s, and 0 of 45; docs/commands.md).
# This test is about the recorder's file, not Fast DDS's recovery.
KILLED_PARTICIPANT_IDS = 60   # the first; well above the ids the automatic choice gives a test's few participants
FASTDDS_PROFILE = ROOT / 'ros_ws' / 'src' / 'mvpose_nodes' / 'config' / 'fastdds.xml'


def own_participant_profile(folder, participant_id):
    """The environment of a process whose DDS participant has `participant_id`: a copy of
    config/fastdds.xml with <participantID> written into `folder`."""
    text = FASTDDS_PROFILE.read_text()
    assert '<rtps>' in text
    profile = folder / f'participant{participant_id}.xml'
    profile.write_text(text.replace('<rtps>', f'<rtps><participantID>{participant_id}</participantID>', 1))
    return {'FASTRTPS_DEFAULT_PROFILES_FILE': str(profile)}


def jpeg_images(count):
    """`count` distinct 1080p JPEGs [bytes] (a gradient with the index drawn), as a camera sends them."""
    import cv2
    import numpy as np
    ramp = np.linspace(0, 255, 1920, dtype=np.uint8)
    images = []
    for index in range(count):
        frame = np.dstack([np.tile(ramp, (1080, 1)), np.full((1080, 1920), 7 * index % 256, np.uint8),
                           np.tile(ramp[::-1], (1080, 1))])
        cv2.putText(frame, str(index), (800, 600), cv2.FONT_HERSHEY_SIMPLEX, 8, (255, 255, 255), 12)
        images.append(cv2.imencode('.jpg', frame, [cv2.IMWRITE_JPEG_QUALITY, 90])[1].tobytes())
    return images


def test_unfinished_file_gives_back_every_complete_chunk_and_reindex_finishes_it(tmp_path):
    """A BagWriter left unclosed (its process killed) after three flushes of 10 messages and 5 more
    unflushed, then its file cut at every byte of its last chunk: BagReader reads exactly the messages
    of the complete chunks, byte-exact; `bag reindex` writes them into a finished bag."""
    import shutil
    from mvpose_nodes.io.bagfile import BagWriter, reindex
    writer = BagWriter(tmp_path / 'live')
    live = tmp_path / 'live' / 'live_0.mcap'
    writer.add_topic('/t', 'std_msgs/msg/String')
    payloads = [bytes([i]) * (100 + i) for i in range(35)]
    sizes = []
    for index, payload in enumerate(payloads):
        writer.write('/t', payload, 1_000 + index)
        if index % 10 == 9:
            writer.flush()
            sizes.append(live.stat().st_size)
    data = live.read_bytes()
    assert len(data) == sizes[-1]             # the 5 unflushed messages are not on the disk
    counts = []
    for cut in [*range(sizes[1], sizes[2], 7), sizes[2]]:
        bag = tmp_path / f'cut{cut}'
        shutil.copytree(tmp_path / 'live', bag)
        (bag / 'live_0.mcap').write_bytes(data[:cut])
        reader = BagReader(bag)
        recovered = [bytes(d) for _, _, d in reader.messages()]
        assert recovered == payloads[:len(recovered)], cut
        assert reader.unfinished[bag / 'live_0.mcap'].messages == len(recovered)
        counts.append(len(recovered))
    # Cut inside the third chunk: the first two; once it is complete (its indexes may still be cut): all three.
    assert counts[0] == 20 and counts[-1] == 30 and set(counts) == {20, 30} and counts == sorted(counts)
    assert reindex(bag).messages == 30
    finished = BagReader(bag)
    assert not finished.unfinished and finished.message_count == 30
    assert [bytes(d) for _, _, d in finished.messages()] == payloads[:30]


@pytest.mark.timeout(240)
def test_recorder_killed_at_random_moments_loses_at_most_its_last_second(tmp_path, ros_context):
    """Issue 15: `bag record` of 1080p JPEGs at 25 Hz, SIGKILLed 2-10 s after its first message reached the
    disk (5 seeded moments): the bag opens (`bag info` says it is unfinished), it holds every message published more than
    a flush period (plus DELIVERY_SLACK) before the kill, byte-exact and in order, and `bag reindex`
    finishes it into a bag the independent rosbags reader reads. Each recorder has a DDS participant id of its
    own (KILLED_PARTICIPANT_IDS)."""
    import random
    import signal
    import rclpy
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import CompressedImage
    from mvpose_nodes.tools.bag import FLUSH_PERIOD

    images = jpeg_images(25)
    # Kills 2-10 s after the first message reached the disk. Counted from the publisher's first message
    # instead, a kill 2.4 s in found nothing on the disk in 2 of 4 whole-suite runs (the recorder not yet
    # receiving: issue 17's start-up race), and 1.4 s in once before.
    moments = random.Random(15).sample([m / 10 for m in range(20, 101)], KILL_TRIALS)
    node = rclpy.create_node('test_kill_publisher')
    try:
        for trial, moment in enumerate(moments):
            bag = tmp_path / f'killed{trial}'
            topic = KILL_TOPIC.format(trial=trial)
            publisher = node.create_publisher(CompressedImage, topic, 100)
            recorder = Background('bag', 'record', '--topics', topic, '-o', bag,
                                  environment=own_participant_profile(tmp_path, KILLED_PARTICIPANT_IDS + trial))
            try:
                spin_until(node, lambda: publisher.get_subscription_count() > 0, 30, 'the recorder to subscribe')
                # The moment counts from the first message on the disk: the recorder's start (its subscription
                # matching, issue 17) is not what this test measures.
                sent, started, recording = [], time.monotonic(), None
                while recording is None or time.monotonic() - recording < moment:
                    index = len(sent)
                    message = CompressedImage(format='jpeg', data=images[index % len(images)])
                    message.header.stamp.sec, message.header.stamp.nanosec = 1, index
                    publisher.publish(message)
                    sent.append(time.monotonic())
                    if recording is None and index % 5 == 4 and recorded_anything(bag):
                        recording = time.monotonic()
                    assert time.monotonic() - started < 60, 'nothing recorded within 60 s'
                    spin_for(node, max(0.0, started + (index + 1) / KILL_RATE - time.monotonic()))
                killed = time.monotonic()
                recorder.process.send_signal(signal.SIGKILL)
                recorder.process.wait(timeout=10)
            finally:
                recorder.kill()
            info = run_mvpose('bag', 'info', bag).stdout
            assert 'Unfinished:' in info, info
            # The recorder stores the CDR as DDS delivered it, which may end in alignment padding.
            recovered = [deserialize_message(bytes(data), CompressedImage) for _, _, data in BagReader(bag).messages()]
            assert [(m.header.stamp.nanosec, bytes(m.data)) for m in recovered] == \
                [(index, images[index % len(images)]) for index in range(len(recovered))], f'trial {trial}'
            must_have = sum(1 for t in sent if t < killed - FLUSH_PERIOD - DELIVERY_SLACK)
            assert len(recovered) >= must_have, (trial, moment, len(recovered), must_have, len(sent))
            print(f'trial {trial}: killed {moment:.1f} s in, {len(sent)} published, {len(recovered)} recovered '
                  f'(at least {must_have} required)')
            result = run_mvpose('bag', 'reindex', bag).stdout
            assert f'reindexed {bag}: {len(recovered)} messages on ' in result, result
            with AnyReader([bag]) as reader:
                assert [bytes(reader.deserialize(raw, connection.msgtype).data)
                        for connection, _, raw in reader.messages()] == [bytes(m.data) for m in recovered]
            assert 'Unfinished:' not in run_mvpose('bag', 'info', bag).stdout
    finally:
        node.destroy_node()


def recorded_anything(bag):
    """Whether a bag being recorded has a message on the disk yet."""
    from mvpose_nodes.io.bagfile import BagError
    try:
        return BagReader(bag).message_count > 0
    except BagError:   # not even its header written yet
        return False


@pytest.mark.timeout(180)
def test_recorder_subscribes_to_a_new_topic_at_once(tmp_path, ros_context):
    """Issue 17: the recorder running, a publisher of a named topic made, and 20 messages published (20 Hz,
    reliable, depth 100) from 2 s after: every one is recorded. Then a publisher on each of 50 more named
    topics, one after another: how long the recorder took to subscribe to each (to be matched by the
    publisher) is printed, the note's distribution; it excludes finding a new process, which the
    participant announcements of config/fastdds.xml bound."""
    import numpy as np
    import rclpy
    from rclpy.serialization import deserialize_message
    bag, topic = tmp_path / 'bag', '/check'
    trial_topics = [f'/check_{trial}' for trial in range(50)]
    recorder = Background('bag', 'record', '--topics', topic, *trial_topics, '-o', bag)
    node = rclpy.create_node('late_publisher')
    try:
        recorder.wait_for_stderr_line('writing')
        time.sleep(2.0)   # the recorder settled, as a user starts it first
        publisher = node.create_publisher(Skeleton, topic, 100)
        spin_for(node, 2.0)
        for seed in range(20):
            publisher.publish(sample_skeleton(seed))
            spin_for(node, 0.05)
        delays = []
        for trial_topic in trial_topics:
            made = time.monotonic()
            probe = node.create_publisher(Skeleton, trial_topic, 100)
            spin_until(node, lambda: probe.get_subscription_count() > 0, 10, f'the recorder subscribing {trial_topic}')
            delays.append(time.monotonic() - made)
        spin_for(node, 0.5)
        code, _, err = recorder.interrupt()
    finally:
        node.destroy_node()
        recorder.kill()
    assert code == 0 and 'may have been missed' not in err, err
    recorded = [deserialize_message(bytes(data), Skeleton) for _, _, data in BagReader(bag).messages([topic])]
    assert recorded == [sample_skeleton(seed) for seed in range(20)]
    print(f'\nthe recorder subscribed to a new topic in {np.percentile(delays, 50) * 1000:.0f} ms (median), '
          f'{np.percentile(delays, 95) * 1000:.0f} ms (95th percentile), {max(delays) * 1000:.0f} ms (most) '
          f'of {len(delays)} trials')


@pytest.mark.timeout(120)
def test_recorder_counts_the_messages_published_before_it_subscribed(tmp_path, background, ros_context):
    """10 messages published before the recorder exists (volatile: nobody gets them), then 10 after it
    subscribed: 10 recorded, and the 10 before are counted at the end."""
    import rclpy
    bag, topic = tmp_path / 'bag', '/early'
    node = rclpy.create_node('early_publisher')
    try:
        publisher = node.create_publisher(Skeleton, topic, 100)
        for seed in range(10):
            publisher.publish(sample_skeleton(seed))
        recorder = background('bag', 'record', '--topics', topic, '-o', bag)
        spin_until(node, lambda: publisher.get_subscription_count() > 0, 30, 'the recorder subscribing')
        for seed in range(10, 20):
            publisher.publish(sample_skeleton(seed))
            spin_for(node, 0.05)
        spin_for(node, 1.0)
        code, _, err = recorder.interrupt()
    finally:
        node.destroy_node()
    assert code == 0, err
    assert f'[record] warning: 10 messages may have been missed before the subscription matched or on the way ' \
           f'(10 on {topic})' in err, err
    assert BagReader(bag).message_count == 10


def test_unknown_topic_in_bag_is_one_line_error(recorded_bag):
    assert_one_line_error(run_mvpose('bag', 'play', recorded_bag, '--topics', '/nope', check=False), '/nope')


def test_record_refuses_existing_output(recorded_bag):
    assert_one_line_error(run_mvpose('bag', 'record', '--all', '-o', recorded_bag, check=False), 'already exists')
