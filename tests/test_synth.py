"""`./mvpose synth`: the synthetic i3DPost-like studio's bags (the walk, the standing clip, the marker suit
with its scripted occlusions), the preview and the i3DPost importer round trip.

Bags here are small (480×270, a few frames) so that they are made in seconds; the geometry is
the same as at 1080p because the rig's focal length scales with the width. These tests run synth
themselves (not the synth_bag fixture): the command is what they test, and two runs are compared."""
import cv2
import numpy as np
import pytest
from common import assert_one_line_error, run_mvpose
from rclpy.serialization import deserialize_message
from rosbags.highlevel import AnyReader
from test_marker_synth import red

from mvpose_nodes.io.bagfile import BagReader
from mvpose_nodes.body.model import JOINT_INDEX, JOINT_NAMES
from mvpose_nodes.ros.camera_bag import (GROUND_TRUTH_TOPIC, MARKER_CENTRES_TOPIC, camera_topics, frame_number_of,
                                         frame_sets)
from mvpose_nodes.io.interfaces import message_class
from mvpose_nodes.ros.conversions import camera_from_messages, image_from_compressed, joints_from_skeleton, stamp_ns
from mvpose_nodes.studio.scene import SKIN_BIT

pytestmark = pytest.mark.cli

CAMERAS = (3, 5, 7)
FRAMES = (60, 63)
SMALL = ('--resolution', '480x270', '--frames', f'{FRAMES[0]}-{FRAMES[1]}', '--cameras', *CAMERAS)


@pytest.fixture(scope='module')
def synth_bags(tmp_path_factory):
    """A small synthetic bag with lens distortion, written also in the i3DPost layout, its import,
    and a second bag from the same seed."""
    root = tmp_path_factory.mktemp('synth')
    run_mvpose('synth', *SMALL, '--distortion', -0.05, '-o', root / 'direct', '--i3dpost-layout', root / 'layout',
               timeout=300)
    run_mvpose('synth', *SMALL, '--distortion', -0.05, '-o', root / 'again', timeout=300)
    run_mvpose('import-i3dpost', root / 'layout', '--cameras', *CAMERAS, '--frames', f'{FRAMES[0]}-{FRAMES[1]}',
               '-o', root / 'imported', timeout=300)
    return root


def read_all(bag_path):
    """{topic: [(log time, message)]} of a bag, deserialised with the installed types."""
    bag = BagReader(bag_path)
    contents = {}
    for info, log_time, data in bag.messages():
        contents.setdefault(info.name, []).append((log_time, deserialize_message(data, message_class(info.type))))
    return contents


def cameras_of(contents):
    return {k: camera_from_messages(k, contents[camera_topics(k)['info']][0][1], contents[camera_topics(k)['pose']][0][1])
            for k in CAMERAS}


def test_rosbags_reads_the_synthetic_bag(synth_bags):
    frames = FRAMES[1] - FRAMES[0] + 1
    expected = {GROUND_TRUTH_TOPIC: ('mvpose_msgs/msg/Skeleton', frames)}
    for k in CAMERAS:
        topics = camera_topics(k)
        expected[topics['image']] = ('sensor_msgs/msg/CompressedImage', frames)
        expected[topics['labels']] = ('sensor_msgs/msg/CompressedImage', frames)
        expected[topics['info']] = ('sensor_msgs/msg/CameraInfo', 1)
        expected[topics['pose']] = ('geometry_msgs/msg/PoseStamped', 1)
    with AnyReader([synth_bags / 'direct']) as reader:
        found = {c.topic: (c.msgtype, c.msgcount) for c in reader.connections}
        first = {}
        for connection, timestamp, raw in reader.messages():
            first.setdefault(connection.topic, (timestamp, reader.deserialize(raw, connection.msgtype)))
    assert found == expected
    info_time, info = first[camera_topics(3)['info']]
    assert info_time < first[camera_topics(3)['image']][0], 'calibration must come before the first image'
    assert (info.width, info.height, info.distortion_model) == (480, 270, 'plumb_bob')
    assert info.header.frame_id == 'cam3_optical_frame' and first[camera_topics(3)['pose']][1].header.frame_id == 'world'
    skeleton = first[GROUND_TRUTH_TOPIC][1]
    assert list(skeleton.joint_names) == list(JOINT_NAMES) and skeleton.header.frame_id == 'world'


def test_ground_truth_joints_land_on_the_rendered_person(synth_bags):
    contents = read_all(synth_bags / 'direct')
    cameras = cameras_of(contents)
    skeletons = {stamp_ns(m.header): joints_from_skeleton(m) for _, m in contents[GROUND_TRUTH_TOPIC]}
    checked = 0
    for k in CAMERAS:
        for (_, image_msg), (_, label_msg) in zip(contents[camera_topics(k)['image']], contents[camera_topics(k)['labels']]):
            stamp = stamp_ns(image_msg.header)
            image, labels = image_from_compressed(image_msg), image_from_compressed(label_msg)
            pixels, depth = cameras[k].project(skeletons[stamp])
            assert np.all(depth > 0)
            for name, (x, y) in zip(JOINT_NAMES, pixels):
                column, row = int(round(x)), int(round(y))
                assert 0 <= column < 480 and 0 <= row < 270, f'{name} off camera {k}'
                # The head joint is the vertex, on the outline; every other joint is inside the body.
                reach = 2 if name == 'head' else 0
                window = labels[max(row - reach, 0):row + reach + 1, max(column - reach, 0):column + reach + 1]
                assert window.any(), f'{name} of frame {frame_number_of(stamp)} misses the person in camera {k}'
                if name != 'head':
                    r, g, b = image[row, column].astype(int)
                    assert not (b > r + 40 and b > g + 40), f'{name} projects onto blue studio in camera {k}'
                checked += 1
    assert checked == len(CAMERAS) * (FRAMES[1] - FRAMES[0] + 1) * len(JOINT_NAMES)


def test_label_masks_mark_skin_only_where_skin_shows(synth_bags):
    contents = read_all(synth_bags / 'direct')
    labels = image_from_compressed(contents[camera_topics(5)['labels']][0][1])
    image = image_from_compressed(contents[camera_topics(5)['image']][0][1]).astype(int)
    skin, person = (labels & SKIN_BIT) > 0, labels > 0
    assert 0 < skin.sum() < 0.4 * person.sum()
    # Skin is reddish and bright; the shirt is red but darker, the trousers dark grey.
    core = cv2.erode(skin.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    assert np.median(image[core][:, 0] - image[core][:, 2]) > 20


def test_same_seed_gives_the_same_bag_and_another_seed_does_not(synth_bags, tmp_path):
    # Messages, not CDR bytes, are compared: the serialiser leaves alignment padding unset.
    assert read_all(synth_bags / 'direct') == read_all(synth_bags / 'again')
    run_mvpose('synth', *SMALL, '--distortion', -0.05, '--seed', 1, '-o', tmp_path / 'other', timeout=300)
    image_topic = camera_topics(3)['image']
    other, same = read_all(tmp_path / 'other')[image_topic], read_all(synth_bags / 'direct')[image_topic]
    assert [t for t, _ in other] == [t for t, _ in same]
    assert any(a.data != b.data for (_, a), (_, b) in zip(other, same))


def test_import_reproduces_the_directly_written_bag(synth_bags):
    direct, imported = read_all(synth_bags / 'direct'), read_all(synth_bags / 'imported')
    for k in CAMERAS:
        topics = camera_topics(k)
        for kind in ('info', 'pose'):
            assert len(imported[topics[kind]]) == 1
        a, b = cameras_of(direct)[k], cameras_of(imported)[k]
        assert np.allclose(a.K, b.K, atol=1e-6) and np.allclose(a.D, b.D, atol=1e-6)
        assert np.allclose(a.R, b.R, atol=1e-6) and np.allclose(a.t, b.t, atol=1e-6)
        assert [stamp_ns(m.header) for _, m in direct[topics['image']]] == \
               [stamp_ns(m.header) for _, m in imported[topics['image']]]
        for (_, original), (_, copy) in zip(direct[topics['image']], imported[topics['image']]):
            difference = np.abs(image_from_compressed(original).astype(int) - image_from_compressed(copy).astype(int))
            assert difference.mean() < 1.0 and difference.max() <= 16, 'beyond JPEG tolerance'
    assert GROUND_TRUTH_TOPIC not in imported


def test_published_calibration_error_moves_the_stated_cameras(tmp_path):
    run_mvpose('synth', *SMALL, '--frames', '60-60', '--calibration-error', 1, '-o', tmp_path / 'wrong', timeout=300)
    run_mvpose('synth', *SMALL, '--frames', '60-60', '-o', tmp_path / 'right', timeout=300)
    wrong, right = cameras_of(read_all(tmp_path / 'wrong')), cameras_of(read_all(tmp_path / 'right'))
    for k in CAMERAS:
        shift = np.linalg.norm(wrong[k].center - right[k].center)
        assert 0 < shift < 0.05 and not np.allclose(wrong[k].R, right[k].R)


def test_standing_clip(tmp_path):
    run_mvpose('synth', '--motion', 'stand', '--resolution', '320x180', '--frames', '0-2', '--cameras', 1,
               '-o', tmp_path / 'stand', timeout=300)
    skeletons = [joints_from_skeleton(m) for _, m in read_all(tmp_path / 'stand')[GROUND_TRUTH_TOPIC]]
    assert len(skeletons) == 3 and np.ptp(np.array(skeletons)[:, :, :2], axis=0).max() < 0.02


def test_preview_contact_sheet(synth_bags, tmp_path):
    output = tmp_path / 'sheet.png'
    run_mvpose('preview', synth_bags / 'direct', '--frame', FRAMES[0] + 1, '-o', output)
    sheet = cv2.imread(str(output))
    assert sheet.shape == (360, 3 * 640, 3)  # three 640×360 tiles, one row
    white = np.all(sheet > 245, axis=2)  # the ground-truth skeleton is drawn in white
    assert all(white[:, i * 640:(i + 1) * 640].sum() > 100 for i in range(3))


def test_bad_synth_and_import_input_is_one_line_errors(synth_bags, tmp_path):
    assert_one_line_error(run_mvpose('synth', '--cameras', 9, '-o', tmp_path / 'x', check=False), '--cameras')
    assert_one_line_error(run_mvpose('synth', '--frames', '500-510', '-o', tmp_path / 'y', check=False), '500')
    assert_one_line_error(run_mvpose('synth', '--resolution', 'big', '-o', tmp_path / 'z', check=False), 'big')
    assert_one_line_error(run_mvpose('import-i3dpost', synth_bags / 'layout', '--cameras', 1, '-o', tmp_path / 'w',
                                     check=False), 'camera 1')
    assert_one_line_error(run_mvpose('import-i3dpost', tmp_path, '-o', tmp_path / 'v', check=False), str(tmp_path))
    assert_one_line_error(run_mvpose('preview', synth_bags / 'direct', '--frame', 5, check=False), 'frame 5')


def test_synth_markers_bag(tmp_path):
    bag = tmp_path / 'occlusions'
    run_mvpose('synth', '--markers', '--motion', 'occlusions', '--frames', '42-45', '--resolution', '960x540',
               '--cameras', *CAMERAS, '-o', bag, timeout=300)
    contents = {}
    for info, _, data in BagReader(bag).messages():
        contents.setdefault(info.name, []).append((info.type, deserialize_message(data, message_class(info.type))))
    for k in CAMERAS:
        topic = camera_topics(k)['markers']
        assert [t for t, _ in contents[topic]] == ['mvpose_msgs/msg/MarkerTracks'] * 4
        images = [m for _, m in contents[camera_topics(k)['image']]]
        for (_, message), image in zip(contents[topic], images):
            assert message.header.stamp == image.header.stamp and message.header.frame_id == image.header.frame_id
            assert message.status == 0 and list(message.names) == list(JOINT_NAMES)
            assert len(message.x) == len(message.y) == len(message.flags) == 15
            assert set(message.flags) <= {message.FLAG_DETECTED, message.FLAG_PREDICTED}
            assert 6 <= list(message.flags).count(message.FLAG_DETECTED) < 15
            assert all(0 <= x < 960 for x in message.x) and all(0 <= y < 540 for y in message.y)
    assert MARKER_CENTRES_TOPIC in contents and len(contents['/mvpose/ground_truth']) == 4
    with AnyReader([bag]) as reader:
        connections = [c for c in reader.connections if c.topic == camera_topics(5)['markers']]
        message = reader.deserialize(next(reader.messages(connections=connections))[2], connections[0].msgtype)
        assert list(message.names) == list(JOINT_NAMES)
    sets = list(frame_sets(bag))
    assert [s.frame for s in sets] == [42, 43, 44, 45]
    for frame_set in sets:
        pixels, visible = frame_set.markers[5]
        assert pixels.shape == (15, 2) and visible.dtype == bool
        assert not visible[JOINT_INDEX['head']], f'frame {frame_set.frame}: the hand hides the head marker from camera 5'
        assert visible[JOINT_INDEX['pelvis']] and visible[JOINT_INDEX['left_knee']]
        # The shirt is not red: the rendered image is red at visible markers only.
        image = frame_set.images[5]
        for (x, y), seen in zip(pixels, visible):
            if seen:
                assert red(image[int(round(y)) - 1:int(round(y)) + 2, int(round(x)) - 1:int(round(x)) + 2]).any()


def test_red_shirt_with_markers_is_refused(tmp_path):
    result = run_mvpose('synth', '--markers', '--shirt', 'red', '-o', tmp_path / 'x', check=False)
    assert_one_line_error(result, '--shirt red')
