"""Forward kinematics compiled with numba, for the stage objective (compiled.py): the joints of 29
parameters, and a limb's twist and lateral excess (limb_limits.limb_excess) read from them. Equal to
body.kinematics.forward_kinematics to 1e-12 (tests/test_compiled.py). Cached on disk like compiled.py.
"""
import numpy as np
from numba import njit

from mvpose_nodes.body.kinematics import BONES, _ANGLE_INDEX, _CHAIN, _TORSO_POSITION
from mvpose_nodes.body.model import JOINT_INDEX
from mvpose_nodes.fitting.limb_limits import euler_rotation, limb_excess

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


def bone_length_array(lengths):
    """Per bone in BONES order its length [m] (14,) float64, from lengths {length key: m}."""
    return np.array([lengths[bone.length] for bone in BONES], np.float64)


@njit(cache=True, nogil=True, error_model='numpy')
def twist_excess(parameters, bone, reference, neutral, low, high, hinge, lateral_low, lateral_high):
    """limb_limits.limb_excess of the limb `bone` (BONES index) at 29 parameters, its child's hinge the
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
