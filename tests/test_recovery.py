"""A fit that has lost the person says so and starts again (issue 13): hypotheses.unexplained_share, Fit.lost
and the re-initialisation that follows; and one camera whose keypoints are far off is not followed
(initialisation.consistent_views). On rendered silhouettes of the CMU walk with exact keypoints."""
import math
from dataclasses import replace

import numpy as np
import pytest

from mvpose_nodes.body.camera import studio_rig
from mvpose_nodes.body.model import JOINT_NAMES
from mvpose_nodes.fitting.fitter import TORSO_POSITION, SkeletonFitter
from mvpose_nodes.fitting.hypotheses import unexplained_share
from mvpose_nodes.fitting.initialisation import consistent_views, triangulated_joints
from mvpose_nodes.fitting.settings import FitterSettings

from common import rendered_views

pytestmark = pytest.mark.pure

KNOCKED_AT = 7           # before this frame (after the start's hypothesis_frames) the fitter's pose is moved
KNOCK = (1.5, 0.0, 0.0)  # KNOCK [m] away from the person
FRAMES = 15
MID_WALK = 28            # the clip's middle frames: the whole person in every view


@pytest.fixture(scope='module')
def walk(cmu_walk):
    return rendered_views(cmu_walk.placed(heading=math.radians(-20)), studio_rig((960, 540), cameras=[3, 5, 7]),
                          range(MID_WALK, MID_WALK + FRAMES))


def knocked_fits(frames, settings):
    """(lost, initialised, mean joint error [mm]) per frame, the pose moved KNOCK away before KNOCKED_AT."""
    fitter, found = SkeletonFitter(settings), []
    for i, (truth, views) in enumerate(frames):
        if i == KNOCKED_AT:
            fitter.parameters[TORSO_POSITION] += KNOCK
        fit = fitter.fit(i / 25.0, views)
        found.append((fit.lost, fit.initialised, 1000 * np.linalg.norm(fit.joints - truth, axis=1).mean()))
    return found


def test_the_true_pose_explains_the_outlines_and_one_moved_away_does_not(walk):
    for truth, views in walk:
        assert unexplained_share(views, truth) < 0.05
        assert unexplained_share(views, truth + KNOCK) > 0.5


def test_a_skeleton_floating_above_the_person_counts_as_lost(walk):
    """A fit seen on a tuning walk (session 43, by a variant of the fitter not kept): its pelvis 0.4 m above the
    person's for 30 frame sets, 27-30 % of the outline unexplained, which lost_share's earlier 0.3 never
    called lost. Here the true pose raised 0.4 m leaves 17-29 %."""
    lost_share = FitterSettings().lost_share
    for truth, views in walk:
        assert unexplained_share(views, truth + (0.0, 0.0, 0.4)) > lost_share
        assert unexplained_share(views, truth) < lost_share / 3


def test_a_fit_knocked_off_the_person_is_lost_then_reinitialised_and_right_again(walk):
    settings = FitterSettings()
    found = knocked_fits(walk, settings)
    lost = [i for i, (is_lost, _, _) in enumerate(found) if is_lost]
    assert lost and lost[0] <= KNOCKED_AT + settings.lost_frames, found
    assert found[lost[0] + 1][1], found   # the next frame set starts again from the keypoints
    assert all(error < 60 for _, _, error in found[lost[0] + 2:]), found
    assert not any(is_lost or initialised for is_lost, initialised, _ in found[settings.hypothesis_frames:KNOCKED_AT]), found


def test_starts_next_names_the_starts_before_they_run(walk):
    """The node asks the cameras for nothing while a start is fitted (sync.ready_to_request), so starts_next
    must say beforehand which fits start: the first, and the one after the knocked fit is lost."""
    fitter, predicted, started = SkeletonFitter(FitterSettings()), [], []
    start = fitter.start
    fitter.start = lambda *arguments: (started.append(len(predicted) - 1), start(*arguments))
    for i, (truth, views) in enumerate(walk):
        if i == KNOCKED_AT:
            fitter.parameters[TORSO_POSITION] += KNOCK
        predicted.append(fitter.starts_next)
        fitter.fit(i / 25.0, views)
    assert started == [i for i, starts in enumerate(predicted) if starts], (started, predicted)
    assert started[0] == 0 and len(started) == 2 and started[1] > KNOCKED_AT, started


def test_without_the_check_the_knocked_fit_stays_off(walk):
    """The check above can fail: without it, the knocked fit stays off the person."""
    found = knocked_fits(walk, FitterSettings(lost_share=1.0))
    assert not any(is_lost for is_lost, _, _ in found)
    assert np.mean([error for _, _, error in found[KNOCKED_AT + 3:]]) > 150, found


MOVED = (200.0, -60.0)   # [px] one camera's keypoints moved so (issue 13 saw elbows and wrists 200-260 px off)
ARMS = ('left_elbow', 'right_elbow', 'left_wrist', 'right_wrist')


def error_with_one_camera_off(frames, moved, settings=None):
    """Mean joint error [mm] of the fits of the frames with the first camera's keypoints `moved` (names)
    moved by MOVED."""
    fitter, errors = SkeletonFitter(settings), []
    for i, (truth, views) in enumerate(frames):
        keypoints = {name: (x + MOVED[0], y + MOVED[1], confidence) if name in moved else (x, y, confidence)
                     for name, (x, y, confidence) in views[0].keypoints.items()}
        fit = fitter.fit(i / 25.0, [replace(views[0], keypoints=keypoints)] + views[1:])
        errors.append(1000 * np.linalg.norm(fit.joints - truth, axis=1).mean())
    return float(np.mean(errors))


@pytest.fixture(scope='module')
def clean_error(walk):
    return error_with_one_camera_off(walk, ())


def test_one_cameras_arms_far_off_do_not_pull_the_fit(walk, clean_error):
    """Issue 13: with one camera's elbows and wrists 200 px off (as seen on independent renders), the fit is
    within 10 % of the clean fit's error: those keypoints disagree with the other views' triangulation and
    are left out, and the start's limb searches are compared by the outline they explain."""
    assert error_with_one_camera_off(walk, ARMS) <= 1.1 * clean_error, clean_error


def test_the_keypoints_of_the_camera_that_disagrees_are_the_ones_left_out(walk):
    """consistent_views leaves out exactly the moved camera's arm keypoints and keeps every other (with the
    gate at 10 m nothing is left out, so the check can fail)."""
    truth, views = walk[0]
    moved = [replace(views[0], keypoints={name: (x + MOVED[0], y + MOVED[1], c) if name in ARMS else (x, y, c)
                                          for name, (x, y, c) in views[0].keypoints.items()})] + views[1:]
    settings = FitterSettings()
    found = triangulated_joints(moved, settings)
    kept = consistent_views(moved, found, settings.keypoint_gate)
    assert sorted(set(moved[0].keypoints) - set(kept[0].keypoints)) == sorted(ARMS)
    assert all(kept_view.keypoints == view.keypoints for kept_view, view in zip(kept[1:], moved[1:]))
    assert consistent_views(moved, found, 10.0)[0].keypoints == moved[0].keypoints


def test_a_keypoint_left_out_of_one_view_weighs_as_much_in_the_others(walk):
    """StageSearch.keypoint_targets: a joint's keypoint weights sum to the same whether three views have it
    or two (one left out), so the outline does not outweigh it where a camera's was far off; a keypoint
    only one view has keeps its confidence."""
    from mvpose_nodes.fitting.stage_search import StageSearch

    def weights(views, name):
        joint = JOINT_NAMES.index(name)
        return [float(weight) for _, joints, _, stage_weights in StageSearch.keypoint_targets('left_arm', views)
                for j, weight in zip(joints, stage_weights) if j == joint]

    def without_wrist(view):
        return replace(view, keypoints={n: v for n, v in view.keypoints.items() if n != 'left_wrist'})

    _, views = walk[0]
    everywhere = weights(views, 'left_wrist')
    one_left_out = weights([without_wrist(views[0])] + views[1:], 'left_wrist')
    assert len(everywhere) == 3
    assert len(one_left_out) == 2
    assert sum(one_left_out) == pytest.approx(sum(everywhere))
    alone = [view if i == 1 else without_wrist(view) for i, view in enumerate(views)]
    assert weights(alone, 'left_wrist') == [views[1].keypoints['left_wrist'][2]]
