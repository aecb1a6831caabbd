"""`export BAG --format csv|json|bvh [-o OUT] [--topic T]`: the motion recorded in a bag as CSV, JSON or BVH.

Reads every mvpose_msgs/Skeleton of the topic (default /mvpose/skeleton, the fitted skeleton; the
ground truth of a synthetic bag is /mvpose/ground_truth), in stamp order, and writes one file; the
formats are described in mvpose_nodes/motion_export.py. A BVH is read back after writing and its
largest joint deviation from the recorded joints is printed (exactly zero up to rounding when the
bone lengths are constant over the take, as the fitter's are).
"""
import argparse
import sys
from pathlib import Path

import numpy as np

from mvpose_nodes.tools.cli import ArgumentParser, UserError, exit_on_user_error
from mvpose_nodes.io.motion_export import FORMATS, Motion, frame_time, read_bvh, write_motion

FORMAT_HELP = """formats:
  csv   one row per frame: stamp_s, status, <joint>_x_m/_y_m/_z_m for the 15 joints (world: metres,
        z up), then the 29 parameters as <name>_m or <name>_rad; empty cells: not recorded
  json  {units, world, joint_names, bones, parameter_names, parameter_units, status_names,
        frames: [{stamp, stamp_ns, status, status_message, joints, parameters}]}
  bvh   for Blender (File > Import > Motion Capture, default settings): one BVH joint per bone of the
        body model, named after it (ROOT torso at the pelvis; left_hip, left_thigh, left_shin, head,
        left_clavicle, left_upper_arm, left_forearm, ...), OFFSETs = median recorded bone lengths; units
        METRES (Blender scale 1.0), angles degrees; Y up as Blender's importer expects by default
        (BVH x, y, z = world x, z, -y, so the default import puts the motion where it was);
        channels Xposition Yposition Zposition (root) and Yrotation Zrotation Xrotation (every joint):
        the model's Rz*Ry*Rx in BVH axes, values (rz, -ry, rx) in degrees relative to the parent
        joint; Frame Time = median stamp spacing"""


def build_parser(prog):
    parser = ArgumentParser(prog=prog, description='The motion recorded in a bag (mvpose_msgs/Skeleton messages) '
                                                   'as CSV, JSON or BVH.',
                            epilog=FORMAT_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('bag', type=Path, help='recorded bag (rosbag2 directory or .mcap)')
    parser.add_argument('--format', choices=FORMATS,
                        help='output format (default: from the suffix of -o)')
    parser.add_argument('-o', '--output', type=Path,
                        help='file to write, must not exist (default: <bag name>.<format> in the current folder)')
    parser.add_argument('--topic', default='/mvpose/skeleton',
                        help='mvpose_msgs/Skeleton topic to export (default /mvpose/skeleton)')
    return parser


def export_main(argv=None, prog='export'):
    parser = build_parser(prog)
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    file_format = args.format
    if file_format is None:
        suffix = args.output.suffix.lower().lstrip('.') if args.output else ''
        if suffix not in FORMATS:
            parser.error('give --format csv, json or bvh (or an -o file ending in .csv, .json or .bvh)')
        file_format = suffix
    output = args.output or Path(f'{args.bag.stem if args.bag.suffix == ".mcap" else args.bag.name}.{file_format}')
    with exit_on_user_error(prog):
        if output.exists():  # before reading the bag: fail fast
            raise UserError(f"output '{output}' already exists; choose another -o or remove it")
        export(args.bag, args.topic, file_format, output)
    return 0


def export(bag_path, topic, file_format, output):
    """Read the topic's skeletons from the bag, write them to `output`, print a summary to stderr."""
    motion = read_motion(bag_path, topic)
    write_motion(motion, output, file_format, source={'bag': str(bag_path), 'topic': topic})
    summary = f'[export] {motion.frame_count} frames of {topic} -> {output}'
    if file_format == 'bvh':
        seconds = frame_time(motion.stamps_ns)
        joints, _ = read_bvh(output)
        deviation = np.linalg.norm(joints - motion.joints, axis=-1).max()
        summary += (f' (frame time {seconds * 1e3:.1f} ms; read back, the BVH joints are within '
                    f'{deviation * 1e3:.3f} mm of the recorded ones)')
        steps = np.diff(np.sort(motion.stamps_ns)) / 1e9
        irregular = int(np.sum(np.abs(steps - seconds) > seconds / 2))
        if irregular:
            summary += f'; note: {irregular} gaps between stamps are not one frame time: BVH has one rate'
    print(summary, file=sys.stderr)


def read_motion(bag_path, topic):
    """The Motion of one mvpose_msgs/Skeleton topic of a bag, frames sorted by stamp. UserError naming
    the bag and topic when the bag has no such topic, it has another type, no messages, or a message
    lacks joints or has parameters that are not the 29 of paper 000 Table 1."""
    from rclpy.serialization import deserialize_message
    from mvpose_msgs.msg import Skeleton
    from mvpose_nodes.io.bagfile import BagReader
    from mvpose_nodes.ros.conversions import joints_from_skeleton, stamp_ns
    bag = BagReader(bag_path)
    if topic not in bag.topics:
        raise UserError(f"bag '{bag_path}' has no {topic} (its topics: {', '.join(sorted(bag.topics)) or 'none'})")
    if bag.topics[topic].type != 'mvpose_msgs/msg/Skeleton':
        raise UserError(f"bag '{bag_path}': {topic} is {bag.topics[topic].type}, not mvpose_msgs/msg/Skeleton")
    frames = []
    for _, _, data in bag.messages(topics=[topic]):
        message = deserialize_message(data, Skeleton)
        stamp = stamp_ns(message.header)
        try:
            joints = joints_from_skeleton(message)
            if not np.all(np.isfinite(joints)):
                raise ValueError('joints are not finite')
            parameters = parameters_of(message)
        except ValueError as error:
            raise UserError(f"bag '{bag_path}': {topic} at stamp {stamp} ns: {error}") from None
        frames.append((stamp, message.status, joints, parameters, message.status_message))
    if not frames:
        raise UserError(f"bag '{bag_path}': {topic} has no messages")
    frames.sort(key=lambda frame: frame[0])  # stable: equal stamps keep their recorded order
    stamps, status, joints, parameters, messages = zip(*frames)
    return Motion(stamps_ns=np.array(stamps, dtype=np.int64), status=np.array(status, dtype=np.int64),
                  joints=np.array(joints), parameters=np.array(parameters), status_messages=messages)


def parameters_of(message):
    """The 29 parameters (29,) [m, rad] of a Skeleton in PARAMETER_NAMES order, matched by name (in
    Table 1 order when it names none); all NaN when it has none (ground truth). ValueError when they
    are not the model's."""
    from mvpose_nodes.body.model import PARAMETER_NAMES
    names, values = list(message.parameter_names), np.array(message.parameters, dtype=float)
    if not len(values):
        return np.full(len(PARAMETER_NAMES), np.nan)
    if not names and len(values) == len(PARAMETER_NAMES):
        return values
    index = {name: i for i, name in enumerate(names)}
    missing = [name for name in PARAMETER_NAMES if name not in index]
    if missing or len(names) != len(values):
        raise ValueError(f'parameters lack {", ".join(missing)}' if missing
                         else f'{len(names)} parameter names but {len(values)} values')
    return values[[index[name] for name in PARAMETER_NAMES]]
