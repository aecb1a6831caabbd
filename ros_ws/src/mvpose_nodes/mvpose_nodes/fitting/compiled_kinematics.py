"""Forward kinematics compiled with numba, for the stage objective (compiled.py): the joints of 29
parameters, equal to body.kinematics.forward_kinematics to 1e-12 (tests/test_compiled.py); and the limbs'
anatomical limits beyond single joint angles: a limb's twist about its own axis and its lateral angle
(limb_excess), which the stages' objective limits (stage_search.TWIST_LIMITS, whose numpy reference is
stage_search.twist_excess), read from the parameters (twist_excess). Cached on disk like compiled.py.
"""
import numpy as np
from numba import njit

from mvpose_nodes.fitting import numba_cache  # noqa: F401  (first: the cache folder of this version's sources)
from mvpose_nodes.body.kinematics import BONES, _ANGLE_INDEX, _CHAIN, _TORSO_POSITION
from mvpose_nodes.body.model import JOINT_INDEX

# Forward kinematics' plan as arrays (kinematics._CHAIN): per bone its parent bone (−1: world), whether it
# has angles, rest direction, length key's index, start and end joints, and its angles' parameter indices.
CHAIN_PARENT = np.array([parent for parent, *_ in _CHAIN], np.int64)
CHAIN_HAS_ANGLES = np.array([has_angles for _, has_angles, *_ in _CHAIN], np.bool_)
CHAIN_REST = np.array([rest for _, _, rest, *_ in _CHAIN], np.float64)
CHAIN_START = np.array([start for *_, start, _ in _CHAIN], np.int64)
CHAIN_END = np.array([end for *_, end in _CHAIN], np.int64)
CHAIN_ANGLES = np.asarray(_ANGLE_INDEX, np.int64)
PELVIS = JOINT_INDEX['pelvis']
TORSO_POSITION = np.array(_TORSO_POSITION, np.int64)


@njit(cache=True, nogil=True, error_model='numpy')
def euler_rotation(rx, ry, rz):
    """kinematics.euler_matrix: Rz(rz)·Ry(ry)·Rx(rx) (paper 004 Eq. 2), 3×3."""
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    out = np.empty((3, 3))
    out[0, 0], out[0, 1], out[0, 2] = cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx
    out[1, 0], out[1, 1], out[1, 2] = sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx
    out[2, 0], out[2, 1], out[2, 2] = -sy, cy * sx, cy * cx
    return out


@njit(cache=True, nogil=True, error_model='numpy')
def limb_twist(rotation, reference, neutral):
    """[rad] The twist of a limb about its own axis whose rotation in its parent bone's frame is `rotation`
    (3×3; its rest direction along the parent's −Z, its child's hinge axis its own X):
    the signed angle about the limb's direction d from the hinge axis the limb would have if swung to d
    from the `reference` direction (3,) (unit, in the parent's frame) by the shortest rotation, its hinge
    axis there being `neutral` (3,) (unit, ⟂ reference), to the hinge axis it has (swing–twist
    decomposition). 0 when d points opposite the reference (the swing is undefined there)."""
    d = -rotation[:, 2]
    hinge = rotation[:, 0]
    c = reference[0] * d[0] + reference[1] * d[1] + reference[2] * d[2]
    if 1.0 + c < 1e-6:
        return 0.0
    v = np.cross(reference, d)
    vn = np.cross(v, neutral)
    swung = neutral + vn + np.cross(v, vn) / (1.0 + c)
    cross = np.cross(swung, hinge)
    return np.arctan2(cross[0] * d[0] + cross[1] * d[1] + cross[2] * d[2],
                      swung[0] * hinge[0] + swung[1] * hinge[1] + swung[2] * hinge[2])


# How many times a joint limit's cost per rad² a limb's lateral angle beyond its range costs: the legs
# exchanged (a thigh across the body's middle) otherwise cost as little as 0.3 % of a frame's objective
# more than the right legs (measured on a tuning walk), and no true pose of the tuning motions is beyond it.
LATERAL_STIFFNESS = 100.0


@njit(cache=True, nogil=True, error_model='numpy')
def limb_excess(rx, ry, rz, hinge_angle, reference, neutral, low, high, lateral_low, lateral_high):
    """[rad²] How far the twist (limb_twist; reference, neutral (3,)) of a limb whose rotation in its parent's
    frame is Rz(rz)·Ry(ry)·Rx(rx) lies beyond [low, high] [rad], times the sine of its child's hinge angle
    `hinge_angle` [rad] (at most 90°), squared (a straight knee or elbow shows no twist, a bent one shows
    it as far as it is bent); plus how far its lateral angle (the arcsine of its direction's x in its
    parent's frame) lies beyond [lateral_low, lateral_high] [rad], squared, times LATERAL_STIFFNESS."""
    rotation = euler_rotation(rx, ry, rz)
    twist = limb_twist(rotation, reference, neutral)
    beyond = max(low - twist, 0.0) + max(twist - high, 0.0)
    lateral = np.arcsin(min(max(-rotation[0, 2], -1.0), 1.0))
    aside = max(lateral_low - lateral, 0.0) + max(lateral - lateral_high, 0.0)
    return (beyond * np.sin(min(abs(hinge_angle), np.pi / 2))) ** 2 + LATERAL_STIFFNESS * aside * aside


def bone_length_array(lengths):
    """Per bone in BONES order its length [m] (14,) float64, from lengths {length key: m}."""
    return np.array([lengths[bone.length] for bone in BONES], np.float64)


@njit(cache=True, nogil=True, error_model='numpy')
def twist_excess(parameters, bone, reference, neutral, low, high, hinge, lateral_low, lateral_high):
    """limb_excess of the limb `bone` (BONES index) at 29 parameters, its child's hinge the
    parameter index `hinge`."""
    angles = np.zeros(3)
    for axis in range(3):
        if CHAIN_ANGLES[bone, axis] >= 0:
            angles[axis] = parameters[CHAIN_ANGLES[bone, axis]]
    return limb_excess(angles[0], angles[1], angles[2], parameters[hinge], reference, neutral, low, high,
                       lateral_low, lateral_high)


@njit(cache=True, nogil=True, error_model='numpy')
def forward_joints(parameters, bone_lengths):
    """Joints (15, 3) [m] of 29 parameters (Table 1 order) and bone lengths (14,) [m]: the joints of
    kinematics.forward_kinematics (without its bone frames). The 3×3 products written out: numba's `@`
    calls BLAS, whose overhead per call is larger than such a product."""
    joints = np.zeros((len(CHAIN_END) + 1, 3))
    joints[PELVIS] = parameters[TORSO_POSITION]
    frames = np.empty((len(CHAIN_END), 3, 3))
    for bone in range(len(CHAIN_END)):
        parent = CHAIN_PARENT[bone]
        if CHAIN_HAS_ANGLES[bone]:
            angles = np.zeros(3)
            for axis in range(3):
                if CHAIN_ANGLES[bone, axis] >= 0:
                    angles[axis] = parameters[CHAIN_ANGLES[bone, axis]]
            rotation = euler_rotation(angles[0], angles[1], angles[2])
            if parent < 0:
                frames[bone] = rotation
            else:
                for i in range(3):
                    for j in range(3):
                        frames[bone, i, j] = (frames[parent, i, 0] * rotation[0, j]
                                              + frames[parent, i, 1] * rotation[1, j]
                                              + frames[parent, i, 2] * rotation[2, j])
        elif parent < 0:
            frames[bone] = np.eye(3)
        else:
            frames[bone] = frames[parent]
        start, end, length = CHAIN_START[bone], CHAIN_END[bone], bone_lengths[bone]
        for i in range(3):
            joints[end, i] = joints[start, i] + length * (frames[bone, i, 0] * CHAIN_REST[bone, 0]
                                                          + frames[bone, i, 1] * CHAIN_REST[bone, 1]
                                                          + frames[bone, i, 2] * CHAIN_REST[bone, 2])
    return joints
