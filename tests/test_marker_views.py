"""marker_views: the cameras' marker tracks fused in 3D, on exact projections of a captured pose (no images):
identities mended by the other views, hidden markers placed from them, a limb marker hidden everywhere
carried by its parent, and a lost marker found again from blobs nobody claimed."""
import numpy as np
import pytest

from mvpose_nodes.body.camera import studio_rig
from mvpose_nodes.markers.views import LIMB_PARENT, MarkerViews
from mvpose_nodes.markers.detection import FLAG_DETECTED, FLAG_PREDICTED, MARKER_NAMES

pytestmark = pytest.mark.pure

WRIST, OTHER_WRIST = MARKER_NAMES.index('left_wrist'), MARKER_NAMES.index('right_wrist')
HEAD = MARKER_NAMES.index('head')


@pytest.fixture(scope='module')
def walk(cmu_walk):
    """(F, 15, 3) [m]: 20 frames of a captured walk (CMU 07_01), markers at the joints."""
    return cmu_walk.placed().joints[10:30]


@pytest.fixture(scope='module')
def cameras():
    return studio_rig(cameras=[3, 5, 7])


def projections(cameras, points):
    return np.array([camera.project(points)[0] for camera in cameras])


def started(cameras, points):
    views = MarkerViews(cameras)
    truth = projections(cameras, points)
    views.start(truth, np.full((len(cameras), 15), FLAG_DETECTED))
    return views


def test_tracks_that_agree_give_the_points_and_keep_their_blobs(walk, cameras):
    views = started(cameras, walk[0])
    truth = projections(cameras, walk[1])
    points, positions, flags = views.fuse(truth, np.full((3, 15), FLAG_DETECTED))
    np.testing.assert_allclose(points, walk[1], atol=1e-6)
    np.testing.assert_allclose(positions, truth, atol=1e-6)
    assert (flags == FLAG_DETECTED).all() and (views.support == 3).all()


def test_a_view_that_swapped_two_markers_is_mended_by_the_others(walk, cameras):
    views = started(cameras, walk[0])
    truth = projections(cameras, walk[1])
    tracks = truth.copy()
    tracks[1, [WRIST, OTHER_WRIST]] = tracks[1, [OTHER_WRIST, WRIST]]   # camera 5 exchanged the wrists
    points, positions, flags = views.fuse(tracks, np.full((3, 15), FLAG_DETECTED))
    np.testing.assert_allclose(points, walk[1], atol=1e-6)
    np.testing.assert_allclose(positions[1], truth[1], atol=1e-6)      # the identities put right
    assert (flags == FLAG_DETECTED).all()


def test_a_marker_hidden_in_one_view_is_predicted_where_the_other_views_see_it(walk, cameras):
    views = started(cameras, walk[0])
    truth = projections(cameras, walk[1])
    tracks, flags = truth.copy(), np.full((3, 15), FLAG_DETECTED)
    tracks[2, WRIST] += (35.0, -20.0)          # camera 7's own guess for its hidden wrist, far off
    flags[2, WRIST] = FLAG_PREDICTED
    blobs = [truth[c] for c in range(3)]
    blobs[2] = np.delete(truth[2], WRIST, axis=0)   # no red blob of that wrist in camera 7
    points, positions, fused_flags = views.fuse(tracks, flags, blobs)
    np.testing.assert_allclose(positions[2, WRIST], truth[2, WRIST], atol=1e-6)
    assert fused_flags[2, WRIST] == FLAG_PREDICTED and views.support[WRIST] == 2


def test_a_limb_marker_hidden_everywhere_follows_its_parent_and_is_found_again(walk, cameras):
    views = started(cameras, walk[0])
    length = np.linalg.norm(walk[0, WRIST] - walk[0, LIMB_PARENT[WRIST]])
    for f in range(1, 16):                      # hidden in every camera: no blob, trackers' guesses off
        truth = projections(cameras, walk[f])
        tracks, flags = truth.copy(), np.full((3, 15), FLAG_DETECTED)
        tracks[:, WRIST] += 60.0
        flags[:, WRIST] = FLAG_PREDICTED
        blobs = [np.delete(truth[c], WRIST, axis=0) for c in range(3)]
        points, _, fused_flags = views.fuse(tracks, flags, blobs)
        assert views.support[WRIST] == 0 and (fused_flags[:, WRIST] == FLAG_PREDICTED).all()
        distance = np.linalg.norm(points[WRIST] - points[LIMB_PARENT[WRIST]])
        assert abs(distance - length) <= views.settings.bone_tolerance_m + 1e-9
    # It reappears, farther from its prediction than a blob is paired with one, and the trackers still
    # miss it: its blobs are nobody's, and the views take them.
    assert np.linalg.norm(views.points[WRIST] - walk[16, WRIST]) > views.settings.predicted_blob_gate_m
    truth = projections(cameras, walk[16])
    tracks, flags = truth.copy(), np.full((3, 15), FLAG_DETECTED)
    tracks[:, WRIST] += 60.0
    flags[:, WRIST] = FLAG_PREDICTED
    points, positions, fused_flags = views.fuse(tracks, flags, [truth[c] for c in range(3)])
    np.testing.assert_allclose(points[WRIST], walk[16, WRIST], atol=1e-6)
    assert (fused_flags[:, WRIST] == FLAG_DETECTED).all()


def test_two_views_agreeing_on_a_point_far_from_the_prediction_are_refused(walk, cameras):
    views = started(cameras, walk[0])
    moved = walk[1].copy()
    moved[HEAD] += (0.0, 0.0, 0.5)             # two views consistent with a head 50 cm up: a shared mistake
    truth, wrong = projections(cameras, walk[1]), projections(cameras, moved)
    tracks, flags = truth.copy(), np.full((3, 15), FLAG_DETECTED)
    tracks[:2, HEAD] = wrong[:2, HEAD]
    flags[2, HEAD] = FLAG_PREDICTED
    points, _, _ = views.fuse(tracks, flags)   # the blobs: where the tracks say they detected markers
    assert views.support[HEAD] < 2
    assert np.linalg.norm(points[HEAD] - walk[1, HEAD]) < 0.1   # moved with the shoulders instead


def test_a_lost_limb_marker_seen_again_by_one_view_takes_its_blob(walk, cameras):
    views = started(cameras, walk[0])
    for f in range(1, 16):                      # hidden in every camera
        truth = projections(cameras, walk[f])
        tracks, flags = truth.copy(), np.full((3, 15), FLAG_DETECTED)
        flags[:, WRIST] = FLAG_PREDICTED
        views.fuse(tracks, flags, [np.delete(truth[c], WRIST, axis=0) for c in range(3)])
    assert np.linalg.norm(views.points[WRIST] - walk[16, WRIST]) > views.settings.single_view_gate_m
    truth = projections(cameras, walk[16])
    tracks, flags = truth.copy(), np.full((3, 15), FLAG_DETECTED)
    flags[:, WRIST] = FLAG_PREDICTED
    blobs = [truth[0]] + [np.delete(truth[c], WRIST, axis=0) for c in (1, 2)]   # back in camera 3 only
    points, positions, fused_flags = views.fuse(tracks, flags, blobs)
    assert views.support[WRIST] == 1 and fused_flags[:, WRIST].tolist() == [FLAG_DETECTED, FLAG_PREDICTED, FLAG_PREDICTED]
    np.testing.assert_allclose(positions[0, WRIST], truth[0, WRIST], atol=1e-6)
    # On that view's ray at its distance from the elbow: within the shell's tolerance of the truth.
    assert np.linalg.norm(points[WRIST] - walk[16, WRIST]) < 2 * views.settings.bone_tolerance_m


def test_two_views_alone_may_not_move_a_limb_marker_far_three_may(walk, cameras):
    moved = walk[1].copy()
    moved[WRIST] += (0.08, 0.0, 0.0)           # 8 cm off its prediction: fast for a wrist within 40 ms
    truth, shifted = projections(cameras, walk[1]), projections(cameras, moved)
    for agreeing, supported in ((2, False), (3, True)):
        views = started(cameras, walk[0])
        tracks, flags = truth.copy(), np.full((3, 15), FLAG_DETECTED)
        tracks[:agreeing, WRIST] = shifted[:agreeing, WRIST]
        flags[agreeing:, WRIST] = FLAG_PREDICTED
        points, _, _ = views.fuse(tracks, flags)
        assert (views.support[WRIST] >= 2) == supported
        if supported:
            np.testing.assert_allclose(points[WRIST], moved[WRIST], atol=1e-6)
