"""Canonical limb starts (fitting/limb_starts.py, issue 13): the poses keep the bones' lengths and point where
they say, and a start without arm keypoints (raised hands not found) while the arms are raised overhead fits
them raised; without the canonical starts the same start leaves them down, so the
check can fail. Keypoints otherwise exact, silhouettes the studio's true masks."""
from dataclasses import replace

import numpy as np
import pytest

from mvpose_nodes.body.camera import studio_rig
from mvpose_nodes.body.model import JOINT_INDEX
from mvpose_nodes.fitting import fitter as fitter_module
from mvpose_nodes.fitting.fitter import SkeletonFitter
from mvpose_nodes.fitting.limb_starts import ARM_POSES, LEG_POSES, limb_start_joints, torso_axes
from mvpose_nodes.fitting.settings import FitterSettings

from common import rendered_views

pytestmark = pytest.mark.pure

ARM_JOINTS = [f'{side}_{name}' for side in ('left', 'right') for name in ('elbow', 'wrist')]


@pytest.fixture(scope='module')
def arms_overhead():
    """Frame sets of the arms-overhead motion while both hands are above the head."""
    from mvpose_nodes.studio.catalogue import load_motion
    motion = load_motion('arms_overhead_and_wave').placed()
    return rendered_views(motion, studio_rig((960, 540), cameras=[2, 4, 7]), range(20, 23))


def test_canonical_poses_keep_the_bones_and_point_where_they_say(cmu_walk):
    joints = cmu_walk.joints[10]
    up, left, forward = torso_axes(joints)
    assert np.allclose([up @ left, up @ forward, left @ forward], 0, atol=1e-12)
    arms, legs = limb_start_joints(joints)
    assert arms.shape == (len(ARM_POSES), 15, 3) and legs.shape == (len(LEG_POSES), 15, 3)
    bones = (('shoulder', 'elbow'), ('elbow', 'wrist'), ('hip', 'knee'), ('knee', 'ankle'))
    for posed in (*arms, *legs):
        for side in ('left', 'right'):
            for a, b in bones:
                length = np.linalg.norm(joints[JOINT_INDEX[f'{side}_{a}']] - joints[JOINT_INDEX[f'{side}_{b}']])
                assert np.linalg.norm(posed[JOINT_INDEX[f'{side}_{a}']] - posed[JOINT_INDEX[f'{side}_{b}']]) \
                    == pytest.approx(length, abs=1e-9)
    overhead, sideways = arms[0], arms[2]
    head = joints[JOINT_INDEX['head']] @ up
    for side, outward in (('left', left), ('right', -left)):
        assert overhead[JOINT_INDEX[f'{side}_wrist']] @ up > head
        shoulder = joints[JOINT_INDEX[f'{side}_shoulder']]
        assert (sideways[JOINT_INDEX[f'{side}_wrist']] - shoulder) @ outward > 0.4
    untouched = [i for name, i in JOINT_INDEX.items() if not name.endswith(('elbow', 'wrist'))]
    assert np.array_equal(arms[:, untouched], np.repeat(joints[None, untouched], len(ARM_POSES), axis=0))


def without_arms(views):
    """The views without elbow and wrist keypoints: raised hands' skin not found (taken for the face's, or
    too small), the start's arms then the template's, hanging."""
    return [replace(view, keypoints={name: k for name, k in view.keypoints.items()
                                     if not name.endswith(('elbow', 'wrist'))}) for view in views]


def arm_error(fitter, frame_sets):
    """Mean distance [m] of the fitted elbows and wrists from the truth over the frame sets."""
    errors = []
    for index, (truth, views) in enumerate(frame_sets):
        fit = fitter.fit(index * 40_000_000, without_arms(views))
        errors.append(np.mean([np.linalg.norm(fit.joints[JOINT_INDEX[n]] - truth[JOINT_INDEX[n]])
                               for n in ARM_JOINTS]))
    return float(np.mean(errors))


def test_a_start_without_arm_keypoints_fits_the_raised_arms(arms_overhead, monkeypatch):
    with_starts = arm_error(SkeletonFitter(FitterSettings()), arms_overhead)
    monkeypatch.setattr(fitter_module, 'limb_start_joints', lambda joints: (np.empty((0, 15, 3)),) * 2)
    without = arm_error(SkeletonFitter(FitterSettings()), arms_overhead)
    assert with_starts < 0.1 < without, (with_starts, without)
