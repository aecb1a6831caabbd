"""Scripted motions built from keyframes of the 29-DOF body model (kinematics), for cases that the
motion-capture clips do not show on demand.

`occlusion_motion`: paper 001's marker-occlusion cases one after another, standing in the middle of
the studio facing camera 5 (world −x; cameras 3 and 7 see the right and left side): a hand passing in
front of the head; shoulders shrugged and arms crossed in front of the chest (neck, shoulder, elbow
and wrist markers bunch); the wrists swinging past the hips; the knees crossing (a cross-step).
Keyframes of the 29 parameters are joined by smoothstep easing, so every joint moves smoothly and
rests at each keyframe. NumPy only.
"""
import numpy as np

from mvpose_nodes.studio.i3dpost import FRAME_RATE
from mvpose_nodes.body.model import JOINT_INDEX, PARAMETER_INDEX, PARAMETER_NAMES
from mvpose_nodes.body.kinematics import bone_lengths, forward_kinematics
from mvpose_nodes.studio.mocap import ANKLE_HEIGHT_PER_HEIGHT, BodyMotion

HEADING = np.pi / 2     # torso_rz: the model's forward +y turned to world −x (towards camera 5)
TOE_REACH = 0.15 / 1.75   # toe tip in front of the ankle, per metre of height
HAND_LENGTH = 0.095       # wrist to fingertip, per metre of height

# The relaxed stance the script starts from and returns to between the cases (degrees).
REST = {'left_upper_arm_ry': 8, 'right_upper_arm_ry': -8, 'left_forearm_rx': 12, 'right_forearm_rx': 12,
        'left_thigh_ry': -2, 'right_thigh_ry': 2}

CROSSED = {'left_clavicle_ry': 25, 'right_clavicle_ry': -25, 'left_clavicle_rz': -12, 'right_clavicle_rz': 12,
           'right_upper_arm_rx': 30, 'right_upper_arm_rz': 60, 'right_forearm_rx': 80,
           'left_upper_arm_rx': 25, 'left_upper_arm_rz': -60, 'left_forearm_rx': 90, 'head_rx': 6}

# (name, [(time [s], {parameter: degrees, relative to REST where not given})…]): each phase starts and
# ends in REST; its keyframe times are from the phase's start.
PHASES = (
    ('rest', [(0.0, {}), (0.4, {})]),
    ('hand_in_front_of_head', [
        (0.0, {}),
        (0.8, {'right_upper_arm_rx': 85, 'right_upper_arm_rz': 10, 'right_forearm_rx': 110}),
        (1.2, {'right_upper_arm_rx': 90, 'right_upper_arm_rz': 30, 'right_forearm_rx': 95}),
        (1.5, {'right_upper_arm_rx': 90, 'right_upper_arm_rz': 38, 'right_forearm_rx': 88}),
        (1.8, {'right_upper_arm_rx': 90, 'right_upper_arm_rz': 50, 'right_forearm_rx': 65}),
        (2.6, {})]),
    ('shrug_and_arms_crossed', [(0.0, {}), (0.9, CROSSED), (1.5, CROSSED), (2.4, {})]),
    ('wrists_past_hips', [
        (0.0, {}),
        (0.6, {'right_upper_arm_rx': 40, 'left_upper_arm_rx': -35, 'right_forearm_rx': 20, 'left_forearm_rx': 10}),
        (1.5, {'right_upper_arm_rx': -35, 'left_upper_arm_rx': 40, 'right_forearm_rx': 10, 'left_forearm_rx': 20}),
        (2.1, {})]),
    ('knees_crossing', [
        (0.0, {}),
        (0.6, {'right_thigh_rx': 25, 'right_thigh_ry': 22, 'right_shin_rx': -35, 'torso_ry': -3}),
        (1.0, {'right_thigh_rx': 15, 'right_thigh_ry': 22, 'right_shin_rx': -12, 'left_shin_rx': -10,
               'torso_ry': -3}),
        (1.4, {'right_thigh_rx': 15, 'right_thigh_ry': 22, 'right_shin_rx': -12, 'left_shin_rx': -10,
               'torso_ry': -3}),
        (2.0, {})]),
    ('rest', [(0.0, {}), (0.4, {})]),
)


def _parameters(angles, lengths, height):
    """The 29 parameters of a keyframe ({parameter: degrees}, over REST), standing at the origin."""
    values = {**REST, **angles}
    parameters = np.zeros(len(PARAMETER_NAMES))
    for name, degrees in values.items():
        parameters[PARAMETER_INDEX[name]] = np.radians(degrees)
    parameters[PARAMETER_INDEX['torso_rz']] += HEADING
    parameters[PARAMETER_INDEX['torso_z']] = ANKLE_HEIGHT_PER_HEIGHT * height + lengths['thigh'] + lengths['shin']
    return parameters


def phase_frames(frame_rate=FRAME_RATE):
    """[(name, first frame, last frame)] of the occlusion script's phases (frame 0 = its start)."""
    ranges, start = [], 0.0
    for name, keys in PHASES:
        end = start + keys[-1][0]
        ranges.append((name, int(round(start * frame_rate)), int(round(end * frame_rate)) - 1))
        start = end
    return ranges


def occlusion_parameters(frame_rate=FRAME_RATE, height=1.75):
    """(F, 29) parameters of the occlusion script sampled at frame_rate [Hz]."""
    lengths = bone_lengths(height)
    times, keys = [], []
    start = 0.0
    for _, phase in PHASES:
        for t, angles in phase:
            if times and abs(start + t - times[-1]) < 1e-9:
                keys[-1] = _parameters(angles, lengths, height)
                continue
            times.append(start + t)
            keys.append(_parameters(angles, lengths, height))
        start += phase[-1][0]
    times, keys = np.array(times), np.array(keys)
    samples = np.arange(int(round(times[-1] * frame_rate))) / frame_rate
    segment = np.clip(np.searchsorted(times, samples, side='right') - 1, 0, len(times) - 2)
    u = (samples - times[segment]) / (times[segment + 1] - times[segment])
    ease = (u * u * (3 - 2 * u))[:, None]  # smoothstep: zero velocity at every keyframe
    return (1 - ease) * keys[segment] + ease * keys[segment + 1]


def body_points(parameters, height=1.75):
    """Joints (15, 3), toe tips (2, 3), fingertips (2, 3) and head_forward (3,) of one parameter vector."""
    lengths = bone_lengths(height)
    joints, frames = forward_kinematics(parameters, lengths)
    ankle_height = ANKLE_HEIGHT_PER_HEIGHT * height
    toes, tips = [], []
    for side in ('left', 'right'):
        forward = frames[f'{side}_shin'][:, 1].copy()  # the shin's forward, made horizontal: a flat foot
        forward[2] = 0.0
        forward /= max(np.linalg.norm(forward), 1e-9)
        toes.append(joints[JOINT_INDEX[f'{side}_ankle']] + TOE_REACH * height * forward + [0.0, 0.0, -ankle_height])
        tips.append(joints[JOINT_INDEX[f'{side}_wrist']] + HAND_LENGTH * height * (frames[f'{side}_forearm'] @ [0.0, 0.0, -1.0]))
    return joints, np.array(toes), np.array(tips), frames['head'][:, 1]


def occlusion_motion(frame_rate=FRAME_RATE, height=1.75, first_frame=0, center=(0.0, 0.0)):
    """The occlusion script as a BodyMotion (see the module's docstring and phase_frames)."""
    points = [body_points(p, height) for p in occlusion_parameters(frame_rate, height)]
    joints, toes, tips, head_forward = (np.array(a) for a in zip(*points))
    shift = np.array([center[0], center[1], 0.0])
    return BodyMotion(frame_rate=float(frame_rate), first_frame=first_frame, joints=joints + shift,
                      toes=toes + shift, hand_tips=tips + shift, head_forward=head_forward)
