"""The articulated body of paper 000 (Fig. 6, Table 1): 15 joints, 14 bones, 29 degrees of freedom,
forward kinematics, and joint angles from 3D joints by paper 004's exact method.

Model frame (every bone's rest frame): X = the person's right, Y = forward, Z = up (right-handed).
A bone's rotation is relative to its parent bone's frame, R = Rz(rz)·Ry(ry)·Rx(rx) (004 Eq. 2; a part
without a DOF keeps 0), so the root's angles are about the world axes (paper: "RX_i, RY_i, RZ_i
about the world X, Y, Z axes") and every child's about its parent's axes, which makes the knee and
elbow (RX only) hinges that bend about the limb's own lateral axis. Rest pose: upright, facing +Y,
arms hanging, legs straight. Bone lengths: a template as fractions of the stature H (Winter,
"Biomechanics and Motor Control of Human Movement", segment lengths), scaled by the person's height.
Angles [rad], positions [m].
"""
from dataclasses import dataclass

import numpy as np

from mvpose_nodes.body.model import JOINT_INDEX, JOINT_NAMES, PARAMETER_INDEX, PARAMETER_NAMES
from mvpose_nodes.body.geometry import (cross, matrix_from_quaternion, normalize, quaternion_from_matrix,
                                        rotation_between)


# Bone lengths as fractions of the stature (Winter's table: hip joint at 0.530 H, knee 0.285, ankle
# 0.039, shoulder line 0.818, elbow 0.630, wrist 0.485; shoulder breadth 0.259 H).
LENGTH_FRACTIONS = {
    'spine': 0.818 - 0.530, 'hip': 0.052, 'thigh': 0.530 - 0.285, 'shin': 0.285 - 0.039,
    'head': 1.0 - 0.818, 'clavicle': 0.259 / 2, 'upper_arm': 0.818 - 0.630, 'forearm': 0.630 - 0.485,
}


@dataclass(frozen=True)
class Bone:
    """A bone from `parent_joint` to `joint`: its rest direction in the parent bone's frame, length
    key, the bone whose frame it hangs from (None: the torso's), and its free Euler angles."""
    name: str
    parent_joint: str
    joint: str
    rest: tuple
    length: str
    parent: str = None
    angles: tuple = ()   # parameter names of (rx, ry, rz) in that order; absent ones are fixed at 0


BONES = (
    Bone('torso', 'pelvis', 'neck', (0, 0, 1), 'spine', angles=('torso_rx', 'torso_ry', 'torso_rz')),
    Bone('left_hip', 'pelvis', 'left_hip', (-1, 0, 0), 'hip', 'torso'),
    Bone('left_thigh', 'left_hip', 'left_knee', (0, 0, -1), 'thigh', 'torso',
         ('left_thigh_rx', 'left_thigh_ry', 'left_thigh_rz')),
    Bone('left_shin', 'left_knee', 'left_ankle', (0, 0, -1), 'shin', 'left_thigh', ('left_shin_rx',)),
    Bone('right_hip', 'pelvis', 'right_hip', (1, 0, 0), 'hip', 'torso'),
    Bone('right_thigh', 'right_hip', 'right_knee', (0, 0, -1), 'thigh', 'torso',
         ('right_thigh_rx', 'right_thigh_ry', 'right_thigh_rz')),
    Bone('right_shin', 'right_knee', 'right_ankle', (0, 0, -1), 'shin', 'right_thigh', ('right_shin_rx',)),
    Bone('head', 'neck', 'head', (0, 0, 1), 'head', 'torso', ('head_rx', 'head_ry', 'head_rz')),
    Bone('left_clavicle', 'neck', 'left_shoulder', (-1, 0, 0), 'clavicle', 'torso',
         (None, 'left_clavicle_ry', 'left_clavicle_rz')),
    Bone('left_upper_arm', 'left_shoulder', 'left_elbow', (0, 0, -1), 'upper_arm', 'torso',
         ('left_upper_arm_rx', 'left_upper_arm_ry', 'left_upper_arm_rz')),
    Bone('left_forearm', 'left_elbow', 'left_wrist', (0, 0, -1), 'forearm', 'left_upper_arm', ('left_forearm_rx',)),
    Bone('right_clavicle', 'neck', 'right_shoulder', (1, 0, 0), 'clavicle', 'torso',
         (None, 'right_clavicle_ry', 'right_clavicle_rz')),
    Bone('right_upper_arm', 'right_shoulder', 'right_elbow', (0, 0, -1), 'upper_arm', 'torso',
         ('right_upper_arm_rx', 'right_upper_arm_ry', 'right_upper_arm_rz')),
    Bone('right_forearm', 'right_elbow', 'right_wrist', (0, 0, -1), 'forearm', 'right_upper_arm',
         ('right_forearm_rx',)),
)
BONE_INDEX = {bone.name: i for i, bone in enumerate(BONES)}


def bone_lengths(height):
    """{length key: [m]} of the template scaled to a person `height` [m] tall."""
    return {key: fraction * height for key, fraction in LENGTH_FRACTIONS.items()}


def bone_lengths_of(joints):
    """{bone name (BONES): [m]} each bone's median length over the frames of joints (F, 15, 3) [m] (frames
    without a skeleton, NaN, ignored)."""
    joints = np.asarray(joints, float).reshape(-1, len(JOINT_NAMES), 3)
    return {bone.name: float(np.nanmedian(np.linalg.norm(joints[:, JOINT_INDEX[bone.joint]]
                                                         - joints[:, JOINT_INDEX[bone.parent_joint]], axis=-1)))
            for bone in BONES}


def lengths_of(joints):
    """{length key (LENGTH_FRACTIONS): [m]} of a person from joints (F, 15, 3) [m]: bone_lengths_of, the
    bones that share a key (left and right) averaged."""
    per_bone, found = bone_lengths_of(joints), {}
    for bone in BONES:
        found.setdefault(bone.length, []).append(per_bone[bone.name])
    return {key: float(np.mean(found[key])) for key in LENGTH_FRACTIONS}


def euler_matrix(rx, ry, rz):
    """R = Rz(rz)·Ry(ry)·Rx(rx) (paper 004 Eq. 2)."""
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    return np.array([[cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx],
                     [sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx],
                     [-sy, cy * sx, cy * cx]])


def euler_from_quaternion(q):
    """(rx, ry, rz) with Rz·Ry·Rx equal to the rotation of unit quaternion q = [x, y, z, w] (the ZYX
    conversion that ends paper 004). At gimbal lock (ry = ±90°) only rz ∓ rx is defined: rx = 0."""
    x, y, z, w = q
    sin_ry = np.clip(2 * (w * y - z * x), -1.0, 1.0)
    if abs(sin_ry) > 1 - 1e-12:  # with rx = 0 the matrix's second column is (−sin rz, cos rz, 0)
        return 0.0, float(np.copysign(np.pi / 2, sin_ry)), float(np.arctan2(-2 * (x * y - z * w),
                                                                            1 - 2 * (x * x + z * z)))
    return (float(np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))), float(np.arcsin(sin_ry)),
            float(np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))))


def forward_kinematics(parameters, lengths):
    """Joints (15, 3) [m] and bone frames {bone: 3×3 world rotation} of 29 parameters (Table 1 order)."""
    parameters = np.asarray(parameters, dtype=float)
    rotations = _euler_matrices(np.append(parameters, 0.0)[_ANGLE_INDEX])  # index −1: a fixed angle, 0
    joints = np.zeros((len(JOINT_NAMES), 3))
    joints[JOINT_INDEX['pelvis']] = parameters[_TORSO_POSITION]
    frames = []
    for bone, (parent, has_angles, rest, length, start, end) in enumerate(_CHAIN):
        frame = _IDENTITY if parent < 0 else frames[parent]
        if has_angles:
            frame = frame @ rotations[bone]
        frames.append(frame)
        joints[end] = joints[start] + lengths[length] * (frame @ rest)
    return joints, dict(zip(_BONE_NAMES, frames))


def _euler_matrices(angles):
    """euler_matrix of each row (rx, ry, rz) of angles (B, 3) [rad]: (B, 3, 3), all at once."""
    (cx, cy, cz), (sx, sy, sz) = np.cos(angles).T, np.sin(angles).T
    return np.stack([cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx,
                     sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx,
                     -sy, cy * sx, cy * cx], axis=1).reshape(-1, 3, 3)


# Forward kinematics' plan, worked out once (it runs hundreds of times per fitted frame): per bone in
# BONES order, its parent bone's index (−1: the world), whether it has angles (else it keeps its parent's
# frame), the rest direction, the length key, and the joint indices; and the parameter indices of each
# bone's (rx, ry, rz) (−1: fixed at 0).
_IDENTITY = np.eye(3)
_TORSO_POSITION = [PARAMETER_INDEX['torso_x'], PARAMETER_INDEX['torso_y'], PARAMETER_INDEX['torso_z']]
_BONE_NAMES = [bone.name for bone in BONES]
_CHAIN = [(_BONE_NAMES.index(bone.parent) if bone.name != 'torso' else -1, bool(bone.angles),
           np.array(bone.rest, dtype=float), bone.length, JOINT_INDEX[bone.parent_joint], JOINT_INDEX[bone.joint]) for bone in BONES]
_ANGLE_INDEX = np.array([[PARAMETER_INDEX[name] if name else -1 for name in (list(bone.angles) + [None] * 3)[:3]] for bone in BONES])


def torso_rotation(joints):
    """World rotation of the torso (columns: right, forward, up) from pelvis, hips and neck."""
    up = normalize(joints[JOINT_INDEX['neck']] - joints[JOINT_INDEX['pelvis']])
    right = joints[JOINT_INDEX['right_hip']] - joints[JOINT_INDEX['left_hip']]
    right = normalize(right - np.dot(right, up) * up)
    return np.column_stack([right, cross(up, right), up])


# The limbs whose child is a hinge: (the child's end joint, the side of local Y it bends to).
HINGE_CHILD = {'left_thigh': ('left_ankle', -1), 'right_thigh': ('right_ankle', -1),    # knees bend back
               'left_upper_arm': ('left_wrist', 1), 'right_upper_arm': ('right_wrist', 1)}  # elbows forwards


def hinge_twist(local, parent, joints, end, bend_sign):
    """Rotation about a limb's own axis (its local Z) that brings the hinge child's end into the limb's
    local Y–Z plane, on the side the hinge bends to. The limb's direction fixes all but this twist, which
    only the child shows (a straight child leaves it at zero)."""
    frame = parent @ local
    start = {'left_ankle': 'left_knee', 'right_ankle': 'right_knee', 'left_wrist': 'left_elbow',
             'right_wrist': 'right_elbow'}[end]
    child = frame.T @ (joints[JOINT_INDEX[end]] - joints[JOINT_INDEX[start]])
    if np.hypot(child[0], child[1]) < 1e-9 * max(np.linalg.norm(child), 1e-12):
        return np.eye(3)
    twist = np.arctan2(-child[0] * bend_sign, child[1] * bend_sign)
    return euler_matrix(0.0, 0.0, twist)


def inverse_kinematics(joints):
    """The 29 parameters whose forward kinematics best reproduce joints (15, 3) [m] (paper 004).

    The torso's rotation comes from its full frame (spine and hip line). Every other bone turns its
    rest direction r into its measured direction r' (in the parent bone's frame) by the exact
    rotation of paper 004 — axis n = nor(r × r'), cos φ = r·r' / (|r||r'|), quaternion, then ZYX
    Euler angles — instead of the older method's constraint that one Euler angle is zero. Parts
    with fewer DOF take the exact angles they have: a clavicle (RY, RZ) reaches any direction; a
    hinge (RX) takes the signed angle of r' about the parent's X axis. A limb whose child is a hinge
    (thigh, upper arm) is also turned about its own axis so that the hinge bends the child where it is
    (hinge_twist): bone vectors alone leave that twist open."""
    joints = np.asarray(joints, dtype=float)
    parameters = np.zeros(len(PARAMETER_NAMES))
    parameters[[PARAMETER_INDEX['torso_x'], PARAMETER_INDEX['torso_y'], PARAMETER_INDEX['torso_z']]] = joints[JOINT_INDEX['pelvis']]
    frames = {'torso': torso_rotation(joints)}
    parameters[[PARAMETER_INDEX['torso_rx'], PARAMETER_INDEX['torso_ry'], PARAMETER_INDEX['torso_rz']]] = euler_from_quaternion(
        quaternion_from_matrix(frames['torso']))
    for bone in BONES[1:]:
        parent = frames[bone.parent]
        measured = parent.T @ (joints[JOINT_INDEX[bone.joint]] - joints[JOINT_INDEX[bone.parent_joint]])
        if not bone.angles:
            frames[bone.name] = parent
            continue
        if len(bone.angles) == 1:      # hinge about the parent's X: rest −Z turned towards ±Y
            angle = np.arctan2(measured[1], -measured[2]) if np.any(measured[1:]) else 0.0
            local = euler_matrix(angle, 0.0, 0.0)
            parameters[PARAMETER_INDEX[bone.angles[0]]] = angle
        elif bone.angles[0] is None:   # clavicle: rest ±X; Rz(rz)·Ry(ry) reaches any direction
            direction = normalize(measured) * np.sign(bone.rest[0])
            ry, rz = -np.arcsin(np.clip(direction[2], -1, 1)), np.arctan2(direction[1], direction[0])
            local = euler_matrix(0.0, ry, rz)
            parameters[[PARAMETER_INDEX[bone.angles[1]], PARAMETER_INDEX[bone.angles[2]]]] = ry, rz
        else:
            local = matrix_from_quaternion(rotation_between(bone.rest, measured))
            if bone.name in HINGE_CHILD:
                local = local @ hinge_twist(local, parent, joints, *HINGE_CHILD[bone.name])
            rx, ry, rz = euler_from_quaternion(quaternion_from_matrix(local))
            local = euler_matrix(rx, ry, rz)
            parameters[[PARAMETER_INDEX[name] for name in bone.angles]] = rx, ry, rz
        frames[bone.name] = parent @ local
    return parameters
