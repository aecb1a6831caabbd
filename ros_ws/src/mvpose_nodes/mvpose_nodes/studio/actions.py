"""Scripted actions of the 29-parameter body model for the randomised evaluation (issue 13), for
movements that the motion-capture clips do not show: turning on the spot, walking backwards, bending
down and up, arms raised overhead and waving, sitting down onto an invisible seat and standing up.

Each action is built as scripted_motion's occlusion script is (its keyframe parameters over REST, its
heading: facing world −x, and its body_points), and then its feet are planted: per frame the legs are
solved analytically (two bones, the knee bending towards the foot's forward direction) so that each
ankle is where the script puts it, on the floor at the studio's ankle height or stepping, and their
angles are taken from kinematics.inverse_kinematics. So every frame is an exact pose of the rigid body
model, the planted feet do not slide, knees bend backwards and elbows forwards (stage_search's
JOINT_LIMITS). Keyframes are joined by smoothstep easing (every joint rests at each keyframe); the
stepping actions' pelvis follows monotone cubic curves (SciPy's PCHIP) through the footfalls.
Pelvis offsets are written in metres for a person REFERENCE_HEIGHT tall and scale with the height.
NumPy and SciPy only.
"""
import numpy as np
from scipy.interpolate import PchipInterpolator

from mvpose_nodes.body.kinematics import bone_lengths, forward_kinematics, inverse_kinematics
from mvpose_nodes.body.model import JOINT_INDEX, PARAMETER_INDEX
from mvpose_nodes.studio.i3dpost import FRAME_RATE
from mvpose_nodes.studio.mocap import ANKLE_HEIGHT_PER_HEIGHT, BodyMotion
from mvpose_nodes.studio.scripted_motion import REST, _parameters, body_points

REFERENCE_HEIGHT = 1.75  # [m] the pelvis offsets and step sizes below are for a person this tall
SIDES = ('left', 'right')
LEG_PARAMETERS = [PARAMETER_INDEX[f'{side}_{name}'] for side in SIDES
                  for name in ('thigh_rx', 'thigh_ry', 'thigh_rz', 'shin_rx')]
TORSO_POSITION = [PARAMETER_INDEX[name] for name in ('torso_x', 'torso_y', 'torso_z')]
OFFSETS = ('forward', 'left', 'down')  # pelvis offset channels [m at REFERENCE_HEIGHT], in the starting body frame


def eased(keys, times):
    """{channel: (F,) values} at `times` [s] of keyframes [(time [s], {channel: value})] joined by
    smoothstep; a keyframe that leaves a channel out has it at rest there (a parameter: REST's degrees,
    else 0); before the first keyframe and after the last the values are held."""
    key_times = np.array([t for t, _ in keys], dtype=float)
    channels = sorted(set().union(*(values for _, values in keys)))
    segment = np.clip(np.searchsorted(key_times, times, side='right') - 1, 0, len(keys) - 2)
    u = np.clip((times - key_times[segment]) / (key_times[segment + 1] - key_times[segment]), 0.0, 1.0)
    ease = u * u * (3 - 2 * u)
    tracks = {}
    for channel in channels:
        values = np.array([frame.get(channel, REST.get(channel, 0.0)) for _, frame in keys], dtype=float)
        tracks[channel] = (1 - ease) * values[segment] + ease * values[segment + 1]
    return tracks


def sample_times(duration, frame_rate):
    """(F,) frame times [s] 0, 1 / frame_rate, … up to `duration`."""
    return np.arange(int(np.floor(duration * frame_rate + 1e-9)) + 1) / frame_rate


def standing_pose(height):
    """(parameters (29,), joints (15, 3), torso frame 3×3: columns right, forward, up) of the script's rest
    stance (REST, facing world −x) at the origin."""
    lengths = bone_lengths(height)
    parameters = _parameters({}, lengths, height)
    joints, frames = forward_kinematics(parameters, lengths)
    return parameters, joints, frames['torso']


def plant_legs(parameters, lengths, ankles, knee_forward):
    """The parameters with both legs solved so that the ankles reach `ankles` (2, 3) [m], each knee bent
    towards its horizontal direction knee_forward (2, 3): hip, knee and ankle in the plane of the
    hip→ankle line and that direction, the knee on its side (a straight leg when the ankle is out of
    reach, pointing at it)."""
    joints, _ = forward_kinematics(parameters, lengths)
    thigh, shin = lengths['thigh'], lengths['shin']
    for side, ankle, forward in zip(SIDES, ankles, knee_forward):
        hip = joints[JOINT_INDEX[f'{side}_hip']]
        reach = ankle - hip
        along = reach / np.linalg.norm(reach)
        distance = np.clip(np.linalg.norm(reach), abs(thigh - shin) + 1e-6, (thigh + shin) * (1 - 1e-12))
        across = forward - np.dot(forward, along) * along
        across /= np.linalg.norm(across)
        cos_hip = (thigh ** 2 + distance ** 2 - shin ** 2) / (2 * thigh * distance)
        joints[JOINT_INDEX[f'{side}_knee']] = hip + thigh * (cos_hip * along + np.sqrt(1 - cos_hip ** 2) * across)
        joints[JOINT_INDEX[f'{side}_ankle']] = hip + distance * along
    planted = parameters.copy()
    planted[LEG_PARAMETERS] = inverse_kinematics(joints)[LEG_PARAMETERS]
    return planted


def perform(times, tracks, height=1.75, frame_rate=FRAME_RATE, first_frame=0, feet=None, knee_forward=None,
            pelvis_shift=None):
    """A BodyMotion sampled at `times` [s] (sample_times at frame_rate [Hz]) of channel tracks {channel: (F,)}: parameter
    names in degrees (absent: REST; 'torso_rz' turns the body from its heading), and OFFSETS, the
    pelvis's offset [m at REFERENCE_HEIGHT] from standing, along the starting forward and left and
    down. feet: (F, 2, 3) [m] ankle targets (left, right; default: where the rest stance has them);
    knee_forward: (F, 2, 3) the directions the knees bend towards (default: the starting forward);
    pelvis_shift: (F, 3) [m] added to the pelvis in the world."""
    count = len(times)
    lengths = bone_lengths(height)
    scale = height / REFERENCE_HEIGHT
    _, rest_joints, heading = standing_pose(height)
    forward, left, up = heading[:, 1], -heading[:, 0], heading[:, 2]
    ankles = [JOINT_INDEX['left_ankle'], JOINT_INDEX['right_ankle']]
    if feet is None:
        feet = np.broadcast_to(rest_joints[ankles], (count, 2, 3))
    if knee_forward is None:
        knee_forward = np.broadcast_to(forward, (count, 2, 3))
    zero = np.zeros(count)
    offset = scale * (tracks.get('forward', zero)[:, None] * forward + tracks.get('left', zero)[:, None] * left
                      - tracks.get('down', zero)[:, None] * up)
    if pelvis_shift is not None:
        offset = offset + pelvis_shift
    angles = {name: values for name, values in tracks.items() if name in PARAMETER_INDEX}
    points = []
    for i in range(count):
        parameters = _parameters({name: values[i] for name, values in angles.items()}, lengths, height)
        parameters[TORSO_POSITION] += offset[i]
        points.append(body_points(plant_legs(parameters, lengths, feet[i], knee_forward[i]), height))
    joints, toes, tips, head_forward = (np.array(a) for a in zip(*points))
    return BodyMotion(frame_rate=float(frame_rate), first_frame=first_frame, joints=joints, toes=toes,
                      hand_tips=tips, head_forward=head_forward)


# --- Bending down and up: a stoop (legs nearly straight, the hands to the shins), then a squatting reach
# (knees deep, the hands to the floor). Arms hang: the upper arms turned forwards by the trunk's lean.
STOOP = {'torso_rx': -78, 'forward': -0.13, 'down': 0.03, 'head_rx': 28, 'left_upper_arm_rx': 70,
         'right_upper_arm_rx': 70, 'left_forearm_rx': 15, 'right_forearm_rx': 15}
SQUAT_REACH = {'torso_rx': -50, 'forward': -0.18, 'down': 0.38, 'head_rx': 20, 'left_upper_arm_rx': 60,
               'right_upper_arm_rx': 55, 'left_forearm_rx': 25, 'right_forearm_rx': 30}
BEND_KEYS = [(0.0, {}), (0.5, {}), (1.6, STOOP), (2.2, STOOP), (3.3, {}), (3.7, {}),
             (4.9, SQUAT_REACH), (5.5, SQUAT_REACH), (6.7, {}), (7.1, {})]

# --- Sitting down onto an invisible seat at knee height and standing up: the trunk leans forward while
# the pelvis goes back and down, settles upright with the hands on the thighs, then leans forward again
# to rise. Seated, the hip joints are 0.57 m high (at 1.75 m), 5 cm above the knees, the thighs level.
HANDS_ON_THIGHS = {'left_upper_arm_rx': 12, 'right_upper_arm_rx': 12, 'left_forearm_rx': 55,
                   'right_forearm_rx': 55}
SEATED = {'torso_rx': -6, 'forward': -0.40, 'down': 0.365, 'head_rx': 3, **HANDS_ON_THIGHS}
SIT_KEYS = [
    (0.0, {}), (0.5, {}),
    (1.1, {'torso_rx': -32, 'forward': -0.12, 'down': 0.10, 'left_upper_arm_rx': 25, 'right_upper_arm_rx': 25}),
    (1.7, {'torso_rx': -28, 'forward': -0.37, 'down': 0.35, 'left_upper_arm_rx': 25, 'right_upper_arm_rx': 25}),
    (2.2, SEATED), (3.0, SEATED),
    (3.5, {'torso_rx': -42, 'forward': -0.37, 'down': 0.355, 'left_upper_arm_rx': 35, 'right_upper_arm_rx': 35,
           'left_forearm_rx': 30, 'right_forearm_rx': 30}),
    (4.1, {'torso_rx': -25, 'forward': -0.14, 'down': 0.12, 'left_upper_arm_rx': 20, 'right_upper_arm_rx': 20}),
    (4.7, {}), (5.2, {}),
]

# --- Arms overhead and waving: both arms raised sideways overhead and swayed from side to side (the
# trunk swaying with them), lowered, then the right hand raised and waving, the elbow flexing and
# extending with the upper arm held out to the side. Abduction: +ry for the left arm, −ry for the right.
def _overhead(lean):
    """Both arms overhead, swayed `lean` degrees to the person's left (negative: right)."""
    return {'left_upper_arm_ry': 160 - lean, 'right_upper_arm_ry': -160 - lean, 'left_forearm_rx': 20,
            'right_forearm_rx': 20, 'left_clavicle_ry': 10, 'right_clavicle_ry': -10, 'torso_ry': -0.2 * lean,
            'down': 0.01}  # knees soft: the trunk's sway tilts the hip line


def _hello(bend):
    """The right upper arm out to the side and level, the forearm raised with the elbow at `bend` degrees."""
    return {'right_upper_arm_rx': 90, 'right_upper_arm_rz': -90, 'right_upper_arm_ry': 0, 'right_forearm_rx': bend,
            'right_clavicle_ry': -8}


WAVE_KEYS = [(0.0, {}), (0.4, {}), (1.3, _overhead(0)), (1.7, _overhead(15)), (2.1, _overhead(-15)),
             (2.5, _overhead(15)), (2.9, _overhead(-15)), (3.3, _overhead(0)), (4.1, {}), (4.3, {}),
             (5.0, _hello(90)), (5.35, _hello(65)), (5.7, _hello(115)), (6.05, _hello(65)), (6.4, _hello(115)),
             (6.75, _hello(90)), (7.5, {}), (7.8, {})]


def bend_down_and_up(height=1.75, frame_rate=FRAME_RATE, first_frame=0):
    """Bending down and up twice (7.1 s): stooping with nearly straight legs (the trunk 78° forward, the
    hands to the shins), back up; then squatting down to reach the floor (knees bent 100°), back up."""
    times = sample_times(BEND_KEYS[-1][0], frame_rate)
    return perform(times, eased(BEND_KEYS, times), height, frame_rate, first_frame)


def sit_down_and_stand_up(height=1.75, frame_rate=FRAME_RATE, first_frame=0):
    """Sitting down onto an invisible seat at knee height, staying 0.8 s, and standing up (5.2 s); the feet
    stay where they stand, the pelvis goes 0.40 m back and 0.365 m down (at 1.75 m)."""
    times = sample_times(SIT_KEYS[-1][0], frame_rate)
    return perform(times, eased(SIT_KEYS, times), height, frame_rate, first_frame)


def arms_overhead_and_wave(height=1.75, frame_rate=FRAME_RATE, first_frame=0):
    """Both arms raised sideways overhead and swayed side to side twice, lowered; then the right hand
    raised and waving hello (7.8 s)."""
    times = sample_times(WAVE_KEYS[-1][0], frame_rate)
    return perform(times, eased(WAVE_KEYS, times), height, frame_rate, first_frame)


# --- Stepping: feet that lift off, swing along a path and land, the pelvis following.
LIFT = 0.07          # [m at REFERENCE_HEIGHT] highest ankle rise during a swing
SOFT_KNEES = 0.03    # [m at REFERENCE_HEIGHT] the pelvis lowered while stepping, so that no knee locks
STEPPING_REST = 0.6  # [s] standing before the first step and after the last
CROUCH = 0.05        # [m at REFERENCE_HEIGHT] the pelvis lowered walking backwards: the feet reach 0.28 m fore and aft


def _swing(times, start, end):
    """(F,) progress 0 → 1 of a swing from `start` to `end` [s] (smoothstep), and (F,) its lift profile
    sin(π · progress) (0 outside the swing)."""
    u = np.clip((times - start) / (end - start), 0.0, 1.0)
    progress = u * u * (3 - 2 * u)
    return progress, np.where((times > start) & (times < end), np.sin(np.pi * u), 0.0)


def _stepping(height, frame_rate, steps, step_time):
    """The common frame of the stepping actions: (scale of REFERENCE_HEIGHT, rest [s] standing before and
    after, duration [s], sample times (T,) [s], the standing body's forward and left (3,), its ankles
    (2, 3) [m] and their midpoint (3,))."""
    rest = STEPPING_REST
    duration = 2 * rest + steps * step_time
    _, rest_joints, heading = standing_pose(height)
    ankles = rest_joints[[JOINT_INDEX['left_ankle'], JOINT_INDEX['right_ankle']]]
    return (height / REFERENCE_HEIGHT, rest, duration, sample_times(duration, frame_rate), heading[:, 1],
            -heading[:, 0], ankles, ankles.mean(axis=0))


def turn_on_the_spot(height=1.75, frame_rate=FRAME_RATE, first_frame=0, steps=9, step_time=0.55, swing_time=0.4):
    """A full turn to the left (360°) on the spot in `steps` small steps (6.15 s): the feet take turns,
    each landing 45° further round than the other (90° per step) and the last one closing up; the body
    turns smoothly to the mean of the feet's headings, the head leading by up to 12°; the pelvis stays
    over the spot, shifting a little towards the standing foot."""
    scale, rest, duration, times, forward, left, ankles, centre = _stepping(height, frame_rate, steps, step_time)
    half_width = np.dot(ankles[0] - centre, left)
    ankle_height = ANKLE_HEIGHT_PER_HEIGHT * height
    # Foot headings [rad] over time: step k moves foot k % 2 (left first) to 45° beyond the other one.
    headings = np.zeros((len(times), 2))
    lifts = np.zeros((len(times), 2))
    landed = [0.0, 0.0]
    knots_t, knots_turn = [0.0, rest], [0.0, 0.0]
    for k in range(steps):
        foot = k % 2
        target = landed[1 - foot] + (np.radians(45.0) if k < steps - 1 else 0.0)
        start = rest + k * step_time
        progress, lift = _swing(times, start, start + swing_time)
        headings[:, foot] += (target - landed[foot]) * progress
        lifts[:, foot] += lift
        landed[foot] = target
        knots_t.append(start + swing_time + 0.5 * (step_time - swing_time))
        knots_turn.append(np.mean(landed))
    knots_t.append(duration)
    knots_turn.append(np.mean(landed))
    turn = PchipInterpolator(knots_t, knots_turn)(times)
    turning = PchipInterpolator(knots_t, knots_turn).derivative()(times)
    feet = np.empty((len(times), 2, 3))
    knee_forward = np.empty_like(feet)
    for foot, sign in enumerate((1.0, -1.0)):
        cos, sin = np.cos(headings[:, foot])[:, None], np.sin(headings[:, foot])[:, None]
        foot_forward = cos * forward + sin * left     # turned to the left by the heading
        foot_left = cos * left - sin * forward
        feet[:, foot] = centre + sign * half_width * foot_left
        feet[:, foot, 2] = ankle_height + LIFT * scale * lifts[:, foot]
        knee_forward[:, foot] = foot_forward
    # The pelvis leans a third of the way towards the standing foot while the other swings.
    standing_foot = lifts[:, ::-1]
    shift = (standing_foot[:, :, None] * (feet - centre)).sum(axis=1) / 3
    shift[:, 2] = 0.0
    keys = [(0.0, {}), (rest, {}), (rest + 0.3, {'down': SOFT_KNEES}), (duration - rest, {'down': SOFT_KNEES}),
            (duration - 0.2, {}), (duration, {})]
    tracks = eased(keys, times)
    tracks['torso_rz'] = np.degrees(turn)
    tracks['head_rz'] = 12.0 * turning / max(np.abs(turning).max(), 1e-9)
    tracks['left_forearm_rx'] = tracks['right_forearm_rx'] = np.full(len(times), 20.0)
    return perform(times, tracks, height, frame_rate, first_frame, feet=feet, knee_forward=knee_forward,
                   pelvis_shift=shift)


def walk_backwards(height=1.75, frame_rate=FRAME_RATE, first_frame=0, steps=8, step_length=0.36, step_time=0.6,
                   swing_time=0.45):
    """Walking backwards (6.0 s): from standing, `steps` − 1 steps of step_length [m at 1.75 m] back,
    right foot first, at 100 steps a minute (0.6 m/s), the last step closing up, then standing. The
    stance foot stays put; the pelvis, lowered by CROUCH, moves back smoothly over the stance foot,
    swaying a little towards it; the arms swing against the legs; the trunk leans 4° forward."""
    scale, rest, duration, times, forward, left, ankles, centre = _stepping(height, frame_rate, steps, step_time)
    length = step_length * scale
    back = np.zeros((len(times), 2))   # each foot's distance back from the start [m]
    lifts = np.zeros((len(times), 2))
    placed = [0.0, 0.0]
    knots_t, knots_back = [0.0, rest], [0.0, 0.0]
    sway_t, sway = [0.0, rest], [0.0, 0.0]
    for k in range(steps):
        foot = 1 - k % 2             # right (1) first
        target = (k + 1) * length if k < steps - 1 else placed[1 - foot]
        start = rest + k * step_time
        progress, lift = _swing(times, start, start + swing_time)
        back[:, foot] += (target - placed[foot]) * progress
        lifts[:, foot] += lift
        middle = start + swing_time / 2
        if 0 < k < steps - 1:        # mid-swing: the pelvis over the standing foot
            knots_t.append(middle)
            knots_back.append(placed[1 - foot])
        sway_t.append(middle)
        sway.append(0.025 * (1.0 if foot == 1 else -1.0))  # towards the standing foot: left while the right swings
        placed[foot] = target
    knots_t += [duration - rest + 0.2, duration]
    knots_back += [placed[0], placed[0]]
    sway_t += [duration - rest + 0.2, duration]
    sway += [0.0, 0.0]
    pelvis_back = PchipInterpolator(knots_t, knots_back)(times)
    feet = np.empty((len(times), 2, 3))
    for foot, sign in enumerate((1.0, -1.0)):
        feet[:, foot] = centre + sign * np.dot(ankles[0] - centre, left) * left - back[:, foot, None] * forward
        feet[:, foot, 2] = ANKLE_HEIGHT_PER_HEIGHT * height + 0.85 * LIFT * scale * lifts[:, foot]
    walking = {'down': CROUCH, 'torso_rx': -4, 'head_rx': -6}
    keys = [(0.0, {}), (rest - 0.2, {}), (rest + 0.2, walking), (duration - rest, walking), (duration - 0.1, {}),
            (duration, {})]
    tracks = eased(keys, times)
    tracks['forward'] = -pelvis_back / scale
    tracks['left'] = PchipInterpolator(sway_t, sway)(times)
    # Arms swing against the legs: an arm forwards when its own foot is behind the pelvis.
    for foot, side in enumerate(SIDES):
        behind = np.clip((back[:, foot] - pelvis_back) / (length / 2), -1.0, 1.0)
        tracks[f'{side}_upper_arm_rx'] = 16.0 * behind
        tracks[f'{side}_forearm_rx'] = 15.0 + 10.0 * np.clip(behind, 0.0, 1.0)
    return perform(times, tracks, height, frame_rate, first_frame, feet=feet)
