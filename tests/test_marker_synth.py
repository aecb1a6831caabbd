"""The synthetic marker suit (paper 001): red markers on the 15 joints rendered by the ray caster,
their per-camera ground truth (true projection, visible or hidden) and the scripted occlusions."""
import cv2
import numpy as np
import pytest
from conftest import assert_one_line_error, run_mvpose
from rclpy.serialization import deserialize_message
from rosbags.highlevel import AnyReader

from mvpose_nodes.studio import scene
from mvpose_nodes.io.bagfile import BagReader
from mvpose_nodes.body.model import JOINT_INDEX, JOINT_NAMES
from mvpose_nodes.body.camera import studio_rig
from mvpose_nodes.ros.camera_bag import MARKER_CENTRES_TOPIC, camera_topics, frame_sets
from mvpose_nodes.io.interfaces import message_class
from mvpose_nodes.studio.scripted_motion import occlusion_motion, phase_frames
from mvpose_nodes.app.synth import make_motion
from types import SimpleNamespace

CAMERAS = (3, 5, 7)


def pose_at(motion, index):
    return scene.BodyPose(motion.joints[index], motion.toes[index], motion.hand_tips[index],
                           motion.head_forward[index])


def red(image):
    """The pixels a simple colour detector takes for a red marker."""
    r, g, b = (image[..., c].astype(int) for c in range(3))
    return (r > 100) & (r - np.maximum(g, b) > 70)


def finished(camera, pose, appearance):
    view = scene.prepare_camera(camera, texture_seed=camera.number)
    rendering = scene.render(view, pose, appearance)
    rgb, labels = scene.Realism().finish(rendering, view, camera.number, 0, 0)
    return rgb, labels, rendering.marker_ids


@pytest.mark.parametrize('skin_tone', ['light', 'medium', 'dark'])
def test_red_shows_exactly_at_the_visible_markers(skin_tone):
    walk = make_motion(SimpleNamespace(frames='52-61', clip='07_01', motion='walk', height=1.75, seed=0))
    pose = pose_at(walk, 3)
    appearance = scene.Appearance(skin=scene.SKIN_TONES[skin_tone], shirt=scene.SHIRTS['green'], markers=True)
    for camera in studio_rig((960, 540), cameras=CAMERAS):
        rgb, labels, marker_ids = finished(camera, pose, appearance)
        pixels, fractions, visible = scene.marker_visibility(camera, pose, appearance)
        reddish = red(rgb)
        assert visible.sum() >= 6, f'camera {camera.number}: only {visible.sum()} markers visible'
        for name, (x, y), seen, fraction in zip(JOINT_NAMES, pixels, visible, fractions):
            column, row = int(round(x)), int(round(y))
            window = reddish[row - 1:row + 2, column - 1:column + 2]
            if seen:
                assert window.any(), f'{name} visible in camera {camera.number} but not red at its centre'
            elif fraction == 0:
                assert not (marker_ids[row - 1:row + 2, column - 1:column + 2] == JOINT_INDEX[name]).any()
        # No red anywhere else on the person: every red pixel is (next to) a rendered marker.
        near_marker = cv2.dilate((marker_ids >= 0).astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
        stray = reddish & (labels > 0) & ~near_marker
        assert stray.sum() == 0, f'camera {camera.number}: {stray.sum()} red pixels away from the markers'
        assert (reddish & ~near_marker).sum() == 0, 'red in the studio'


def test_the_red_test_sees_a_red_shirt():
    """The colour rule above is not blind: the walk's usual red shirt trips it."""
    walk = make_motion(SimpleNamespace(frames='52-61', clip='07_01', motion='walk', height=1.75, seed=0))
    camera = studio_rig((960, 540), cameras=[5])[0]
    rgb, labels, _ = finished(camera, pose_at(walk, 3), scene.Appearance(shirt=scene.SHIRTS['red']))
    assert (red(rgb) & (labels > 0)).sum() > 200


def test_marker_behind_the_body_is_hidden():
    """Standing facing camera 5 (world −x): the markers on the front of the pelvis and the neck face
    camera 5 and are hidden from camera 1 behind the person; the left hip's (on the left side, world −y)
    is seen by camera 7 and hidden from camera 3 on the right."""
    pose = pose_at(occlusion_motion(), 0)
    appearance = scene.Appearance(markers=True)
    rig = {camera.number: camera for camera in studio_rig((960, 540))}
    seen = {k: scene.marker_visibility(rig[k], pose, appearance)[2] for k in (1, 3, 5, 7)}
    for name in ('pelvis', 'neck'):
        assert seen[5][JOINT_INDEX[name]] and not seen[1][JOINT_INDEX[name]], name
    assert seen[7][JOINT_INDEX['left_hip']] and not seen[3][JOINT_INDEX['left_hip']]
    assert seen[3][JOINT_INDEX['right_hip']] and not seen[7][JOINT_INDEX['right_hip']]
    assert seen[1][JOINT_INDEX['head']] and seen[5][JOINT_INDEX['head']], 'the vertex is seen from all round'
    # Marker centres sit on the body's surface, a few centimetres from the joints.
    offsets = np.linalg.norm(scene.marker_centres(pose, appearance) - pose.joints, axis=1)
    assert offsets[JOINT_INDEX['head']] < 0.02 and np.all(offsets < 0.13) and np.all(offsets[np.arange(15) != JOINT_INDEX['head']] > 0.03)


def test_occlusion_script_hides_the_head_behind_the_hand():
    motion = occlusion_motion()
    phases = {name: (first, last) for name, first, last in phase_frames()}
    assert len(motion.joints) == max(last for _, _, last in phase_frames()) + 1
    camera = studio_rig((960, 540), cameras=[5])[0]
    appearance = scene.Appearance(markers=True)
    first, last = phases['hand_in_front_of_head']
    hidden = [f for f in range(first, last + 1)
              if not scene.marker_visibility(camera, pose_at(motion, f), appearance)[2][JOINT_INDEX['head']]]
    assert len(hidden) >= 3
    first, last = phases['knees_crossing']
    assert any(not scene.marker_visibility(camera, pose_at(motion, f), appearance)[2][JOINT_INDEX['left_knee']]
               for f in range(first, last + 1, 3))
    # Smooth: no joint moves more than 10 cm between frames (2.5 m/s); the feet stay on or above the floor.
    assert np.abs(np.diff(motion.joints, axis=0)).max() < 0.10
    assert motion.toes[..., 2].min() > -0.01


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
