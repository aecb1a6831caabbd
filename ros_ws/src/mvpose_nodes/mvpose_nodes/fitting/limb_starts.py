"""Canonical limb poses that a (re)start searches each limb stage from, beside the previous pose and the
frame's triangulated joints (beyond paper 000, whose Sec. 5.3 avoids local minima by good starts).

Why: the objective is right where the searches start near the truth (refitted from the true pose, the
suite's tuning cases with arms overhead come out 9-13 mm off), but a start from keypoints misread (a
hand's skin found on the trousers, a raised hand not found at all) leaves an arm folded down while the
silhouettes show it raised, and the tracking that follows keeps it there. Started from the true pose
instead, the 10 tuning cases of seed 1 went from 105 to 66 mm. A limb's Nelder-Mead search from a few
poses that span where limbs go (raised, out, forward, hanging; a stride, a raised knee, seated) finds the
raised arm; the searches of a limb are compared by the outline they leave unexplained
(stage_search.StageSearch.explained_cost).

Each pose gives the upper and lower bone's directions as (up, out, forward) weights in the torso's frame:
up from the pelvis to the neck, out towards the limb's own side, forward the way the torso faces.
"""
import numpy as np

from mvpose_nodes.body.model import JOINT_INDEX, torso_frame

ARM_POSES = (   # (upper arm, forearm)
    ((1, 0, 0), (1, 0, 0)),     # raised overhead
    ((1, 1, 0), (1, 1, 0)),     # raised out to the side
    ((0, 1, 0), (0, 1, 0)),     # held out sideways
    ((0, 0, 1), (0, 0, 1)),     # held forward
    ((1, 0, 1), (1, 0, 1)),     # raised forward
    ((0, 1, 0), (1, 0, 0)),     # out sideways, the forearm up (waving)
    ((-1, 0, 0), (-1, 0, 0)),   # hanging
)
LEG_POSES = (   # (thigh, shin)
    ((-1, 0, 0), (-1, 0, 0)),   # straight down
    ((-1, 0, 1), (-1, 0, 0)),   # thigh forward, shin down: a stride's front leg, a raised knee
    ((-2, 0, -1), (-1, 0, -1)),  # thigh and shin back: a stride's back leg
    ((0, 0, 1), (-1, 0, 0)),    # thigh level, shin down: seated
)
ARM_CHAIN = ('shoulder', 'elbow', 'wrist')
LEG_CHAIN = ('hip', 'knee', 'ankle')


def torso_axes(joints):
    """(up, left, forward) unit vectors (3,) of the torso of joints (15, 3) [m]: model.torso_frame's axes with
    left taken across the shoulders, which is where the arms hang from (the hips may turn with the legs)."""
    forward, left, up = torso_frame(joints, across=('right_shoulder', 'left_shoulder')).T
    return up, left, forward


def posed_limbs(joints, poses, chain):
    """joints (15, 3) [m] with both limbs of `chain` (root, middle, end joint names without the side) posed as
    each of `poses` in turn, the bones' lengths kept: (len(poses), 15, 3)."""
    up, left, forward = torso_axes(joints)
    posed = np.repeat(joints[None], len(poses), axis=0)
    for side, outward in (('left', left), ('right', -left)):
        base, middle, end = (JOINT_INDEX[f'{side}_{name}'] for name in chain)
        upper = np.linalg.norm(joints[middle] - joints[base])
        lower = np.linalg.norm(joints[end] - joints[middle])
        axes = np.array([up, outward, forward])
        for k, (upper_weights, lower_weights) in enumerate(poses):
            directions = [np.asarray(weights, float) @ axes for weights in (upper_weights, lower_weights)]
            upper_direction, lower_direction = (d / np.linalg.norm(d) for d in directions)
            posed[k, middle] = joints[base] + upper * upper_direction
            posed[k, end] = posed[k, middle] + lower * lower_direction
    return posed


def limb_start_joints(joints):
    """The canonical starts for a pose joints (15, 3) [m]: (arms (len(ARM_POSES), 15, 3), legs (len(LEG_POSES),
    15, 3)), each with both arms, or both legs, posed so and the rest of the body as it is."""
    return posed_limbs(joints, ARM_POSES, ARM_CHAIN), posed_limbs(joints, LEG_POSES, LEG_CHAIN)
