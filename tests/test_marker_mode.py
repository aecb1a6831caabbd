"""Marker mode around the tracker: triangulating the cameras' tracks (only detected markers count) and the
evaluation's identity-swap count. The MarkerTracks conversion: test_messages.py; `markers eval`:
test_commands.py; marker mode in the graph: test_graph.py."""
import numpy as np
import pytest

from mvpose_nodes.body.model import JOINT_NAMES
from mvpose_nodes.body.camera import studio_rig
from mvpose_nodes.markers.triangulation import triangulate_markers
from mvpose_nodes.markers.detection import FLAG_DETECTED, FLAG_LOST, FLAG_PREDICTED
from mvpose_nodes.app.markers import errors_and_swaps, swap_events

pytestmark = pytest.mark.pure


@pytest.fixture(scope='module')
def pose(cmu_walk):
    return cmu_walk.placed().joints[10]


def test_detected_markers_triangulate_back_and_predicted_ones_are_not_used(pose):
    cameras = studio_rig(cameras=[3, 5, 7])
    positions = np.array([camera.project(pose)[0] for camera in cameras])
    flags = np.full((3, 15), FLAG_DETECTED)
    joints, used = triangulate_markers(cameras, positions, flags)
    np.testing.assert_allclose(joints, pose, atol=1e-6)
    assert used.tolist() == [3] * 15
    # A prediction far off, flagged as such, changes nothing; one flagged detected would.
    wrist = JOINT_NAMES.index('left_wrist')
    moved = positions.copy()
    moved[0, wrist] += 40.0
    flags[0, wrist] = FLAG_PREDICTED
    joints, used = triangulate_markers(cameras, moved, flags)
    np.testing.assert_allclose(joints[wrist], pose[wrist], atol=1e-6)
    assert used[wrist] == 2
    flags[0, wrist] = FLAG_DETECTED
    assert np.linalg.norm(triangulate_markers(cameras, moved, flags)[0][wrist] - pose[wrist]) > 0.01


def test_a_marker_seen_in_one_camera_keeps_its_previous_position(pose):
    cameras = studio_rig(cameras=[3, 5, 7])
    positions = np.array([camera.project(pose)[0] for camera in cameras])
    flags = np.full((3, 15), FLAG_DETECTED)
    head = JOINT_NAMES.index('head')
    flags[1:, head] = [FLAG_PREDICTED, FLAG_LOST]
    previous = pose + 0.05
    joints, used = triangulate_markers(cameras, positions, flags, previous)
    assert used[head] == 1 and np.array_equal(joints[head], previous[head])
    # Without a previous position the prediction helps out; a lost marker never does.
    np.testing.assert_allclose(triangulate_markers(cameras, positions, flags)[0][head], pose[head], atol=1e-6)
    flags[0, head] = FLAG_LOST
    assert np.isnan(triangulate_markers(cameras, positions, flags)[0][head]).all()


def test_identity_swaps_are_counted_once_per_swap():
    true = np.array([[[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]]] * 6)   # 6 frames, 3 markers
    estimates = true.copy()
    estimates[2:4, [0, 1]] = estimates[2:4, [1, 0]]   # markers 0 and 1 exchanged in frames 2 and 3
    estimates[:, 2] += [1.0, 0.0]                       # marker 2 one pixel off: no swap
    runs = [(e, np.zeros(3), t, np.ones(3, bool)) for e, t in zip(estimates, true)]
    errors, visible, swapped = errors_and_swaps(runs)
    assert swapped[:, 0].tolist() == [False, False, True, True, False, False]
    assert swap_events(swapped) == 2          # one swap each for markers 0 and 1
    assert errors[0, 2] == pytest.approx(1.0) and visible.all()
