"""The synthetic studio without a bag: the walk of the paper's frames in the paper's cameras, and the marker
suit (paper 001): red markers on the 15 joints rendered by the ray caster, their per-camera ground truth
(true projection, visible or hidden) and the scripted occlusions. The bags synth writes: test_synth.py."""
import cv2
import numpy as np
import pytest

from mvpose_nodes.studio import palette, scene
from mvpose_nodes.body.model import JOINT_INDEX, JOINT_NAMES
from mvpose_nodes.body.camera import studio_rig
from mvpose_nodes.studio.scripted_motion import occlusion_motion, phase_frames
from mvpose_nodes.app.synth import make_motion
from types import SimpleNamespace

pytestmark = pytest.mark.pure

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
    appearance = scene.Appearance(skin=palette.SKIN_TONES[skin_tone], shirt=palette.SHIRTS['green'], markers=True)
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
    rgb, labels, _ = finished(camera, pose_at(walk, 3), scene.Appearance(shirt=palette.SHIRTS['red']))
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


def test_whole_walk_of_the_paper_frames_stays_in_the_paper_cameras():
    """Frames 52–101 at 1080p: the whole person (joints, toes, fingertips, hair above the vertex)
    is inside the image of cameras 3, 5 and 7, as in the paper's choice of frames and cameras."""
    from types import SimpleNamespace
    from mvpose_nodes.body.camera import studio_rig
    from mvpose_nodes.app.synth import make_motion
    motion = make_motion(SimpleNamespace(frames='52-101', clip='07_01', motion='walk', height=1.75, seed=0))
    points = np.concatenate([motion.joints, motion.toes, motion.hand_tips], axis=1).reshape(-1, 3)
    for camera in studio_rig(cameras=CAMERAS):
        pixels, depth = camera.project(points)
        assert np.all(depth > 0)
        assert pixels[:, 0].min() > 20 and pixels[:, 0].max() < 1900, camera.number
        assert pixels[:, 1].min() > 40 and pixels[:, 1].max() < 1060, camera.number
