"""Tracking across gaps (issue 14): at the bag's speed the fitter fits one frame set in several, up to half a
second apart, and must stay on the person (fitter.SkeletonFitter.pelvis_shift, limb_sides.LimbTracks.label,
SkeletonFitter.triangulated_limbs). On rendered silhouettes of the CMU walk with exact keypoints, and on
constructed triangulated pairs."""
import math

import numpy as np
import pytest

from mvpose_nodes.body.camera import studio_rig
from mvpose_nodes.body.kinematics import bone_lengths, forward_kinematics
from mvpose_nodes.body.model import JOINT_INDEX
from mvpose_nodes.fitting.fitter import SkeletonFitter
from mvpose_nodes.fitting.limb_sides import LimbTracks, label_across
from mvpose_nodes.fitting.settings import FitterSettings

from common import rendered_views

pytestmark = pytest.mark.pure

GAP = 12                   # frame sets between fits: 0.48 s at 25 fps, as at 1x on this machine
FITTED = range(4, 60, GAP)  # five fits over 2 s of the walk: a stride and a half


@pytest.fixture(scope='module')
def sparse_walk(cmu_walk):
    return rendered_views(cmu_walk.placed(heading=math.radians(-20)), studio_rig((960, 540), cameras=[3, 5, 7]),
                          FITTED)


def errors_with_gaps(frames, settings):
    """Mean joint error [mm] of each fit of the frames, fitted at their times in the clip (25 fps)."""
    fitter, errors = SkeletonFitter(settings), []
    for index, (truth, views) in zip(FITTED, frames):
        fit = fitter.fit(index / 25.0, views)
        errors.append(1000 * np.linalg.norm(fit.joints - truth, axis=1).mean())
    return errors


def test_a_walk_fitted_half_a_second_apart_stays_on_the_person(sparse_walk):
    errors = errors_with_gaps(sparse_walk, FitterSettings())
    assert max(errors) < 40, errors


def test_without_the_gaps_handled_the_fit_falls_behind(sparse_walk):
    """The check above can fail: with every gap treated as a frame period (the pelvis moved on at the fits'
    velocity, the pairs labelled by continuity, the limbs searched from the last fit), the fit is lost."""
    errors = errors_with_gaps(sparse_walk, FitterSettings(velocity_horizon=10.0))
    assert max(errors[1:]) > 100, errors


def test_the_hypotheses_fitted_side_by_side_give_the_same_fits(sparse_walk):
    # A start's eight labellings and their comparison over the next fits, and each stage's searches from its
    # several starts, on two threads and on one.
    fits = {threads: SkeletonFitter(threads=threads) for threads in (1, 2)}
    for index, (_, views) in zip(FITTED, sparse_walk):
        one, two = (fits[threads].fit(index / 25.0, views) for threads in (1, 2))
        assert np.array_equal(one.joints, two.joints) and one.initialised == two.initialised


LONG_GAP = 20   # frame sets: 0.8 s, over time_jump


@pytest.fixture(scope='module')
def sparser_walk(cmu_walk):
    return rendered_views(cmu_walk.placed(heading=math.radians(-20)), studio_rig((960, 540), cameras=[3, 5, 7]),
                          range(4, 60, LONG_GAP))


def test_frame_sets_skipped_to_keep_up_are_no_jump_in_time(sparser_walk):
    """Gaps over time_jump in which the node skipped frame sets (a slow machine at 1x) are followed across;
    the same gaps with nothing skipped (a pause in the recording) start again."""
    for skipped, starts in ((LONG_GAP - 1, [True, False, False]), (0, [True, True, True])):
        fitter = SkeletonFitter()
        fits = [fitter.fit((4 + LONG_GAP * n) / 25.0, views, skipped=skipped * (n > 0))
                for n, (_, views) in enumerate(sparser_walk)]
        assert [fit.initialised for fit in fits] == starts
        errors = [1000 * np.linalg.norm(fit.joints - truth, axis=1).mean() for fit, (truth, _) in zip(fits, sparser_walk)]
        assert max(errors) < 60, (skipped, errors)


def standing_body(root):
    """A 1.75 m person standing at the origin: joints (15, 3) [m], and the unit vectors across the body
    (from the right `root` joint, e.g. 'hip', to the left one) and forward (level)."""
    joints, _ = forward_kinematics(np.r_[0.0, 0.0, 1.0, np.zeros(26)], bone_lengths(1.75))
    left_root, right_root = joints[JOINT_INDEX[f'left_{root}']], joints[JOINT_INDEX[f'right_{root}']]
    across = (left_root - right_root) / np.linalg.norm(left_root - right_root)
    return joints, across, np.cross(across, (0.0, 0.0, 1.0))


def test_pairs_are_labelled_by_the_side_of_the_body_they_are_on():
    """label_across: of a triangulated pair, the point on the left shoulder's side is the left one, however
    far the two are apart front to back."""
    joints, across, forward = standing_body('shoulder')
    left_shoulder, right_shoulder = joints[JOINT_INDEX['left_shoulder']], joints[JOINT_INDEX['right_shoulder']]
    for name in ('knee', 'wrist'):
        on_left, on_right = left_shoulder + 0.4 * forward, right_shoulder - 0.4 * forward   # a stride apart
        found = {f'left_{name}': on_right, f'right_{name}': on_left, 'pelvis': joints[JOINT_INDEX['pelvis']]}
        label_across(found, joints)
        assert found[f'left_{name}'] is on_left and found[f'right_{name}'] is on_right
        label_across(found, joints)   # labelled right: left as it is
        assert found[f'left_{name}'] is on_left


def test_a_strides_feet_are_labelled_across_the_shoulders_not_the_fits_turned_hips():
    """A fit's hips' line is often 15-40 degrees off while its shoulders' is right (docs/method.md, session 43).
    Mid-stride the feet are 0.7 m apart front to back and 0.1 m side to side: across hips turned 20 degrees they
    would lie on the wrong sides; across the shoulders they are labelled right."""
    joints, across, forward = standing_body('shoulder')
    turn = math.radians(20)
    for side in ('left', 'right'):   # the hips turned about the pelvis, level
        offset = joints[JOINT_INDEX[f'{side}_hip']] - joints[JOINT_INDEX['pelvis']]
        width = np.dot(offset, across)
        joints[JOINT_INDEX[f'{side}_hip']] = joints[JOINT_INDEX['pelvis']] + width * (
            math.cos(turn) * across - math.sin(turn) * forward) + (0.0, 0.0, offset[2])
    hips = joints[JOINT_INDEX['left_hip']] - joints[JOINT_INDEX['right_hip']]
    left_foot, right_foot = 0.05 * across + 0.35 * forward, -0.05 * across - 0.35 * forward
    assert np.dot(left_foot - right_foot, hips) < 0   # the hips' side would exchange them
    found = {'left_ankle': right_foot, 'right_ankle': left_foot}
    label_across(found, joints)
    assert found['left_ankle'] is left_foot and found['right_ankle'] is right_foot


def test_pairs_a_few_frame_periods_on_are_labelled_by_continuity():
    """LimbTracks.label: up to continuity_horizon after the last fit a triangulated pair keeps the labels of
    the points nearest where the fits had it, also with the feet in line mid-stride and the left ankle
    triangulated 3 cm right of the right one, which the side of the body (label_across) would exchange;
    after a longer gap, when a walker's feet may have changed places front to back, the side decides."""
    settings = FitterSettings()
    joints, across, forward = standing_body('hip')
    middle = (joints[JOINT_INDEX['left_hip']] + joints[JOINT_INDEX['right_hip']]) / 2 - (0.0, 0.0, 0.8)
    fitted = joints.copy()   # a stride: the left foot 0.3 m ahead, the right one 0.3 m behind, in line
    fitted[JOINT_INDEX['left_ankle']] = middle + 0.3 * forward
    fitted[JOINT_INDEX['right_ankle']] = middle - 0.3 * forward
    ahead = middle + 0.35 * forward - 0.03 * across   # 0.12 s on: the left foot, a little right of the line
    behind = middle - 0.3 * forward
    for gap, horizon, left in ((0.12, settings.continuity_horizon, ahead), (0.12, 0.0, behind),
                               (0.5, settings.continuity_horizon, behind)):
        tracks = LimbTracks(FitterSettings(continuity_horizon=horizon))
        tracks.append(0.0, fitted)
        found = {'left_ankle': ahead, 'right_ankle': behind}
        tracks.label(gap, found)
        assert found['left_ankle'] is left, (gap, horizon)


def test_searches_after_a_skipped_frame_set_are_ranked_on_their_own_outlines(cmu_walk, monkeypatch):
    """SkeletonFitter.search_stages: a frame set one period after the last fit keeps the last fit's outline
    assignment for every search of a stage; over outline_horizon after it (a frame set skipped), each search
    is ranked by how well it explains the outline assigned from its own start (StageSearch.explained_cost)."""
    from mvpose_nodes.fitting.stage_search import StageSearch
    frames = rendered_views(cmu_walk.placed(heading=math.radians(-20)), studio_rig((960, 540), cameras=[3, 5, 7]),
                            [4, 5, 7])
    ranked = []
    explained_cost = StageSearch.explained_cost
    monkeypatch.setattr(StageSearch, 'explained_cost', lambda *args: ranked.append(1) or explained_cost(*args))
    for horizon, ranked_afresh in ((FitterSettings().outline_horizon, [False, True]), (1.0, [False, False])):
        fitter, counts = SkeletonFitter(FitterSettings(outline_horizon=horizon, hypothesis_frames=1)), []
        for index, (_, views) in zip([4, 5, 7], frames):
            ranked.clear()
            fitter.fit(index / 25.0, views)
            counts.append(bool(ranked))
        assert counts[1:] == ranked_afresh, (horizon, counts)
