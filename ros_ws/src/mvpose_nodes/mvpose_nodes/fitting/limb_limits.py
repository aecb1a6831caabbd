"""The limbs' anatomical limits beyond single joint angles, compiled (numba): a limb's twist about its own
axis and its lateral angle, which the stages' objective limits (stage_search.TWIST_LIMITS, whose numpy
reference is stage_search.twist_excess), and the Euler rotation they and compiled_kinematics.forward_joints share.
"""
import numpy as np
from numba import njit


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
