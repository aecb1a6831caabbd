"""`preview BAG --frame N -o FILE.png`: every camera of a bag at one frame, in one picture, with the
skeletons projected on (like paper 000's Fig. 10): the ground truth (white) and, where the bag has
it, the fitted /mvpose/skeleton (left side green, right side orange, centre yellow)."""
import math
import sys
from pathlib import Path

import cv2
import numpy as np

from mvpose_nodes.ros.camera_bag import GROUND_TRUTH_TOPIC
from mvpose_nodes.tools.cli import ArgumentParser, UserError, exit_on_user_error
from mvpose_nodes.app.reports.drawing import draw_skeleton  # the project's one skeleton drawing function

TILE_WIDTH = 640  # [px] of each camera's tile in the sheet


def build_parser(prog):
    parser = ArgumentParser(prog=prog, description=__doc__.split('\n\n')[0].replace('\n', ' '))
    parser.add_argument('bag', type=Path, help='bag directory or .mcap file')
    parser.add_argument('--frame', type=int, help='frame number (default: the first frame of the bag)')
    parser.add_argument('-o', '--output', type=Path, help='PNG to write (default: <bag name>_frame<N>.png)')
    return parser


def main(argv=None, prog='preview'):
    args = build_parser(prog).parse_args(sys.argv[1:] if argv is None else argv)
    with exit_on_user_error(prog):
        frame, sheet = contact_sheet(args.bag, args.frame)
        output = args.output or Path(f'{args.bag.name}_frame{frame}.png')
        if output.suffix.lower() != '.png':
            raise UserError(f"-o {output}: the contact sheet is a PNG file (name it .png)")
        output.parent.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(output), cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))
        print(f'[preview] wrote {output} ({sheet.shape[1]}×{sheet.shape[0]}, frame {frame})', file=sys.stderr)
    return 0


def frame_contents(bag_path, frame):
    """The FrameSet (camera_bag) of frame number `frame` of a bag (None: its first frame with images)."""
    from mvpose_nodes.ros.camera_bag import frame_sets
    seen = []
    for frame_set in frame_sets(bag_path):
        if frame_set.images:
            seen.append(frame_set.frame)
            if frame is None or frame_set.frame == frame:
                return frame_set
    if not seen:
        raise UserError(f"bag '{bag_path}' has no /cam<K>/image_raw[/compressed] topic")
    raise UserError(f"bag '{bag_path}' has no image at frame {frame} (its frames: {seen[0]}–{seen[-1]})")


def contact_sheet(bag_path, frame):
    """(frame, RGB uint8 sheet): every camera's image at `frame` with the skeletons drawn, in a grid."""
    frame_set = frame_contents(bag_path, frame)
    frame = frame_set.frame
    tiles = []
    for number, image in sorted(frame_set.images.items()):
        canvas = image.copy()
        for topic, joints in sorted(frame_set.skeletons.items()):
            draw_skeleton(canvas, frame_set.cameras[number], joints, truth=topic == GROUND_TRUTH_TOPIC)
        tile = cv2.resize(canvas, (TILE_WIDTH, round(TILE_WIDTH * image.shape[0] / image.shape[1])),
                          interpolation=cv2.INTER_AREA)
        cv2.putText(tile, f'cam{number}  frame {frame}', (12, 30), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (255, 255, 255), 2,
                    cv2.LINE_AA)
        tiles.append(tile)
    columns = min(4, len(tiles))
    rows = math.ceil(len(tiles) / columns)
    height = max(t.shape[0] for t in tiles)
    sheet = np.zeros((rows * height, columns * TILE_WIDTH, 3), np.uint8)
    for i, tile in enumerate(tiles):
        r, c = divmod(i, columns)
        sheet[r * height:r * height + tile.shape[0], c * TILE_WIDTH:(c + 1) * TILE_WIDTH] = tile
    return frame, sheet
