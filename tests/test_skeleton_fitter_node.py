"""The skeleton_fitter node over DDS, fed features computed here from rendered studio views: a frame set
that two cameras see is fitted; one that only one camera sees gets a standing best guess before the first
fit and STATUS_LOST with the last pose after it. The input's last frame set is fitted once the input stops. Bad
calibration and malformed contours are logged and dropped, and the node keeps running. Features that come
before their camera's calibration wait for it. It asks the cameras for the frame sets it will fit."""
import math
import time

import numpy as np
import pytest
import rclpy
from common import Publisher, run_mvpose, spin_for, spin_until
from mvpose_msgs.msg import LabelledContour, Skeleton, SkinEllipseArray
from sensor_msgs.msg import Image

from mvpose_nodes.body.camera import studio_rig
from mvpose_nodes.fitting.hypotheses import HYPOTHESES_POOL
from mvpose_nodes.ros.camera_bag import frame_stamp_ns
from mvpose_nodes.ros.conversions import (calibration_messages, empty_feature_messages, feature_messages,
                                          joints_from_skeleton, optical_frame, set_stamp, stamp_ns)
from mvpose_nodes.ros.helpers import LATCHED
from mvpose_nodes.ros.params import default_skin_model_path
from mvpose_nodes.studio import scene
from mvpose_nodes.vision.features import FeatureExtractor, FeatureSettings
from mvpose_nodes.vision.skin import SkinModel

pytestmark = pytest.mark.dds

CAMERAS = (3, 5)
FEATURES = {'skin_ellipses': SkinEllipseArray, 'labelled_contour': LabelledContour}


@pytest.fixture(scope='module')
def rendered_features(cmu_walk):
    """{camera: (Camera, features.Features)} of one walking frame seen by cameras 3 and 5 at 960×540."""
    motion = cmu_walk.placed(heading=math.radians(45))
    i = len(motion.joints) // 2
    pose = scene.BodyPose(motion.joints[i], motion.toes[i], motion.hand_tips[i], motion.head_forward[i])
    extractor = FeatureExtractor(FeatureSettings(), SkinModel.load(default_skin_model_path()))
    found = {}
    shadow = scene.floor_shadow(pose, scene.Appearance())
    for camera in studio_rig((960, 540), cameras=list(CAMERAS)):
        view = scene.prepare_camera(camera)
        rendering = scene.render(view, pose, scene.Appearance(), *shadow)
        rgb, _ = scene.Realism().finish(rendering, view, camera.number, 0, 0)
        found[camera.number] = camera, extractor(rgb)
    return found


def feeding_node(name):
    """A node that records /mvpose/skeleton and publishes the CAMERAS' feature topics: (node, the Skeletons
    received, {(camera, topic): Publisher})."""
    node = rclpy.create_node(name)
    received = []
    node.create_subscription(Skeleton, '/mvpose/skeleton', received.append, LATCHED)
    publishers = {(k, topic): Publisher(node, kind, f'/cam{k}/{topic}', 10)
                  for k in CAMERAS for topic, kind in FEATURES.items()}
    return node, received, publishers


def publish_calibration(node, rendered_features, stamp):
    """Each camera's camera_info and camera_pose, latched: published at once, the fitter gets them when it
    subscribes."""
    for k, (camera, _) in rendered_features.items():
        for message, topic in zip(calibration_messages(camera, stamp), ('camera_info', 'camera_pose')):
            Publisher(node, type(message), f'/cam{k}/{topic}', LATCHED).publish(message, subscribers=0)


def test_a_frame_set_seen_by_one_camera_gets_status_lost_with_the_last_pose(rendered_features, background,
                                                                              ros_context):
    fitter = background('run', 'skeleton_fitter', '--ros-args', '-p', f'cameras:={list(CAMERAS)}')
    node, received, publishers = feeding_node('fitter_feeder')
    try:
        for publisher in publishers.values():
            publisher.wait_for_subscribers(timeout=30)
        guess, first, second = frame_stamp_ns(59), frame_stamp_ns(60), frame_stamp_ns(61)
        calibration = []
        for k, (camera, _) in rendered_features.items():
            for message, topic in zip(calibration_messages(camera, first), ('camera_info', 'camera_pose')):
                # Latched: published at once, the fitter gets it when it subscribes.
                calibration.append(Publisher(node, type(message), f'/cam{k}/{topic}', LATCHED)
                                   .publish(message, subscribers=0))
        for publisher in calibration:
            publisher.wait_for_subscribers(timeout=30)
        for stamp in (guess, first, second):
            for k, (camera, features) in rendered_features.items():
                header = Image().header
                set_stamp(header, stamp, optical_frame(k))
                if stamp in (guess, second) and k == CAMERAS[1]:   # the person is not in camera 5's view
                    messages = empty_feature_messages(header, LabelledContour.STATUS_NO_PERSON, 'no person in the image')
                else:
                    messages = feature_messages(features, header)
                for topic, message in zip(FEATURES, messages):
                    publishers[(k, topic)].publish(message)
            spin_until(node, lambda: any(stamp_ns(m.header) == stamp for m in received), 60,
                       f'a skeleton stamped {stamp}')
    finally:
        node.destroy_node()
    guessed, fitted, lost = (next(m for m in received if stamp_ns(m.header) == s) for s in (guess, first, second))
    assert guessed.status == Skeleton.STATUS_INITIALISING and 'best guess' in guessed.status_message
    assert len(joints_from_skeleton(guessed)) == 15
    assert fitted.status == Skeleton.STATUS_INITIALISING and 'best guess' not in fitted.status_message
    assert lost.status == Skeleton.STATUS_LOST and 'fewer than 2 cameras' in lost.status_message
    np.testing.assert_allclose(joints_from_skeleton(lost), joints_from_skeleton(fitted), atol=1e-9)
    code, _, err = fitter.interrupt()
    assert code == 0, err


def test_the_last_frame_set_of_the_input_is_fitted_once_the_input_stops(rendered_features, background, ros_context):
    """Issue 13 (none lost at the end of a bag): with the cameras' stamps 2 ms apart, the synchroniser can
    publish a set only once a later message proves it the narrowest, so the input's last set would wait for
    ever; once nothing has come for camera_timeout it is flushed and fitted."""
    fitter = background('run', 'skeleton_fitter', '--ros-args', '-p', f'cameras:={list(CAMERAS)}',
                        '-p', 'camera_timeout:=0.5', '-p', 'request_frames:=false')
    node, received, publishers = feeding_node('last_set_feeder')
    stamps = [frame_stamp_ns(60), frame_stamp_ns(61)]
    try:
        publish_calibration(node, rendered_features, stamps[0])
        for publisher in publishers.values():
            publisher.wait_for_subscribers(timeout=30)
        for stamp in stamps:
            for offset_ns, (k, (camera, features)) in zip((0, 2_000_000), rendered_features.items()):
                header = set_stamp(Image().header, stamp + offset_ns, optical_frame(k))
                for topic, message in zip(FEATURES, feature_messages(features, header)):
                    publishers[(k, topic)].publish(message)
        spin_until(node, lambda: len(received) == 2, 60, 'skeletons for both frame sets, the last one flushed')
    finally:
        node.destroy_node()
    assert [stamp_ns(m.header) for m in received] == [stamp + 2_000_000 for stamp in stamps], 'in order, each once'
    code, _, err = fitter.interrupt()
    assert code == 0, err


def test_skeleton_fitter_node_survives_nan_calibration_and_malformed_contours(background, ros_context):
    """Over DDS: a NaN camera_info and a contour whose arrays disagree are logged with the topic and the
    cause, and dropped; the node keeps running (it still answers Ctrl-C with exit 0)."""
    fitter = background('run', 'skeleton_fitter', '--ros-args', '-p', 'cameras:=[3, 5]')
    nan_info = ("{header: {frame_id: cam3}, width: 1920, height: 1080, distortion_model: plumb_bob, "
                "k: [.nan, 0, 960, 0, 1400, 540, 0, 0, 1], d: [0, 0, 0, 0, 0]}")
    pose = "{header: {frame_id: world}, pose: {orientation: {w: 1.0}}}"
    qos = ('--qos-durability', 'transient_local', '-w', 1, '--once')
    run_mvpose('topic', 'pub', '/cam3/camera_info', 'sensor_msgs/msg/CameraInfo', nan_info, *qos)
    run_mvpose('topic', 'pub', '/cam3/camera_pose', 'geometry_msgs/msg/PoseStamped', pose, *qos)
    run_mvpose('topic', 'pub', '/cam5/camera_info', 'sensor_msgs/msg/CameraInfo', nan_info.replace('.nan', '1400'), *qos)
    run_mvpose('topic', 'pub', '/cam5/camera_pose', 'geometry_msgs/msg/PoseStamped', pose, *qos)
    stamp = '{header: {stamp: {sec: 5}}'
    for k in (3, 5):  # one frame set whose contours have 3 pixels but 1 label
        run_mvpose('topic', 'pub', f'/cam{k}/skin_ellipses', 'mvpose_msgs/msg/SkinEllipseArray', stamp + '}',
                   '-w', 1, '--once')
        run_mvpose('topic', 'pub', f'/cam{k}/labelled_contour', 'mvpose_msgs/msg/LabelledContour',
                   stamp + ', x: [1, 2, 3], y: [1, 2, 3], labels: [1], sides: [1]}', '-w', 1, '--once')
    logged = ''.join(fitter.wait_for_stderr_line('/cam5/labelled_contour: ', timeout=60))
    code, _, err = fitter.interrupt()
    err = logged + err
    assert code == 0, err
    assert '/cam3 calibration unusable: camera_info K is not a valid intrinsic matrix' in err, err
    assert '/cam5/labelled_contour: LabelledContour x, y, labels and sides differ in length; dropped' in err, err


def test_features_that_come_before_the_calibration_wait_for_it(rendered_features, background, ros_context):
    """Issue 13: no frame set is lost at start-up because calibration came after the first images: the
    fitter holds the frame sets (calibration_wait) and fits them, in order, once it comes. With every set
    fitted (pending_frame_sets 0): by default the burst of held sets is real time's backlog, of which the
    newest is fitted (test_frame_sets_faster_than_the_fitter_skip_the_stale_ones)."""
    fitter = background('run', 'skeleton_fitter', '--ros-args', '-p', f'cameras:={list(CAMERAS)}',
                        '-p', 'calibration_wait:=30.0', '-p', 'pending_frame_sets:=0')
    node, received, publishers = feeding_node('early_features')
    stamps = [frame_stamp_ns(60), frame_stamp_ns(61)]
    try:
        for publisher in publishers.values():
            publisher.wait_for_subscribers(timeout=30)
        for stamp in stamps:
            for k, (camera, features) in rendered_features.items():
                header = set_stamp(Image().header, stamp, optical_frame(k))
                for topic, message in zip(FEATURES, feature_messages(features, header)):
                    publishers[(k, topic)].publish(message)
        for publisher in publishers.values():
            publisher.wait_for_acknowledgements(timeout=10)
        spin_for(node, 1.0)   # the features wait, unanswered
        assert received == [], 'fitted without calibration'
        publish_calibration(node, rendered_features, stamps[0])
        spin_until(node, lambda: {stamp_ns(m.header) for m in received} >= set(stamps), 60,
                   'skeletons for both frame sets held before the calibration')
    finally:
        node.destroy_node()
    assert [stamp_ns(m.header) for m in received] == stamps, 'in order, each once'
    assert received[0].status == Skeleton.STATUS_INITIALISING
    code, _, err = fitter.interrupt()
    assert code == 0, err


BURST = 8   # frame sets sent back to back, within the fitter's input queues (depth 10)


def test_frame_sets_faster_than_the_fitter_skip_the_stale_ones(rendered_features, background, ros_context):
    """Issue 14, over DDS: frame sets sent faster than the fitter fits are not queued: at most one waits,
    the older ones are skipped and said so (status_message, /diagnostics), and the newest is fitted."""
    import re
    from diagnostic_msgs.msg import DiagnosticArray
    fitter = background('run', 'skeleton_fitter', '--ros-args', '-p', f'cameras:={list(CAMERAS)}')
    node = rclpy.create_node('fast_features')
    received, diagnostics = [], []
    node.create_subscription(Skeleton, '/mvpose/skeleton', received.append, 100)
    node.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append, 100)
    publishers = {(k, topic): Publisher(node, kind, f'/cam{k}/{topic}', 10)
                  for k in CAMERAS for topic, kind in FEATURES.items()}
    stamps = [frame_stamp_ns(60 + i) for i in range(BURST + 1)]

    def send(stamp):
        for k, (camera, features) in rendered_features.items():
            header = set_stamp(Image().header, stamp, optical_frame(k))
            for topic, message in zip(FEATURES, feature_messages(features, header)):
                publishers[(k, topic)].publisher.publish(message)
    try:
        publish_calibration(node, rendered_features, stamps[0])
        for publisher in publishers.values():
            publisher.wait_for_subscribers(timeout=30)
        send(stamps[0])   # the first alone: the fitter is ready when the burst comes
        spin_until(node, lambda: received, 60, 'the first skeleton')
        for stamp in stamps[1:]:
            send(stamp)
        spin_until(node, lambda: stamp_ns(received[-1].header) == stamps[-1], 60, 'the newest frame set fitted')
        burst = received[1:]
        skipped = sum(int(m[1]) for s in burst for m in [re.search(r'(\d+) stale frame set', s.status_message)] if m)
        spin_until(node, lambda: any(v.key == 'frame sets skipped (stale)' and v.value == str(skipped)
                                     for array in diagnostics for status in array.status for v in status.values),
                   10, f'/diagnostics counting {skipped} skipped frame sets')
        # The start fitted its labellings on the hypotheses pool (fit_threads 2): its CPU is reported apart.
        pool = f'cpu/pool/{HYPOTHESES_POOL}'
        spin_until(node, lambda: any(v.key == pool and float(v.value) > 0
                                     for array in diagnostics for status in array.status for v in status.values),
                   10, f'/diagnostics reporting {pool}')
    finally:
        node.destroy_node()
    fitted = [stamp_ns(m.header) for m in burst]
    assert fitted == sorted(set(fitted)) and set(fitted) <= set(stamps[1:]), 'in order, each at most once'
    assert len(fitted) + skipped == BURST, 'every frame set fitted or counted as skipped'
    assert skipped >= 1, 'the burst came faster than the fitter'
    code, _, err = fitter.interrupt()
    assert code == 0, err


def test_the_fitter_requests_the_newest_announced_frame_set_one_at_a_time(ros_context, background):
    """Issue 14, over DDS: the fitter asks every camera for the newest frame set they announced, once
    nothing waits before its stages; while a request is unanswered it asks for nothing more, and after
    camera_timeout it gives the request up (counted on /diagnostics) and asks for the newest again,
    passing over the sets announced in between."""
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import Header
    fitter = background('run', 'skeleton_fitter', '--ros-args', '-p', f'cameras:={list(CAMERAS)}',
                        '-p', 'camera_timeout:=1.0')
    node = rclpy.create_node('fake_cameras')
    requested, diagnostics = {k: [] for k in CAMERAS}, []
    for k in CAMERAS:
        node.create_subscription(Header, f'/cam{k}/frame_request', requested[k].append, 10)
    node.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append, 100)
    announcers = {k: Publisher(node, Header, f'/cam{k}/frame_available', 10) for k in CAMERAS}
    stamps = [frame_stamp_ns(60 + i) for i in range(3)]

    def announce(stamp):
        for k, announcer in announcers.items():
            announcer.publish(set_stamp(Header(), stamp, optical_frame(k)))
    try:
        spin_until(node, lambda: all(node.count_publishers(f'/cam{k}/frame_request') for k in CAMERAS), 60,
                   "the fitter's frame_request publishers")
        spin_for(node, 0.5)
        announce(stamps[0])
        spin_until(node, lambda: all(requested.values()), 30, 'a request to every camera')
        started = time.monotonic()
        announce(stamps[1])
        announce(stamps[2])
        spin_until(node, lambda: all(len(r) == 2 for r in requested.values()), 30, 'the second request')
        waited = time.monotonic() - started
        spin_until(node, lambda: any(v.key == 'frame requests unanswered' and v.value == '1'
                                     for array in diagnostics for status in array.status for v in status.values),
                   10, '/diagnostics counting the unanswered request')
    finally:
        node.destroy_node()
    for k in CAMERAS:
        assert [stamp_ns(h) for h in requested[k]] == [stamps[0], stamps[2]], f'camera {k}: the newest, once'
        assert requested[k][0].frame_id == optical_frame(k)
    assert waited > 0.8, 'the second request waits for the first to be answered or given up'
    code, _, err = fitter.interrupt()
    assert code == 0, err


def test_a_camera_announcing_late_is_waited_for_while_others_announce(rendered_features, background, ros_context):
    """The idle flush (camera_timeout without input: a bag's end) is for input that has stopped. Between two
    frames of a slow playback, camera 3 announcing its next image counts as input, so camera 5's announcement
    of the same image 0.7 s later (within camera_timeout of camera 3's, but more than camera_timeout after
    the last features) joins the set: both cameras are asked for it, not each alone."""
    from std_msgs.msg import Header
    fitter = background('run', 'skeleton_fitter', '--ros-args', '-p', f'cameras:={list(CAMERAS)}',
                        '-p', 'camera_timeout:=1.0')
    node, _, publishers = feeding_node('late_announcer')
    requested = {k: [] for k in CAMERAS}
    for k in CAMERAS:
        node.create_subscription(Header, f'/cam{k}/frame_request', requested[k].append, 10)
    announcers = {k: Publisher(node, Header, f'/cam{k}/frame_available', 10) for k in CAMERAS}
    features_stamp, announced_stamp = frame_stamp_ns(60), frame_stamp_ns(61)
    try:
        for publisher in [*publishers.values(), *announcers.values()]:
            publisher.wait_for_subscribers(timeout=30)
        spin_until(node, lambda: all(node.count_publishers(f'/cam{k}/frame_request') for k in CAMERAS), 60,
                   "the fitter's frame_request publishers")
        for k, (_, features) in rendered_features.items():   # input has come: the idle flush is armed
            header = set_stamp(Image().header, features_stamp, optical_frame(k))
            for topic, message in zip(FEATURES, feature_messages(features, header)):
                publishers[(k, topic)].publish(message)
        spin_for(node, 0.6)
        announcers[3].publish(set_stamp(Header(), announced_stamp, optical_frame(3)))
        spin_for(node, 0.7)   # 1.3 s after the features
        announcers[5].publish(set_stamp(Header(), announced_stamp, optical_frame(5)))
        spin_until(node, lambda: any(requested.values()), 30, 'a request')
        spin_for(node, 1.5)   # a split set's second request; unanswered, a request is also asked once more
    finally:
        node.destroy_node()
    asked = {k: [stamp_ns(h) for h in requested[k]] for k in CAMERAS}
    assert asked[3] and asked[3] == asked[5] and set(asked[3]) == {announced_stamp}, asked
    code, _, err = fitter.interrupt()
    assert code == 0, err


ODD_SEGMENT = 8   # frame sets per fault in the test below
ODD_PERIOD = 0.4  # [s] between its frame sets: the fitter keeps up, also where a fault restarts it (a start fits
#                   every labelling of the body for hypothesis_frames frame sets: fitting/hypotheses.py)


@pytest.mark.timeout(180)
def test_the_fitter_stays_sane_under_odd_stamps(rendered_features, background, ros_context):
    """Issue 15, over DDS: features sent in turn with camera 5 at twice the rate, camera 5 300 ms late,
    camera 3 stamped back in time once, camera 5 sending every stamp twice, and the clock jumping an hour
    ahead: the fitter keeps fitting (the frame sets at the end of each fault all get a skeleton, in order, each
    once) and stops cleanly on Ctrl-C. (The synchroniser's queues under the same faults: test_sync.py.)"""
    fitter = background('run', 'skeleton_fitter', '--ros-args', '-p', f'cameras:={list(CAMERAS)}',
                        '-p', 'request_frames:=false')
    node, received, publishers = feeding_node('odd_stamps_feeder')
    faults = ['twice the rate', '300 ms late', 'stamps going back', 'duplicated stamps', 'clock jump']
    late = []   # camera 5's messages held back: (send after this many more frame sets, stamp)

    def send(k, stamp):
        header = set_stamp(Image().header, stamp, optical_frame(k))
        for topic, message in zip(FEATURES, feature_messages(rendered_features[k][1], header)):
            publishers[(k, topic)].publisher.publish(message)

    expected = []   # the stamps that must get a skeleton: each fault's last frame sets
    try:
        publish_calibration(node, rendered_features, frame_stamp_ns(60))
        for publisher in publishers.values():
            publisher.wait_for_subscribers(timeout=30)
        frame = 60
        for fault in faults:
            for i in range(ODD_SEGMENT):
                stamp = frame_stamp_ns(frame) + (3600 * 10**9 if fault == 'clock jump' else 0)
                send(3, stamp - (5 * 40_000_000 if fault == 'stamps going back' and i == 0 else 0))
                if fault == '300 ms late':
                    late.append([3, stamp])
                else:
                    send(5, stamp)
                if fault == 'twice the rate':
                    send(5, stamp + 20_000_000)
                if fault == 'duplicated stamps':
                    send(5, stamp)
                for entry in late:
                    entry[0] -= 1
                    if entry[0] < 0:
                        send(5, entry[1])
                late[:] = [entry for entry in late if entry[0] >= 0]
                spin_for(node, ODD_PERIOD)
                if i >= ODD_SEGMENT - 3 and fault not in ('300 ms late',):
                    expected.append(stamp)
                frame += 1
        for entry in late:
            send(5, entry[1])
        spin_until(node, lambda: set(expected) <= {stamp_ns(m.header) for m in received}, 60,
                   'a skeleton for the last frame sets of each fault')
    finally:
        node.destroy_node()
    stamps = [stamp_ns(m.header) for m in received]
    assert len(stamps) == len(set(stamps)), 'each frame set once'
    code, _, err = fitter.interrupt()
    assert code == 0, err
    assert 'went back in time' in err
