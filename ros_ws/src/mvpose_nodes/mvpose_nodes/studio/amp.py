"""Motions of the AMP humanoid (IsaacGymEnvs' amp_humanoid_*.npy, retargeted from CMU clips; shipped in
studio/motions with README-motions.md and the BSD-3 licence) as BodyMotions of the 15-joint body model.

Each file is one pickled dict (poselib's SkeletonMotion): 15 bodies with their parents and origins in
the parent's frame, per frame each body's rotation relative to its parent (quaternions x, y, z, w) and
the root's position; world z up, metres, the humanoid facing +x with its left at +y. Body origins are
joint centres; the head body's origin is the base of the neck, its head a sphere of radius 0.095 m
centred 0.175 m up its z axis; each foot a box whose front face is 0.1335 m ahead of the ankle
(centre 0.045 + half length 0.0885, amp_humanoid.xml) and whose sole is 0.05 m below it.

Resampling works on the rotations (spherical interpolation per body, linear for the root), so bones
keep their lengths even in the 16-fps backflip. NumPy and SciPy only (no rclpy).
"""
import dataclasses
import pickle
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from mvpose_nodes.body.model import JOINT_INDEX, JOINT_NAMES
from mvpose_nodes.studio.i3dpost import FRAME_RATE
from mvpose_nodes.studio.mocap import ANKLE_HEIGHT_PER_HEIGHT, BodyMotion, MotionFileError, shipped_file
from mvpose_nodes.studio.scripted_motion import HAND_LENGTH

AMP_BODIES = ('pelvis', 'torso', 'head', 'right_upper_arm', 'right_lower_arm', 'right_hand', 'left_upper_arm',
              'left_lower_arm', 'left_hand', 'right_thigh', 'right_shin', 'right_foot', 'left_thigh', 'left_shin',
              'left_foot')
HEAD_VERTEX = 0.175 + 0.095   # [m] the top of the head sphere, up the head body's z axis from its origin
FOOT_REACH = 0.045 + 0.0885   # [m] the foot box's front face, along the foot body's x axis from the ankle
# Body-model joint → the AMP bodies whose origins it is the mean of (the head: see HEAD_VERTEX).
JOINT_BODIES = {
    'pelvis': ('left_thigh', 'right_thigh'), 'left_hip': ('left_thigh',), 'left_knee': ('left_shin',),
    'left_ankle': ('left_foot',), 'right_hip': ('right_thigh',), 'right_knee': ('right_shin',),
    'right_ankle': ('right_foot',), 'neck': ('head',), 'head': ('head',),
    'left_shoulder': ('left_upper_arm',), 'left_elbow': ('left_lower_arm',), 'left_wrist': ('left_hand',),
    'right_shoulder': ('right_upper_arm',), 'right_elbow': ('right_lower_arm',), 'right_wrist': ('right_hand',),
}
BODY_INDEX = {name: index for index, name in enumerate(AMP_BODIES)}


def motions_directory():
    """The motions shipped with the package (studio/motions, package data of mvpose_nodes.studio)."""
    return Path(__file__).resolve().parent / 'motions'


@dataclasses.dataclass(frozen=True)
class AmpMotion:
    """An AMP humanoid motion: parents (15,) int64 (−1: the root), offsets (15, 3) [m] of each body's
    origin in its parent's frame, rotations (F, 15, 4) unit quaternions x, y, z, w relative to the parent
    (the root's: in the world), root (F, 3) [m] the root body's origin in the world, frame_time [s]."""
    path: Path
    parents: np.ndarray
    offsets: np.ndarray
    rotations: np.ndarray
    root: np.ndarray
    frame_time: float

    @property
    def frame_count(self):
        return len(self.root)

    @property
    def duration(self):
        return (self.frame_count - 1) * self.frame_time

    def frames(self, index):
        """The motion of frames `index` (an index array or slice)."""
        return dataclasses.replace(self, rotations=self.rotations[index], root=self.root[index])

    def global_transforms(self):
        """World rotations (F, 15, 3, 3) and origins (F, 15, 3) [m] of the bodies by forward kinematics:
        R_world = R_world[parent] · R; p_world = p_world[parent] + R_world[parent] · offset."""
        count = self.frame_count
        local = Rotation.from_quat(self.rotations.reshape(-1, 4)).as_matrix().reshape(count, len(self.parents), 3, 3)
        rotations, positions = np.empty_like(local), np.empty((count, len(self.parents), 3))
        for body, parent in enumerate(self.parents):  # parents come first
            if parent < 0:
                rotations[:, body], positions[:, body] = local[:, body], self.root
            else:
                rotations[:, body] = rotations[:, parent] @ local[:, body]
                positions[:, body] = positions[:, parent] + rotations[:, parent] @ self.offsets[body]
        return rotations, positions


def _field(data, path, *keys):
    try:
        for key in keys:
            data = data[key]
    except (KeyError, TypeError, IndexError):
        raise MotionFileError(f'{path}: not an AMP motion: no {"/".join(keys)}') from None
    return data


def load_amp(path):
    """Read an AMP .npy; MotionFileError naming the file when it is missing or not an AMP motion.

    IsaacGymEnvs' 60-fps files hold 30-fps motion, every frame stored twice (frames 2k and 2k + 1 are
    equal): such pairs are merged and the frame time doubled, or resampling would make the motion stutter."""
    path = Path(path)
    try:
        data = np.load(path, allow_pickle=True).item()
    except (OSError, ValueError, EOFError, AttributeError, pickle.UnpicklingError) as error:
        raise MotionFileError(f'{path}: cannot read an AMP motion: {error}') from None
    names = tuple(_field(data, path, 'skeleton_tree', 'node_names'))
    if names != AMP_BODIES:
        raise MotionFileError(f'{path}: bodies {", ".join(names)}; expected the AMP humanoid\'s {", ".join(AMP_BODIES)}')
    if not _field(data, path, 'is_local'):
        raise MotionFileError(f'{path}: rotations are global; expected local ones (is_local True)')
    parents = np.asarray(_field(data, path, 'skeleton_tree', 'parent_indices', 'arr'), dtype=np.int64)
    offsets = np.asarray(_field(data, path, 'skeleton_tree', 'local_translation', 'arr'), dtype=float)
    rotations = np.asarray(_field(data, path, 'rotation', 'arr'), dtype=float)
    root = np.asarray(_field(data, path, 'root_translation', 'arr'), dtype=float)
    fps = float(_field(data, path, 'fps'))
    count = len(root)
    if (parents.shape != (15,) or offsets.shape != (15, 3) or rotations.shape != (count, 15, 4)
            or root.shape != (count, 3) or count < 2 or not fps > 0):
        raise MotionFileError(f'{path}: malformed AMP motion (rotations {rotations.shape}, root {root.shape}, '
                              f'fps {fps})')
    if any(parent >= body for body, parent in enumerate(parents)):
        raise MotionFileError(f'{path}: a body comes before its parent')
    rotations = rotations / np.linalg.norm(rotations, axis=-1, keepdims=True)
    frame_time = 1.0 / fps
    even = np.arange(0, count - 1, 2)
    if count >= 4 and np.array_equal(rotations[even], rotations[even + 1]) and np.array_equal(root[even], root[even + 1]):
        rotations, root, frame_time = rotations[::2], root[::2], 2 * frame_time
    return AmpMotion(path=path, parents=parents, offsets=offsets, rotations=rotations, root=root,
                     frame_time=frame_time)


def amp_clip(name):
    """A shipped AMP motion by name ('amp_run' or 'amp_run.npy'), loaded; MotionFileError when missing."""
    return load_amp(shipped_file(motions_directory(), name, '.npy', 'AMP motion'))


def resampled(motion, frame_rate):
    """The motion at frame_rate [Hz]: times m / frame_rate over the same span (as mocap.resample); each
    body's rotation by spherical linear interpolation, the root's position linearly."""
    count = int(np.floor(motion.duration * frame_rate + 1e-9)) + 1
    source = np.arange(motion.frame_count) * motion.frame_time
    times = np.minimum(np.arange(count) / frame_rate, source[-1])
    rotations = np.stack([Slerp(source, Rotation.from_quat(motion.rotations[:, body]))(times).as_quat()
                          for body in range(len(motion.parents))], axis=1)
    root = np.stack([np.interp(times, source, motion.root[:, axis]) for axis in range(3)], axis=1)
    return dataclasses.replace(motion, rotations=rotations, root=root, frame_time=1.0 / frame_rate)


def _travel(motion, first, last):
    """The root's horizontal displacement from frame `first` to frame `last` (z: 0)."""
    shift = motion.root[last] - motion.root[first]
    shift[2] = 0.0
    return shift


def best_cycle(motion, shortest=0.5):
    """(start, stop): the frame pair at least `shortest` [s] apart whose poses are most alike (every
    body's rotation, the root's included, and the root's height), for looping: frames start..stop − 1 are
    one cycle of a periodic motion such as running."""
    gap = int(np.ceil(shortest / motion.frame_time))
    best, pair = np.inf, None
    for start in range(motion.frame_count - gap):
        stops = np.arange(start + gap, motion.frame_count)
        alike = np.abs(np.einsum('fbi,bi->fb', motion.rotations[stops], motion.rotations[start]))
        cost = (1.0 - alike).sum(axis=1) + np.abs(motion.root[stops, 2] - motion.root[start, 2])
        if cost.min() < best:
            best, pair = cost.min(), (start, int(stops[np.argmin(cost)]))
    if pair is None:
        raise MotionFileError(f'{motion.path}: shorter than one cycle of {shortest} s')
    return pair


def looped(motion, start, stop, count):
    """The motion with its cycle (frames start..stop − 1) played `count` times: the frames before it, the
    cycles each carried on by the cycle's horizontal travel, then the frames from `stop` on."""
    travel = _travel(motion, start, stop)
    parts = [motion.frames(slice(0, start))]
    for repeat in range(count):
        part = motion.frames(slice(start, stop))
        parts.append(dataclasses.replace(part, root=part.root + repeat * travel))
    tail = motion.frames(slice(stop, None))
    parts.append(dataclasses.replace(tail, root=tail.root + (count - 1) * travel))
    return _joined(motion, parts)


def repeated(motion, count, pause):
    """The motion played `count` times, each from where the last ended (shifted by its horizontal travel),
    with its first pose held for `pause` [s] before, between and after. The motion must end in the pose
    it starts in (the AMP backflip does: standing)."""
    held = max(int(round(pause / motion.frame_time)), 0)
    travel = _travel(motion, 0, -1)
    parts = []
    for repeat in range(count):
        shift, first = repeat * travel, 1 if repeat else 0  # a repeat's frame 0 is the pose just held
        pause_frames = motion.frames(np.zeros(held, dtype=int))
        parts.append(dataclasses.replace(pause_frames, root=pause_frames.root + shift))
        parts.append(dataclasses.replace(motion.frames(slice(first, None)), root=motion.root[first:] + shift))
    last = motion.frames(np.full(held, motion.frame_count - 1))
    parts.append(dataclasses.replace(last, root=last.root + (count - 1) * travel))
    return _joined(motion, parts)


def _joined(motion, parts):
    return dataclasses.replace(motion, rotations=np.concatenate([part.rotations for part in parts]),
                               root=np.concatenate([part.root for part in parts]))


def rest_span(motion):
    """[m] the AMP humanoid's vertex above its ankles standing straight (the offsets' rest pose): ankle →
    knee → hip, pelvis → torso → base of the neck, then HEAD_VERTEX (1.561 m)."""
    legs = -sum(motion.offsets[BODY_INDEX[body], 2] for body in ('left_foot', 'left_shin'))
    trunk = sum(motion.offsets[BODY_INDEX[body], 2] for body in ('torso', 'head'))
    return legs + trunk + HEAD_VERTEX


def body_motion(motion, height=1.75, frame_rate=FRAME_RATE, first_frame=0):
    """The AMP motion as a BodyMotion of a person `height` [m] tall, at frame_rate [Hz].

    Joints (JOINT_BODIES): pelvis = midpoint of the thigh origins (hip joint centres), hips = thighs,
    knees = shins, ankles = feet, neck = the head body's origin (base of the neck), head = its vertex
    (HEAD_VERTEX up the head body's z axis), shoulders = upper arms, elbows = lower arms, wrists = hands.
    Toes: the front of the foot box at the sole (FOOT_REACH along the foot's x axis, the studio's ankle
    height down its z axis); hand tips: a hand length (scripted_motion.HAND_LENGTH · height) beyond the
    wrist along the forearm; head_forward: the head body's x axis (the humanoid faces +x at rest).
    Scaled uniformly (travel and flight too) so that the rest pose is `height` tall with its ankles at the
    studio's ankle height (rest_span = height − that ankle height), then shifted in z so that the lowest
    ankle over the motion is at that height (0.075 m at 1.75 m), as mocap.retarget places the floor. The floor is not turned:
    the AMP motions' floor is the simulator's plane z = 0, level along their travel (the hop's stance
    ankles over 2.6 m: 0.1°), while a plane fitted as mocap.floor_levelling does would be ill-conditioned
    across it (the contacts span 4–34 cm sideways) and tilt it by up to 2.4°."""
    motion = resampled(motion, frame_rate)
    rotations, positions = motion.global_transforms()
    scale = height * (1.0 - ANKLE_HEIGHT_PER_HEIGHT) / rest_span(motion)
    head = BODY_INDEX['head']
    joints = np.stack([positions[:, [BODY_INDEX[body] for body in JOINT_BODIES[name]]].mean(axis=1)
                       for name in JOINT_NAMES], axis=1)
    joints[:, JOINT_INDEX['head']] = positions[:, head] + rotations[:, head, :, 2] * HEAD_VERTEX
    joints *= scale
    ankle_height = ANKLE_HEIGHT_PER_HEIGHT * height
    toes, tips = [], []
    for side in ('left', 'right'):
        foot = rotations[:, BODY_INDEX[f'{side}_foot']]
        toes.append(joints[:, JOINT_INDEX[f'{side}_ankle']] + FOOT_REACH * scale * foot[:, :, 0]
                    - ankle_height * foot[:, :, 2])
        wrist, elbow = joints[:, JOINT_INDEX[f'{side}_wrist']], joints[:, JOINT_INDEX[f'{side}_elbow']]
        forearm = (wrist - elbow) / np.linalg.norm(wrist - elbow, axis=-1, keepdims=True)
        tips.append(wrist + HAND_LENGTH * height * forearm)
    toes, tips = np.stack(toes, axis=1), np.stack(tips, axis=1)
    ankles = joints[:, [JOINT_INDEX['left_ankle'], JOINT_INDEX['right_ankle']], 2]
    lift = np.array([0.0, 0.0, ankle_height - ankles.min()])
    return BodyMotion(frame_rate=float(frame_rate), first_frame=first_frame, joints=joints + lift, toes=toes + lift,
                      hand_tips=tips + lift, head_forward=rotations[:, head, :, 0].copy())
