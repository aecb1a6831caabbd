"""`import-i3dpost`: frames and calibration in the i3DPost dataset layout -> a bag of the mvpose contract.

The layout and calibration format are those of `i3dpost` (partly assumptions: see that module).
Each PNG frame becomes a CompressedImage on /cam<K>/image_raw/compressed with the stamp of its frame
number (camera_bag), encoded exactly as `synth` encodes its images; each camera's calibration
becomes its latched camera_info and camera_pose.
"""
import sys
from pathlib import Path

from mvpose_nodes.tools.cli import ArgumentParser, UserError, exit_on_user_error


def build_parser(prog):
    parser = ArgumentParser(prog=prog, description=__doc__.split('\n\n')[0])
    parser.add_argument('dataset', type=Path, help='dataset folder: <actor>/…/<sequence>/<000..007>/NNNNN.png below it')
    parser.add_argument('-o', '--output', type=Path, required=True, help='bag directory to create')
    parser.add_argument('--calibration', type=Path, help='calibration text file (default DATASET/calibration.txt)')
    parser.add_argument('--units', choices=['m', 'mm'], default='m', help='unit of t in the calibration (default m)')
    parser.add_argument('--cameras', type=int, nargs='+', default=[3, 5, 7], metavar='K',
                        help='i3DPost camera numbers 1..8 (default 3 5 7, the paper\'s)')
    parser.add_argument('--frames', default='52-101', help='frame range (default 52-101, the paper\'s)')
    parser.add_argument('--image-format', choices=['jpeg', 'png'], default='jpeg', help='compression (default jpeg)')
    parser.add_argument('--jpeg-quality', type=int, default=90, help='JPEG quality (default 90)')
    return parser


def main(argv=None, prog='import-i3dpost'):
    args = build_parser(prog).parse_args(sys.argv[1:] if argv is None else argv)
    with exit_on_user_error(prog):
        import_dataset(args)
    return 0


def import_dataset(args):
    from rclpy.serialization import serialize_message
    from mvpose_nodes.studio import i3dpost
    from mvpose_nodes.ros.camera_bag import CameraBagWriter, frame_stamp_ns
    from mvpose_nodes.app.progress import Progress
    from mvpose_nodes.ros.conversions import compressed_image

    sequence = i3dpost.find_sequence(args.dataset)
    first, last = i3dpost.parse_frame_range(args.frames)
    found = i3dpost.available(sequence)
    for camera in args.cameras:
        missing = sorted(set(range(first, last + 1)) - set(found.get(camera, [])))
        if missing:
            raise UserError(f"{sequence}: camera {camera} lacks frame(s) {missing[0]}…{missing[-1]} "
                            f"({len(missing)} missing; cameras found: {sorted(found)})")
    calibration_path = args.calibration or args.dataset / 'calibration.txt'
    height, width = i3dpost.read_frame(i3dpost.frame_path(sequence, args.cameras[0], first)).shape[:2]
    calibration = {c.number: c for c in i3dpost.read_calibration(calibration_path, args.units, image_size=(width, height))}
    unknown = [k for k in args.cameras if k not in calibration]
    if unknown:
        raise UserError(f'{calibration_path}: no calibration for camera(s) {unknown} (it has {sorted(calibration)})')
    progress = Progress(last - first + 1, 'import')
    with CameraBagWriter(args.output, [calibration[k] for k in args.cameras], first) as bag:
        for frame in range(first, last + 1):
            for camera in args.cameras:
                rgb = i3dpost.read_frame(i3dpost.frame_path(sequence, camera, frame))
                image = compressed_image(rgb, camera, frame_stamp_ns(frame), args.image_format, args.jpeg_quality)
                bag.write_image(camera, frame, serialize_message(image))
            progress.update()
    progress.close()
    print(f'[import] wrote {args.output}: cameras {args.cameras}, frames {first}–{last} from {sequence}', file=sys.stderr)
