"""Names of the paper-000 body model (Fig. 6, Table 1) shared by every message producer.

The joints are P1..P15 of paper 000; the 29 parameters are its Table 1 in order (the
paper's symbols in the comments); the stages are its hierarchical search (Sec. 5.1).
"""

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

STAGE_NAMES = ('torso', 'head_neck', 'left_arm', 'right_arm', 'left_leg', 'right_leg')

