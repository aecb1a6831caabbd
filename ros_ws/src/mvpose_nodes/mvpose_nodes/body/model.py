"""The paper-000 body model (Fig. 6, Table 1): names shared by every message producer, part
labels, and the joint frames published in Skeleton messages.

The joints are P1..P15 of paper 000; the 29 parameters are its Table 1 in order (the
paper's symbols in the comments); the stages are its hierarchical search (Sec. 5.1).
"""
import numpy as np

from mvpose_nodes.body.geometry import matrix_from_quaternion, normalize, quaternion_from_matrix, rotation_between

JOINT_NAMES = (
    'pelvis',          # P1: midpoint of the two hip joint centres (root)
    'left_hip',        # P2
    'left_knee',       # P3
    'left_ankle',      # P4
    'right_hip',       # P5
    'right_knee',      # P6
    'right_ankle',     # P7
    'neck',            # P8: base of the neck, top of the thorax between the shoulders
    'head',            # P9: top of the head (vertex)
    'left_shoulder',   # P10
    'left_elbow',      # P11
    'left_wrist',      # P12: wrist joint centre
    'right_shoulder',  # P13
    'right_elbow',     # P14
    'right_wrist',     # P15
)

PARAMETER_NAMES = (
    'torso_x', 'torso_y', 'torso_z',                                 # X, Y, Z [m]: root position
    'torso_rx', 'torso_ry', 'torso_rz',                              # RX1, RY1, RZ1 [rad]
    'left_thigh_rx', 'left_thigh_ry', 'left_thigh_rz',               # RX3, RY3, RZ3
    'left_shin_rx',                                                  # RX4
    'right_thigh_rx', 'right_thigh_ry', 'right_thigh_rz',            # RX5, RY5, RZ5
    'right_shin_rx',                                                 # RX7
    'head_rx', 'head_ry', 'head_rz',                                 # RX9, RY9, RZ9
    'left_clavicle_ry', 'left_clavicle_rz',                          # RY10, RZ10
    'left_upper_arm_rx', 'left_upper_arm_ry', 'left_upper_arm_rz',   # RX11, RY11, RZ11
    'left_forearm_rx',                                               # RX12
    'right_clavicle_ry', 'right_clavicle_rz',                        # RY13, RZ13
    'right_upper_arm_rx', 'right_upper_arm_ry', 'right_upper_arm_rz',  # RX14, RY14, RZ14
    'right_forearm_rx',                                              # RX15
)

# Where each name sits in a joints (15, 3) array and a parameters (29,) vector.
JOINT_INDEX = {name: index for index, name in enumerate(JOINT_NAMES)}
PARAMETER_INDEX = {name: index for index, name in enumerate(PARAMETER_NAMES)}

STAGE_NAMES = ('torso', 'head_neck', 'left_arm', 'right_arm', 'left_leg', 'right_leg')


# Body-part labels of contour pixels and ground-truth masks; the values of mvpose_msgs/LabelledContour's
# LABEL_* constants (a test keeps them equal), so that algorithm modules need not import messages.
LABEL_NONE = 0
LABEL_TORSO = 1
LABEL_HEAD = 2
LABEL_LEFT_ARM = 3
LABEL_RIGHT_ARM = 4
LABEL_LEFT_LEG = 5
LABEL_RIGHT_LEG = 6
LABEL_LEFT_HAND = 7
LABEL_RIGHT_HAND = 8
PART_LABELS = {'torso': LABEL_TORSO, 'head': LABEL_HEAD, 'left_arm': LABEL_LEFT_ARM, 'right_arm': LABEL_RIGHT_ARM,
               'left_leg': LABEL_LEFT_LEG, 'right_leg': LABEL_RIGHT_LEG, 'left_hand': LABEL_LEFT_HAND,
               'right_hand': LABEL_RIGHT_HAND}

# Which bone orients each joint's frame, and that bone's direction in the rest pose (standing
# upright, arms hanging), in the torso frame (x forward, y left, z up). None: the torso frame itself.
ORIENTING_BONES = {
    'pelvis': None, 'neck': None,
    'left_hip': ('left_hip', 'left_knee', (0, 0, -1)), 'left_knee': ('left_knee', 'left_ankle', (0, 0, -1)),
    'left_ankle': ('left_knee', 'left_ankle', (0, 0, -1)),
    'right_hip': ('right_hip', 'right_knee', (0, 0, -1)), 'right_knee': ('right_knee', 'right_ankle', (0, 0, -1)),
    'right_ankle': ('right_knee', 'right_ankle', (0, 0, -1)),
    'head': ('neck', 'head', (0, 0, 1)),
    'left_shoulder': ('left_shoulder', 'left_elbow', (0, 0, -1)),
    'left_elbow': ('left_elbow', 'left_wrist', (0, 0, -1)), 'left_wrist': ('left_elbow', 'left_wrist', (0, 0, -1)),
    'right_shoulder': ('right_shoulder', 'right_elbow', (0, 0, -1)),
    'right_elbow': ('right_elbow', 'right_wrist', (0, 0, -1)),
    'right_wrist': ('right_elbow', 'right_wrist', (0, 0, -1)),
}


# ORIENTING_BONES as arrays: the joints that have one, their bones' start and end joints and rest directions.
_ORIENTING = [(name, ORIENTING_BONES[name]) for name in JOINT_NAMES if ORIENTING_BONES[name] is not None]
_ORIENTED = [JOINT_INDEX[name] for name, _ in _ORIENTING]
_ORIENTING_START = [JOINT_INDEX[start] for _, (start, _, _) in _ORIENTING]
_ORIENTING_END = [JOINT_INDEX[end] for _, (_, end, _) in _ORIENTING]
_ORIENTING_REST = np.array([rest for _, (_, _, rest) in _ORIENTING], float)


def torso_frame(joints, across=('right_hip', 'left_hip')):
    """3×3 rotation (columns x forward, y left, z up) of the torso from joints (15, 3) [m]:
    z along pelvis→neck, y along the `across` pair of joints (right → left: the hips, or the shoulders)
    made orthogonal to z."""
    up = normalize(joints[JOINT_INDEX['neck']] - joints[JOINT_INDEX['pelvis']])
    left = joints[JOINT_INDEX[across[1]]] - joints[JOINT_INDEX[across[0]]]
    left = normalize(left - np.dot(left, up) * up)
    return np.column_stack([np.cross(left, up), left, up])


def joint_orientations(joints):
    """Quaternions [x, y, z, w] (15, 4) of the joints' frames in the world, for Skeleton.joints.

    Each joint's frame is the torso frame turned by the smallest rotation that takes its orienting
    bone from the rest direction to the posed one (paper 004's exact axis-angle → quaternion, Eq. 3–4),
    so a person standing in the rest pose has every joint frame equal to the torso frame. The bones'
    rotations are found all at once (rotation_between of (N, 3))."""
    torso = torso_frame(joints)
    local = (joints[_ORIENTING_END] - joints[_ORIENTING_START]) @ torso   # each bone in the torso frame
    frames = torso @ matrix_from_quaternion(rotation_between(_ORIENTING_REST, local))
    orientations = np.tile(quaternion_from_matrix(torso), (len(JOINT_NAMES), 1))
    orientations[_ORIENTED] = [quaternion_from_matrix(frame) for frame in frames]
    return orientations

# The 14 bones of paper 000 (Fig. 6, Table 1), as (parent joint, child joint).
BONES = (
    ('pelvis', 'neck'), ('pelvis', 'left_hip'), ('left_hip', 'left_knee'), ('left_knee', 'left_ankle'),
    ('pelvis', 'right_hip'), ('right_hip', 'right_knee'), ('right_knee', 'right_ankle'), ('neck', 'head'),
    ('neck', 'left_shoulder'), ('left_shoulder', 'left_elbow'), ('left_elbow', 'left_wrist'),
    ('neck', 'right_shoulder'), ('right_shoulder', 'right_elbow'), ('right_elbow', 'right_wrist'),
)
