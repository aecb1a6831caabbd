"""Motion-capture ground truth: BVH files, and CMU clips retargeted to the 15-joint body model.

Sources: the BVH format (Biovision; hierarchy of ROOT/JOINT/End Site with OFFSET and CHANNELS, then
MOTION rows), and the CMU Graphics Lab Motion Capture Database in B. Hahne's MotionBuilder-friendly
BVH conversion (shipped in studio/cmu with its README-cmu.txt: frame 1 of every file is an added T-pose facing
+Z, Y up, subject's left at +X, 120 fps) and in his 3dsMax-friendly one (studio/motions/cmu_131_01.bvh, see
README-motions.md: the same skeleton and axes under other joint names, and no added T-pose).

Project world: metres, z up, floor at z = 0. NumPy only (no rclpy), so tests and tools can use it
without a ROS graph.
"""
import dataclasses
from pathlib import Path

import numpy as np

from mvpose_nodes.studio.i3dpost import FRAME_RATE
from mvpose_nodes.body.model import JOINT_NAMES
from mvpose_nodes.body.geometry import matrix_from_quaternion, rotation_between


class MotionFileError(ValueError):
    """A motion-capture file or clip that is missing or malformed; the message names the file (and line)."""


# +90° about x: BVH (x, y, z) → project (x, −z, y); Y up becomes z up, the T-pose's +Z facing becomes −y.
BVH_TO_WORLD = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
ANKLE_HEIGHT_PER_HEIGHT = 0.075 / 1.75  # ankle joint centre above the sole, per metre of standing height
# The CMU "Neck" joint (lowerneck) sits at the thorax, below the shoulder line; 0.6 of the way up to
# Neck1 (upperneck) brings it to the base of the neck between the shoulders (body_model P8).
NECK_FRACTION = 0.6
SWAY_AMPLITUDE = 0.004  # [m] horizontal sway of the head in standing_motion
BODY_JOINT_SOURCES = {  # body-model joint → weights of BVH points whose weighted sum it is
    'pelvis': {'LeftUpLeg': 0.5, 'RightUpLeg': 0.5},
    'left_hip': {'LeftUpLeg': 1.0}, 'left_knee': {'LeftLeg': 1.0}, 'left_ankle': {'LeftFoot': 1.0},
    'right_hip': {'RightUpLeg': 1.0}, 'right_knee': {'RightLeg': 1.0}, 'right_ankle': {'RightFoot': 1.0},
    'neck': {'Neck': 1.0 - NECK_FRACTION, 'Neck1': NECK_FRACTION},
    'head': {'Head_end': 1.0},
    'left_shoulder': {'LeftArm': 1.0}, 'left_elbow': {'LeftForeArm': 1.0}, 'left_wrist': {'LeftHand': 1.0},
    'right_shoulder': {'RightArm': 1.0}, 'right_elbow': {'RightForeArm': 1.0}, 'right_wrist': {'RightHand': 1.0},
}
TOE_TIPS = ('LeftToeBase_end', 'RightToeBase_end')
HAND_TIPS = ('LeftHandIndex1_end', 'RightHandIndex1_end')
# The 3dsMax-friendly release names the points that retargeting reads otherwise (MotionBuilder name → its
# name). Its lowerneck and Neck are MotionBuilder's Neck (top of the thorax) and Neck1 (upper neck).
THREE_DS_MAX_NAMES = {
    **{f'{side}{motion_builder}': f'{side}{max_name}' for side in ('Left', 'Right') for motion_builder, max_name in (
        ('UpLeg', 'Hip'), ('Leg', 'Knee'), ('Foot', 'Ankle'), ('ToeBase', 'Toe'), ('ToeBase_end', 'Toe_end'),
        ('Arm', 'Shoulder'), ('ForeArm', 'Elbow'), ('Hand', 'Wrist'))},
    'LeftHandIndex1_end': 'LFingers_end', 'RightHandIndex1_end': 'RFingers_end',
    'Neck': 'lowerneck', 'Neck1': 'Neck',
}
TPOSE_ARM_SLOPE = np.sin(np.radians(20.0))  # frame 1 is a T-pose when both upper arms are within 20° of level
CHANNEL_NAMES = ('Xposition', 'Yposition', 'Zposition', 'Xrotation', 'Yrotation', 'Zrotation')


def cmu_directory():
    """The CMU clips shipped with the package: package data of mvpose_nodes.studio (studio/cmu), so that
    the studio finds them without ROS's ament index."""
    return Path(__file__).resolve().parent / 'cmu'


def shipped_file(directory, name, suffix, what):
    """Path of the file `name` (with or without `suffix`, e.g. '.bvh') in `directory`; MotionFileError
    naming the `what` ('motion-capture clip') and the ones there are when missing."""
    path = directory / (name if name.endswith(suffix) else f'{name}{suffix}')
    if not path.is_file():
        known = ', '.join(sorted(p.stem for p in directory.glob(f'*{suffix}')))
        raise MotionFileError(f'no {what} {path.name} in {directory} (there are: {known})')
    return path


def cmu_clip(name):
    """Path of a shipped CMU clip by name ('07_01' or '07_01.bvh'); MotionFileError when missing."""
    return shipped_file(cmu_directory(), name, '.bvh', 'motion-capture clip')


def elementary_rotations(axis, degrees):
    """(N, 3, 3) rotation matrices about BVH axis 'X', 'Y' or 'Z' by angles (N,) [deg] (right-handed)."""
    radians = np.radians(degrees)
    cos, sin = np.cos(radians), np.sin(radians)
    k = 'XYZ'.index(axis)
    i, j = (k + 1) % 3, (k + 2) % 3
    matrices = np.zeros((len(radians), 3, 3))
    matrices[:, k, k] = 1.0
    matrices[:, i, i] = matrices[:, j, j] = cos
    matrices[:, i, j], matrices[:, j, i] = -sin, sin
    return matrices


@dataclasses.dataclass(frozen=True)
class Bvh:
    """A parsed BVH file. Points are the joints and End Sites in file order (a parent before its
    children); an End Site is named after its joint plus '_end' (e.g. 'Head_end') and has no channels.

    names: (J,) str; parents: (J,) int64, −1 for the root; offsets: (J, 3) float64 [BVH units], from the
    parent in its frame; channels: (J,) tuples of channel names in file order; motion: (F, C) float64,
    one row per frame, channels in the order of `channels` (positions in BVH units, rotations [deg]);
    frame_time [s]. Row 0 is the file's frame 1.
    """
    path: Path
    names: tuple
    parents: np.ndarray
    offsets: np.ndarray
    channels: tuple
    motion: np.ndarray
    frame_time: float

    @property
    def frame_count(self):
        return len(self.motion)

    def index(self, name):
        """Index of the joint or End Site `name`; MotionFileError naming the file when there is none."""
        if name not in self.names:
            raise MotionFileError(f'{self.path}: no joint {name} (expected a CMU MotionBuilder- or '
                                  f'3dsMax-friendly skeleton)')
        return self.names.index(name)

    def global_transforms(self, frames=None):
        """World rotations (F, J, 3, 3) and positions (F, J, 3) float64 [BVH units, BVH axes] of every
        point by forward kinematics: global = parent_global · translate(offset + position channels) ·
        rotate(local), local = product of the elementary rotations in channel order (Zrotation
        Yrotation Xrotation → Rz·Ry·Rx). frames: row index or indices into `motion` (default all)."""
        motion = self.motion if frames is None else np.atleast_2d(self.motion[frames])
        count = len(motion)
        rotations = np.empty((count, len(self.names), 3, 3))
        positions = np.empty((count, len(self.names), 3))
        column = 0
        for point, (parent, channels) in enumerate(zip(self.parents, self.channels)):
            local = np.broadcast_to(np.eye(3), (count, 3, 3))
            translation = np.broadcast_to(self.offsets[point], (count, 3)).copy()
            for channel in channels:
                axis, kind = channel[0], channel[1:]
                if kind == 'rotation':
                    local = local @ elementary_rotations(axis, motion[:, column])
                else:
                    translation[:, 'XYZ'.index(axis)] += motion[:, column]
                column += 1
            if parent < 0:
                rotations[:, point], positions[:, point] = local, translation
            else:
                rotations[:, point] = rotations[:, parent] @ local
                positions[:, point] = positions[:, parent] + np.einsum('fij,fj->fi', rotations[:, parent], translation)
        return rotations, positions

    def global_positions(self, frames=None):
        """(F, J, 3) float64 world positions [BVH units, BVH axes] of every joint and End Site."""
        return self.global_transforms(frames)[1]


class BvhReader:
    """Whitespace tokens of a BVH file with their line numbers, read front to back."""

    def __init__(self, path, text):
        self.path = path
        self.tokens = [(number, word) for number, line in enumerate(text.splitlines(), 1) for word in line.split()]
        self.position = 0

    def error(self, message):
        line = self.tokens[min(self.position, len(self.tokens) - 1)][0] if self.tokens else 1
        return MotionFileError(f'{self.path}: line {line}: {message}')

    def peek(self):
        return self.tokens[self.position][1] if self.position < len(self.tokens) else None

    def take(self, *expected):
        """The next token; with `expected`, it must be one of them."""
        word = self.peek()
        if word is None or (expected and word not in expected):
            raise self.error(f'expected {" or ".join(expected) or "more"}, found {word or "end of file"}')
        self.position += 1
        return word

    def number(self, kind=float):
        word = self.peek()
        try:
            value = kind(word)
        except (TypeError, ValueError):
            raise self.error(f'expected a number, found {word or "end of file"}') from None
        self.position += 1
        return value

    def point(self, name, parent, points):
        """Read one joint's block (after its name) and its children into `points`, a list of
        (name, parent, offset, channels)."""
        self.take('{')
        self.take('OFFSET')
        offset = [self.number() for _ in range(3)]
        channels = ()
        if not name.endswith('_end'):
            self.take('CHANNELS')
            count = self.number(int)
            channels = tuple(self.take(*CHANNEL_NAMES) for _ in range(count))
        points.append((name, parent, offset, channels))
        index = len(points) - 1
        while self.peek() != '}':
            if self.take('JOINT', 'End', '}') == 'JOINT':
                self.point(self.take(), index, points)
            else:
                self.take('Site')
                self.point(f'{name}_end', index, points)
        self.take('}')


def load_bvh(path):
    """Parse the BVH file at `path` into a Bvh; MotionFileError naming the file and line when malformed."""
    path = Path(path)
    try:
        reader = BvhReader(path, path.read_text())
    except (OSError, UnicodeDecodeError) as error:
        raise MotionFileError(f'{path}: cannot read: {error}') from None
    points = []
    reader.take('HIERARCHY')
    reader.take('ROOT')
    reader.point(reader.take(), -1, points)
    reader.take('MOTION')
    reader.take('Frames:')
    frame_count = reader.number(int)
    reader.take('Frame')
    reader.take('Time:')
    frame_time = reader.number()
    if frame_time <= 0:
        raise reader.error(f'Frame Time must be positive, found {frame_time}')
    channel_count = sum(len(channels) for *_, channels in points)
    rows = {}
    for number, word in reader.tokens[reader.position:]:
        rows.setdefault(number, []).append(word)
    if len(rows) != frame_count:
        raise reader.error(f'Frames: {frame_count}, but {len(rows)} rows of motion follow')
    for number, row in rows.items():
        if len(row) != channel_count:
            raise MotionFileError(f'{path}: line {number}: expected {channel_count} channel values, found {len(row)}')
    try:
        motion = np.array(list(rows.values()), dtype=float).reshape(frame_count, channel_count)
    except ValueError:
        raise MotionFileError(f'{path}: motion rows hold a value that is not a number') from None
    names, parents, offsets, channels = zip(*points)
    return Bvh(path=path, names=names, parents=np.array(parents), offsets=np.array(offsets, dtype=float),
               channels=channels, motion=motion, frame_time=frame_time)


@dataclasses.dataclass(frozen=True)
class BodyMotion:
    """A person's motion in the project world (metres, z up, floor at z = 0) sampled at frame_rate [Hz].

    first_frame: frame number of index 0; joints: (F, 15, 3) float64 [m] in body_model.JOINT_NAMES order;
    toes: (F, 2, 3) [m] toe tips (left, right); hand_tips: (F, 2, 3) [m] fingertips (left, right);
    head_forward: (F, 3) unit vectors, the direction the face looks.
    """
    frame_rate: float
    first_frame: int
    joints: np.ndarray
    toes: np.ndarray
    hand_tips: np.ndarray
    head_forward: np.ndarray

    def read_only(self):
        """The motion with read-only copies of its arrays, for one shared by several users."""
        arrays = {field.name: np.array(getattr(self, field.name)) for field in dataclasses.fields(self)
                  if isinstance(getattr(self, field.name), np.ndarray)}
        for array in arrays.values():
            array.setflags(write=False)
        return dataclasses.replace(self, **arrays)

    @property
    def frame_numbers(self):
        """(F,) int64 frame numbers first_frame, first_frame + 1, …"""
        return np.arange(self.first_frame, self.first_frame + len(self.joints))

    def select(self, first, last):
        """The frames numbered first..last (inclusive); MotionFileError naming the available range."""
        available = self.frame_numbers
        if not available[0] <= first <= last <= available[-1]:
            raise MotionFileError(f'frames {first}..{last} are not in the motion: it has frames '
                            f'{available[0]}..{available[-1]}')
        window = slice(first - self.first_frame, last - self.first_frame + 1)
        return dataclasses.replace(self, first_frame=first, joints=self.joints[window], toes=self.toes[window],
                                   hand_tips=self.hand_tips[window], head_forward=self.head_forward[window])

    def placed(self, center=(0.0, 0.0), heading=0.0):
        """The motion turned about the vertical so that the mean horizontal pelvis velocity points along
        `heading` [rad, from +x towards +y], then shifted horizontally so that the mean pelvis (x, y) is
        `center` [m]; z is unchanged. A person who hardly travels (mean pelvis speed below 0.1 m/s) is
        turned by the mean horizontal head_forward instead, since their velocity is mere sway."""
        pelvis = self.joints[:, JOINT_NAMES.index('pelvis'), :2]
        duration = max(len(pelvis) - 1, 1) / self.frame_rate
        direction = (pelvis[-1] - pelvis[0]) / duration
        if np.linalg.norm(direction) < 0.1:
            direction = self.head_forward[:, :2].mean(axis=0)
        angle = heading - np.arctan2(direction[1], direction[0])
        cos, sin = np.cos(angle), np.sin(angle)
        turn = np.array([[cos, -sin, 0.0], [sin, cos, 0.0], [0.0, 0.0, 1.0]])
        shift = np.zeros(3)
        shift[:2] = np.asarray(center, dtype=float) - (pelvis @ turn[:2, :2].T).mean(axis=0)
        return dataclasses.replace(self, joints=self.joints @ turn.T + shift, toes=self.toes @ turn.T + shift,
                                   hand_tips=self.hand_tips @ turn.T + shift, head_forward=self.head_forward @ turn.T)


def is_three_ds_max(bvh):
    """Whether the BVH names its joints as the 3dsMax-friendly CMU release does (LeftHip, …) rather than
    as the MotionBuilder-friendly one (LeftUpLeg, …)."""
    return 'LeftUpLeg' not in bvh.names and 'LeftHip' in bvh.names


def point_index(bvh, name):
    """Index of the point that MotionBuilder's skeleton calls `name`, in either naming (THREE_DS_MAX_NAMES);
    MotionFileError naming the file when there is none."""
    return bvh.index(THREE_DS_MAX_NAMES.get(name, name) if is_three_ds_max(bvh) else name)


def point_weights(bvh, sources):
    """(K, J) weights such that weights @ bvh points gives the K points named by `sources`
    (a sequence of {BVH point name: weight}, in MotionBuilder's names; see point_index)."""
    weights = np.zeros((len(sources), len(bvh.names)))
    for row, source in enumerate(sources):
        for name, weight in source.items():
            weights[row, point_index(bvh, name)] += weight
    return weights


def neck_fraction(bvh):
    """How far the neck (base of the neck, between the shoulders) lies from MotionBuilder's Neck (top of
    the thorax) towards Neck1 (upper neck). MotionBuilder-friendly clips: NECK_FRACTION, as tuned on
    subject 7. Otherwise the level of the shoulders' midpoint on that segment in the standing reference
    pose (reference_pose), since the clavicles' rise differs from subject to subject (131: 0.86, its
    lowerneck is 8 cm below the shoulder joints)."""
    if not is_three_ds_max(bvh):
        return NECK_FRACTION
    pose = reference_pose(bvh)
    thorax, upper = pose[point_index(bvh, 'Neck')], pose[point_index(bvh, 'Neck1')]
    shoulders = (pose[point_index(bvh, 'LeftArm')] + pose[point_index(bvh, 'RightArm')]) / 2
    segment = upper - thorax
    return float(np.dot(shoulders - thorax, segment) / np.dot(segment, segment))


def body_points(bvh, positions):
    """Joints (F, 15, 3), toes (F, 2, 3), hand tips (F, 2, 3) from BVH point positions (F, J, 3), in the
    same units and axes."""
    joint_sources = BODY_JOINT_SOURCES
    if is_three_ds_max(bvh):
        fraction = neck_fraction(bvh)
        joint_sources = {**BODY_JOINT_SOURCES, 'neck': {'Neck': 1.0 - fraction, 'Neck1': fraction}}
    sources = [joint_sources[name] for name in JOINT_NAMES] + [{name: 1.0} for name in TOE_TIPS + HAND_TIPS]
    points = np.einsum('kj,fjc->fkc', point_weights(bvh, sources), positions)
    return points[:, :len(JOINT_NAMES)], points[:, -4:-2], points[:, -2:]


def has_tpose(bvh):
    """Whether frame 1 is a T-pose, as the MotionBuilder-friendly files add one: both upper arms level
    (within 20°). The 3dsMax-friendly release starts with the motion itself."""
    pose = bvh.global_positions(0)[0]
    for side in ('Left', 'Right'):
        arm = pose[point_index(bvh, f'{side}ForeArm')] - pose[point_index(bvh, f'{side}Arm')]
        if abs(arm[1]) > TPOSE_ARM_SLOPE * np.linalg.norm(arm):
            return False
    return True


def reference_pose(bvh):
    """(J, 3) positions [BVH units, BVH axes] of the skeleton standing upright, which sizes it: frame 1
    when that is a T-pose (has_tpose); otherwise the rest pose that the OFFSETs define (every channel
    zero), with each leg turned about its hip to hang straight down, for a CMU skeleton's rest pose
    spreads the legs by 20° (a T-pose's legs are straight)."""
    if has_tpose(bvh):
        return bvh.global_positions(0)[0]
    pose = dataclasses.replace(bvh, motion=np.zeros((1, bvh.motion.shape[1]))).global_positions(0)[0]
    for side in ('Left', 'Right'):
        hip, knee = point_index(bvh, f'{side}UpLeg'), point_index(bvh, f'{side}Leg')
        leg = np.zeros(len(bvh.names), dtype=bool)
        leg[hip] = True
        for point in range(hip + 1, len(bvh.names)):  # a parent comes before its children
            leg[point] = leg[bvh.parents[point]]
        turn = matrix_from_quaternion(rotation_between(pose[knee] - pose[hip], [0.0, -1.0, 0.0]))
        pose[leg] = pose[hip] + (pose[leg] - pose[hip]) @ turn.T
    return pose


def world_scale(bvh, height):
    """Metres per BVH unit such that the standing reference pose (reference_pose: the T-pose, row 0, or
    the OFFSETs' rest pose) stands `height` [m] tall: Head End Site above the lower toe End Site."""
    tpose = reference_pose(bvh)
    standing = tpose[point_index(bvh, 'Head_end'), 1] - min(tpose[point_index(bvh, name), 1] for name in TOE_TIPS)
    if standing <= 0:
        raise MotionFileError(f'{bvh.path}: its standing pose (the T-pose of frame 1, or the rest pose of the '
                              f'OFFSETs) does not stand (head not above the toes)')
    return height / standing


def resample(samples, source_period, target_rate):
    """Linear interpolation of samples (N, ...) taken every source_period [s] (times 0, source_period, …)
    at times m / target_rate [s], m = 0 … M − 1, M = floor(duration · target_rate) + 1 with
    duration = (N − 1) · source_period: the last output lies within the source span."""
    duration = (len(samples) - 1) * source_period
    count = int(np.floor(duration * target_rate + 1e-9)) + 1  # + 1e-9: an exact multiple is not lost to rounding
    source_index = np.minimum(np.arange(count) / target_rate / source_period, len(samples) - 1)
    lower = np.minimum(source_index.astype(int), len(samples) - 2)
    weight = (source_index - lower).reshape((-1,) + (1,) * (samples.ndim - 1))
    return (1.0 - weight) * samples[lower] + weight * samples[lower + 1]


def floor_levelling(ankles):
    """3×3 rotation that makes the capture's floor level. A clip's floor is not always level in its BVH
    (in CMU 07_01 the feet rise about 7 cm over 3 m of walking); the plane z = a·x + b·y + c is fitted by
    least squares to the lower ankle of every frame (the stance foot), ankles (F, 2, 3) [m], and its
    normal turned to +z by the smallest rotation (paper 004's, geometry.rotation_between)."""
    lower = ankles[np.arange(len(ankles)), np.argmin(ankles[:, :, 2], axis=1)]
    design = np.column_stack([lower[:, 0], lower[:, 1], np.ones(len(lower))])
    (a, b, _), *_ = np.linalg.lstsq(design, lower[:, 2], rcond=None)
    return matrix_from_quaternion(rotation_between([-a, -b, 1.0], [0.0, 0.0, 1.0]))


def retarget(bvh, height=1.75, frame_rate=FRAME_RATE, first_frame=0):
    """The motion of a CMU BVH as a BodyMotion: frames 2..end of a MotionBuilder-friendly file (after its
    T-pose), every frame of a 3dsMax-friendly one (has_tpose).

    Axes BVH (x, y, z) → project (x, −z, y), scaled so that the standing reference pose (the T-pose, or
    the OFFSETs' rest pose with straight legs) is `height` [m] tall (see world_scale). Joints, in
    MotionBuilder's names (3dsMax's in THREE_DS_MAX_NAMES): hips = Left/RightUpLeg, pelvis = their
    midpoint, knees = Left/RightLeg, ankles = Left/RightFoot, shoulders = Left/RightArm, elbows =
    Left/RightForeArm, wrists = Left/RightHand, head = Head's End Site (vertex); neck = Neck + 0.6 ·
    (Neck1 − Neck), a retargeting choice: CMU's Neck sits at the thorax below the shoulder line, and 0.6
    of the way up to Neck1 is the base of the neck (3dsMax-friendly skeletons: the shoulders' level,
    neck_fraction). head_forward: BVH +Z (the T-pose's facing) through the Head's global rotation, in
    project axes.
    Every point trajectory is resampled from the BVH rate to frame_rate [Hz] by linear interpolation
    (see resample; head_forward renormalised after). The floor: levelled (floor_levelling), then z shifted
    so that the lowest ankle over the clip is at 0.075 · height / 1.75 m, the ankle joint centre's height
    above the sole.
    """
    first = 1 if bvh.frame_count and has_tpose(bvh) else 0
    if bvh.frame_count - first < 2:
        raise MotionFileError(f'{bvh.path}: {bvh.frame_count} frames: need at least two of motion'
                              + (' after the T-pose' if first else ''))
    scale = world_scale(bvh, height)
    rotations, positions = bvh.global_transforms(np.arange(first, bvh.frame_count))
    joints, toes, hand_tips = (scale * points @ BVH_TO_WORLD.T for points in body_points(bvh, positions))
    head_forward = rotations[:, point_index(bvh, 'Head'), :, 2] @ BVH_TO_WORLD.T  # column 2 = image of BVH +Z
    tracks = np.concatenate([joints, toes, hand_tips, head_forward[:, None]], axis=1)
    tracks = resample(tracks, bvh.frame_time, frame_rate)
    ankles = [JOINT_NAMES.index('left_ankle'), JOINT_NAMES.index('right_ankle')]
    tracks = tracks @ floor_levelling(tracks[:, ankles]).T
    floor_shift = ANKLE_HEIGHT_PER_HEIGHT * height - tracks[:, ankles, 2].min()
    points = tracks[:, :-1] + [0.0, 0.0, floor_shift]
    head_forward = tracks[:, -1] / np.linalg.norm(tracks[:, -1], axis=-1, keepdims=True)
    count = len(JOINT_NAMES)
    return BodyMotion(frame_rate=float(frame_rate), first_frame=first_frame, joints=points[:, :count],
                      toes=points[:, count:count + 2], hand_tips=points[:, count + 2:], head_forward=head_forward)


def standing_motion(bvh, frames, height=1.75, frame_rate=FRAME_RATE, first_frame=0, seed=0):
    """A person standing still for `frames` frames, for initialisation tests, built from the subject's own
    bone lengths (T-pose or reference_pose, scaled as in retarget; left and right averaged): upright at the origin facing
    +x (left at +y), feet under the hips, legs straight, arms hanging with 10° of abduction, head upright,
    ankles 0.075 · height / 1.75 m above the floor. A seeded smooth sway leans the body about the ankles:
    up to SWAY_AMPLITUDE at the head, so that frames are not identical."""
    tpose = world_scale(bvh, height) * reference_pose(bvh) @ BVH_TO_WORLD.T
    joints, (toes,), (hand_tips,) = body_points(bvh, tpose[None])
    joints = joints[0]
    at = {name: joints[JOINT_NAMES.index(name)] for name in JOINT_NAMES}
    sides = ('left', 'right')

    def length(start, end):  # bone length, mean of the left and right side [m]
        return np.mean([np.linalg.norm(at[f'{side}_{end}'] - at[f'{side}_{start}']) for side in sides])

    down = np.array([0.0, 0.0, -1.0])
    hip_half_width = np.linalg.norm(at['left_hip'] - at['right_hip']) / 2
    shoulder_half_width = np.linalg.norm(at['left_shoulder'] - at['right_shoulder']) / 2
    toe_reach = np.mean([np.linalg.norm((tip - at[f'{side}_ankle'])[:2]) for side, tip in zip(sides, toes)])
    hand_length = np.mean([np.linalg.norm(tip - at[f'{side}_wrist']) for side, tip in zip(sides, hand_tips)])
    shoulder_drop = np.mean([at['neck'][2] - at[f'{side}_shoulder'][2] for side in sides])
    ankle_height = ANKLE_HEIGHT_PER_HEIGHT * height
    pelvis = np.array([0.0, 0.0, ankle_height + length('knee', 'ankle') + length('hip', 'knee')])
    neck = pelvis + [0.0, 0.0, at['neck'][2] - at['pelvis'][2]]
    place = {'pelvis': pelvis, 'neck': neck, 'head': neck + [0.0, 0.0, at['head'][2] - at['neck'][2]]}
    abduction = np.radians(10.0)
    toe_tips, finger_tips = [], []
    for side, outward in zip(sides, (1.0, -1.0)):
        place[f'{side}_hip'] = place['pelvis'] + [0.0, outward * hip_half_width, 0.0]
        place[f'{side}_knee'] = place[f'{side}_hip'] + length('hip', 'knee') * down
        place[f'{side}_ankle'] = place[f'{side}_knee'] + length('knee', 'ankle') * down
        toe_tips.append(place[f'{side}_ankle'] + [toe_reach, 0.0, -ankle_height])
        arm = np.array([0.0, outward * np.sin(abduction), -np.cos(abduction)])
        place[f'{side}_shoulder'] = neck + [0.0, outward * shoulder_half_width, -shoulder_drop]
        place[f'{side}_elbow'] = place[f'{side}_shoulder'] + length('shoulder', 'elbow') * arm
        place[f'{side}_wrist'] = place[f'{side}_elbow'] + length('elbow', 'wrist') * arm
        finger_tips.append(place[f'{side}_wrist'] + hand_length * arm)
    pose = np.array([place[name] for name in JOINT_NAMES] + toe_tips + finger_tips)
    # Sway: each horizontal axis a sine of random frequency (0.1–0.4 Hz) and phase, scaled by the height
    # above the ankles so the feet stay planted.
    rng = np.random.default_rng(seed)
    times = np.arange(frames)[:, None] / frame_rate
    sway = SWAY_AMPLITUDE * np.sin(2 * np.pi * rng.uniform(0.1, 0.4, 2) * times + rng.uniform(0, 2 * np.pi, 2))
    lean = np.clip((pose[:, 2] - ankle_height) / (place['head'][2] - ankle_height), 0.0, 1.0)
    points = pose + lean[None, :, None] * np.concatenate([sway, np.zeros((frames, 1))], axis=1)[:, None, :]
    count = len(JOINT_NAMES)
    return BodyMotion(frame_rate=float(frame_rate), first_frame=first_frame, joints=points[:, :count],
                      toes=points[:, count:count + 2], hand_tips=points[:, count + 2:],
                      head_forward=np.tile([1.0, 0.0, 0.0], (frames, 1)))
