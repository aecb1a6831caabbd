"""The fitted motion out of the project as CSV, JSON or BVH, and a written BVH read back.

Input is a Motion: per frame the stamp, the fit status, the 15 joints P1..P15 of paper 000 (Fig. 6;
model.JOINT_NAMES) [m] in the world (z up, floor at z = 0) and the 29 parameters of its Table 1
(model.PARAMETER_NAMES: torso_x/y/z [m], the rest Euler angles [rad], kinematics.py's
convention), NaN where a message carried none (ground truth has no parameters).

CSV: one header row, then one row per frame: `stamp_s` (exact decimal seconds since the Unix epoch),
`status` (Skeleton.STATUS_*), each joint's `<joint>_x_m`, `<joint>_y_m`, `<joint>_z_m`, then each
parameter as `<name>_m` or `<name>_rad`; an empty cell is a value the frame did not record. The units
are in the names so that every CSV reader (spreadsheet, pandas, numpy, csv) gets them without
a comment-line convention.

JSON: one object: `units`, `world` (axes), `joint_names`, `bones` ({parent, child} joint pairs,
model.BONES), `parameter_names`, `parameter_units`, `status_names`, and `frames`, a list of
{stamp [s], stamp_ns, status, status_message, joints (15 × [x, y, z] [m]), parameters (29 or null)}.

BVH (Biovision Hierarchy, as Blender's File > Import > Motion Capture (.bvh) reads it):
- Hierarchy: one BVH joint per bone of kinematics.BONES, named after it and placed at the bone's
  start: ROOT `torso` at the pelvis; a bone that starts where another ends hangs from it (head and
  clavicles from the torso's end, the neck; thighs from the hip bones; upper arms from the clavicles);
  the hip bones start at the pelvis itself and so sit on the root with a zero OFFSET. The leaf bones
  (shins, head, forearms) end in an End Site: the ankles, the head top, the wrists.
- OFFSETs: each bone's length is the median over the frames of its recorded length, along its rest
  direction (kinematics.BONES: upright, facing world +y, arms hanging).
- Units: metres, angles in degrees. Blender's importer (default Scale 1.0) then gives metres.
- Axes: Y up, as BVH files are and as Blender's importer expects by default (Forward −Z, Up Y):
  BVH (x, y, z) = world (x, z, −y), the inverse of mocap.BVH_TO_WORLD with which the project reads
  BVH files. Imported with Blender's defaults the motion lands where it was in the world (Blender is
  z up as the world is). The rest pose faces BVH −Z (world +y).
- Channels: ROOT `Xposition Yposition Zposition Yrotation Zrotation Xrotation`, every other joint
  `Yrotation Zrotation Xrotation` (three rotations everywhere, so that every joint is keyed alike).
  Rotations apply in channel order, local = R_Y·R_Z·R_X in BVH axes, which is the model's
  Rz(rz)·Ry(ry)·Rx(rx) (paper 004 Eq. 2) seen in BVH axes (BVH Y = world z, BVH Z = −world y): a
  joint's channels are (rz, −ry, rx) in degrees of its rotation relative to its BVH parent. Where the
  BVH parent is the model's parent bone (all but the upper arms) and the joints are the model's, they
  are the recorded parameters themselves, 0 where the model has no DOF; an upper arm turns relative to
  its clavicle here (it hangs from the clavicle's end), relative to the torso in the model.
- Per-frame rotations come from the joints: a bone's world rotation is its kinematic-model frame (the
  frame's parameters, or kinematics.inverse_kinematics of its joints when it has none) turned by the
  smallest rotation (paper 004's, geometry.rotation_between) that takes the bone's modelled direction
  onto its recorded one. So the BVH reproduces every recorded bone direction exactly, with the roll
  about the bone from the model; the joints come back exactly where every bone keeps its length over
  the take (as a fitted skeleton's do), and otherwise each bone is off by its length's deviation from
  the median. read_bvh is the check.
- Frame Time: the median spacing of the stamps (BVH has a single rate).

NumPy only (no rclpy), so tests and tools use it without a ROS graph.
"""
import csv
import dataclasses
import json
from pathlib import Path

import numpy as np

from mvpose_nodes.body import model

from mvpose_nodes.body import kinematics
from mvpose_nodes.body.model import JOINT_INDEX, JOINT_NAMES, PARAMETER_NAMES
from mvpose_nodes.body.geometry import matrix_from_quaternion, quaternion_from_matrix, rotation_between
from mvpose_nodes.studio.i3dpost import FRAME_RATE
from mvpose_nodes.studio.mocap import BVH_TO_WORLD, load_bvh


class ExportError(ValueError):
    """An export that cannot be written, or a file that is not an mvpose export; the message names the file."""


FORMATS = ('csv', 'json', 'bvh')
# mvpose_msgs/Skeleton's STATUS_* constants (a test keeps them equal): names for readers of the JSON.
STATUS_NAMES = {0: 'OK', 1: 'INITIALISING', 2: 'DEGRADED', 3: 'LOST'}
PARAMETER_UNITS = tuple('m' if name in ('torso_x', 'torso_y', 'torso_z') else 'rad' for name in PARAMETER_NAMES)
DEFAULT_FRAME_TIME = 1 / FRAME_RATE  # [s] i3DPost's rate, for a take with a single stamp
DECIMALS = 9                 # written decimals of metres, radians and degrees: nm and nrad, far below any error here

WORLD_TO_BVH = BVH_TO_WORLD.T  # world (x, y, z) → BVH (x, z, −y): Y up
ROOT = kinematics.BONES[0]     # the torso: its start is the pelvis, the root of the body
BONE = {bone.name: bone for bone in kinematics.BONES}


def _bvh_parent(bone):
    """The bone that `bone` hangs from in the BVH: the one that ends where it starts, else (a bone
    starting at the pelvis) the root, which starts there too; None for the root."""
    if bone is ROOT:
        return None
    ending = [other.name for other in kinematics.BONES if other.joint == bone.parent_joint]
    return ending[0] if ending else ROOT.name


BVH_PARENT = {bone.name: _bvh_parent(bone) for bone in kinematics.BONES}
BVH_CHILDREN = {name: [b.name for b in kinematics.BONES if BVH_PARENT[b.name] == name] for name in BONE}
# Where each of the 15 joints is in the BVH: the joint of the (first) bone starting there, else the
# End Site of the bone ending there (named '<bone>_end', as mocap.load_bvh names End Sites).
JOINT_POINTS = {joint: next((b.name for b in kinematics.BONES if b.parent_joint == joint), None)
                or next(f'{b.name}_end' for b in kinematics.BONES if b.joint == joint) for joint in JOINT_NAMES}


@dataclasses.dataclass(frozen=True)
class Motion:
    """A recorded skeleton motion, frames in stamp order.

    stamps_ns: (F,) int64 [ns since the Unix epoch]; status: (F,) int64 Skeleton.STATUS_*;
    joints: (F, 15, 3) float64 [m] in the world, JOINT_NAMES order; parameters: (F, 29) float64
    [m, rad] in PARAMETER_NAMES order, NaN where not recorded; status_messages: (F,) str.
    """
    stamps_ns: np.ndarray
    status: np.ndarray
    joints: np.ndarray
    parameters: np.ndarray
    status_messages: tuple = None

    def __post_init__(self):
        count = len(self.stamps_ns)
        if count == 0:
            raise ValueError('a motion needs at least one frame')
        if (self.joints.shape != (count, len(JOINT_NAMES), 3) or len(self.status) != count
                or self.parameters.shape != (count, len(PARAMETER_NAMES))):
            raise ValueError(f'inconsistent motion shapes: {count} stamps, joints {self.joints.shape}, '
                             f'parameters {self.parameters.shape}, {len(self.status)} status values')
        if self.status_messages is None:  # frozen: the one way to fill in a default per frame
            object.__setattr__(self, 'status_messages', ('',) * count)
        elif len(self.status_messages) != count:
            raise ValueError(f'{len(self.status_messages)} status messages for {count} frames')

    @property
    def frame_count(self):
        return len(self.stamps_ns)


def stamp_text(nanoseconds):
    """Exact decimal seconds of an integer stamp [ns] (a float64 cannot hold ns at 1e9 s)."""
    seconds, rest = divmod(int(nanoseconds), 10**9)
    return f'{seconds}.{rest:09d}'


def number_text(value):
    """A value with DECIMALS decimals ('' for NaN: not recorded); no '-0'."""
    return '' if not np.isfinite(value) else f'{round(float(value), DECIMALS) + 0.0:.{DECIMALS}f}'


def csv_header():
    """The CSV column names: stamp_s, status, <joint>_<axis>_m (45), <parameter>_<unit> (29)."""
    return (['stamp_s', 'status'] + [f'{joint}_{axis}_m' for joint in JOINT_NAMES for axis in 'xyz']
            + [f'{name}_{unit}' for name, unit in zip(PARAMETER_NAMES, PARAMETER_UNITS)])


def write_csv(motion, stream):
    """The motion as CSV (module docstring) to a text stream."""
    writer = csv.writer(stream, lineterminator='\n')
    writer.writerow(csv_header())
    for stamp, status, joints, parameters in zip(motion.stamps_ns, motion.status, motion.joints, motion.parameters):
        writer.writerow([stamp_text(stamp), int(status)] + [number_text(v) for v in joints.ravel()]
                        + [number_text(v) for v in parameters])


def motion_json(motion, source=None):
    """The motion as a JSON-ready dict (module docstring); `source`: optional dict, e.g. bag and topic."""
    def finite_or_none(values):
        return [float(v) for v in values] if np.all(np.isfinite(values)) else None

    document = {'format': 'mvpose motion', 'version': 1}
    if source:
        document['source'] = source
    document.update({
        'units': {'stamp': 's since the Unix epoch (stamp_ns: the same in integer ns)', 'joints': 'm',
                  'parameters': 'torso_x, torso_y, torso_z in m, the Euler angles in rad'},
        'world': 'x, y horizontal, z up, floor at z = 0; joints P1..P15 of paper 000',
        'joint_names': list(JOINT_NAMES),
        'bones': [{'parent': parent, 'child': child} for parent, child in model.BONES],
        'parameter_names': list(PARAMETER_NAMES),
        'parameter_units': list(PARAMETER_UNITS),
        'parameter_convention': 'paper 000 Table 1; each bone R = Rz(rz)·Ry(ry)·Rx(rx) relative to its parent bone',
        'status_names': {str(value): name for value, name in STATUS_NAMES.items()},
        'frames': [{'stamp': float(stamp_text(stamp)), 'stamp_ns': int(stamp), 'status': int(status),
                    'status_message': message, 'joints': joints.tolist(), 'parameters': finite_or_none(parameters)}
                   for stamp, status, message, joints, parameters in zip(
                       motion.stamps_ns, motion.status, motion.status_messages, motion.joints, motion.parameters)],
    })
    return document


def write_json(motion, stream, source=None):
    """The motion as JSON (module docstring) to a text stream: indented, but one line per frame (a
    frame's 15 joints and 29 parameters one number per line would bury the file)."""
    document = motion_json(motion, source)
    frames = document.pop('frames')
    head = json.dumps(document, indent=1)
    stream.write(head[:-len('\n}')] + ',\n "frames": [\n')
    stream.write(',\n'.join('  ' + json.dumps(frame) for frame in frames) + '\n ]\n}\n')


def frame_time(stamps_ns):
    """[s] The median spacing of the stamps (F,) [ns]; DEFAULT_FRAME_TIME without two distinct stamps."""
    steps = np.diff(np.sort(np.asarray(stamps_ns, dtype=np.int64)))
    steps = steps[steps > 0]
    return float(np.median(steps)) / 1e9 if len(steps) else DEFAULT_FRAME_TIME


def bone_rotations(joints, parameters=None):
    """{bone name: 3×3 world rotation} of every bone of kinematics.BONES in one frame (module docstring):
    the model's frame of the bone from `parameters` (29,) [m, rad] (inverse_kinematics of the joints when
    None or not all finite), turned by the smallest rotation taking its modelled direction onto the
    recorded one, joints (15, 3) [m]. A zero-length recorded bone keeps the model's frame."""
    if parameters is None or not np.all(np.isfinite(parameters)):
        parameters = kinematics.inverse_kinematics(joints)
    # The frames do not depend on the lengths: any will do.
    _, frames = kinematics.forward_kinematics(parameters, kinematics.bone_lengths(1.0))
    rotations = {}
    for bone in kinematics.BONES:
        modelled = frames[bone.name] @ np.array(bone.rest, dtype=float)
        recorded = joints[JOINT_INDEX[bone.joint]] - joints[JOINT_INDEX[bone.parent_joint]]
        rotations[bone.name] = matrix_from_quaternion(rotation_between(modelled, recorded)) @ frames[bone.name]
    return rotations


def bvh_channels(rotation):
    """BVH channel values (Yrotation, Zrotation, Xrotation) [deg] of a rotation matrix given in model
    axes: its Rz(rz)·Ry(ry)·Rx(rx) angles (kinematics.euler_from_quaternion) as (rz, −ry, rx)."""
    rx, ry, rz = kinematics.euler_from_quaternion(quaternion_from_matrix(rotation))
    return np.degrees([rz, -ry, rx])


def bvh_motion(motion, lengths):
    """(F, 3 + 3·14) BVH motion rows: the root's position [m, BVH axes], then per bone in file order
    (bvh_order) its rotation channels [deg] relative to its BVH parent, each channel unwrapped over the
    frames (±360° leaves a rotation unchanged, and keeps Blender's interpolation from spinning)."""
    order = bvh_order()
    rows = np.empty((motion.frame_count, 3 + 3 * len(order)))
    for frame, (joints, parameters) in enumerate(zip(motion.joints, motion.parameters)):
        world = bone_rotations(joints, parameters)
        rows[frame, :3] = WORLD_TO_BVH @ joints[JOINT_INDEX[ROOT.parent_joint]]
        for k, name in enumerate(order):
            parent = BVH_PARENT[name]
            local = world[name] if parent is None else world[parent].T @ world[name]
            rows[frame, 3 + 3 * k:6 + 3 * k] = bvh_channels(local)
    rows[:, 3:] = np.unwrap(rows[:, 3:], period=360.0, axis=0)
    return rows


def bvh_order():
    """The bone names in BVH file order (depth first from the root, children in kinematics.BONES order)."""
    order = []

    def visit(name):
        order.append(name)
        for child in BVH_CHILDREN[name]:
            visit(child)
    visit(ROOT.name)
    return order


def bvh_offset(name, lengths):
    """OFFSET of bone `name`'s BVH joint [m, BVH axes]: its parent bone's full length along that bone's
    rest direction if it starts at the parent's end, else (a hip bone on the root) zero."""
    parent = BVH_PARENT[name]
    if parent is None or BONE[parent].joint != BONE[name].parent_joint:
        return np.zeros(3)
    return WORLD_TO_BVH @ (lengths[parent] * np.array(BONE[parent].rest, dtype=float))


def bvh_hierarchy(lengths):
    """The HIERARCHY section's lines for bone lengths {bone name: [m]}."""
    def vector(values):
        return ' '.join(number_text(v) for v in values)

    lines = []

    def write(name, depth):
        pad = '  ' * depth
        bone = BONE[name]
        lines.append(f'{pad}{"ROOT" if depth == 0 else "JOINT"} {name}')
        lines.append(f'{pad}{{')
        lines.append(f'{pad}  OFFSET {vector(bvh_offset(name, lengths))}')
        channels = 'Yrotation Zrotation Xrotation'
        lines.append(f'{pad}  CHANNELS 6 Xposition Yposition Zposition {channels}' if depth == 0
                     else f'{pad}  CHANNELS 3 {channels}')
        for child in BVH_CHILDREN[name]:
            write(child, depth + 1)
        if not BVH_CHILDREN[name]:
            tip = WORLD_TO_BVH @ (lengths[name] * np.array(bone.rest, dtype=float))
            lines.extend([f'{pad}  End Site', f'{pad}  {{', f'{pad}    OFFSET {vector(tip)}', f'{pad}  }}'])
        lines.append(f'{pad}}}')
    lines.append('HIERARCHY')
    write(ROOT.name, 0)
    return lines


def write_bvh(motion, stream):
    """The motion as BVH (module docstring) to a text stream."""
    lengths = kinematics.bone_lengths_of(motion.joints)
    rows = bvh_motion(motion, lengths)
    lines = bvh_hierarchy(lengths)
    lines += ['MOTION', f'Frames: {motion.frame_count}', f'Frame Time: {frame_time(motion.stamps_ns):.9f}']
    lines += [' '.join(number_text(v) for v in row) for row in rows]
    stream.write('\n'.join(lines) + '\n')


def read_bvh(path):
    """(joints, frame_time) of a BVH written by write_bvh: joints (F, 15, 3) [m] in the world by the
    file's own forward kinematics (mocap.load_bvh, Bvh.global_positions), frame_time [s]. ExportError
    naming the file when it is malformed or not such a BVH."""
    bvh = load_bvh(path)
    missing = [point for point in JOINT_POINTS.values() if point not in bvh.names]
    if missing:
        raise ExportError(f'{path}: not an mvpose BVH export (no joint {missing[0]})')
    positions = bvh.global_positions() @ BVH_TO_WORLD.T
    return positions[:, [bvh.names.index(JOINT_POINTS[name]) for name in JOINT_NAMES]], bvh.frame_time


def write_motion(motion, path, file_format, source=None):
    """Write the motion to a new file `path` in `file_format` (one of FORMATS; `source` goes into the
    JSON); ExportError when the file exists
    (the project's commands never overwrite) or cannot be written."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, 'x', encoding='utf-8', newline='') as stream:
            if file_format == 'json':
                write_json(motion, stream, source)
            elif file_format == 'csv':
                write_csv(motion, stream)
            else:
                write_bvh(motion, stream)
    except FileExistsError:
        raise ExportError(f"output '{path}' already exists; choose another -o or remove it") from None
    except OSError as error:
        raise ExportError(f"cannot write '{path}': {error.strerror or error}") from None
