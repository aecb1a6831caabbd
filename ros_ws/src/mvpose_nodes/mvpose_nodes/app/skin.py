"""`skin train`: build the skin colour model (paper 000 Sec. 3.2) from images with skin masks.

Sources: synthetic bags (their /cam<K>/ground_truth/labels masks mark skin), or a folder of
image / mask pairs (NAME.png or .jpg with NAME_skin.png, white = skin) for real data. The pixels
that count are the person and a band of background around it (DEFAULT_BAND px), so that the
backdrop's colours are learned as non-skin while the rest of a mostly empty frame does not
swamp the histogram.
"""
import sys
from pathlib import Path

import cv2
import numpy as np

from mvpose_nodes.tools.cli import ArgumentParser, UserError, exit_on_user_error

DEFAULT_BAND = 40  # [px] of background around the person that counts as non-skin training data


def build_parser(prog):
    parser = ArgumentParser(prog=prog, description=__doc__.split('\n\n')[0])
    verbs = parser.add_subparsers(dest='verb', metavar='VERB', required=True)
    train = verbs.add_parser('train', help='build a skin model from bags or image/mask folders',
                             description=__doc__.split('\n\n')[1].replace('\n', ' '))
    train.add_argument('sources', nargs='+', type=Path, help='synthetic bags and/or folders of image/mask pairs')
    train.add_argument('-o', '--output', type=Path, required=True, help='model file to write (.npz)')
    train.add_argument('--band', type=int, default=DEFAULT_BAND, help=f'background band [px] (default {DEFAULT_BAND})')
    train.add_argument('--alpha', type=float, default=None,
                       help='weight of the uniform colour prior (default: the skin module\'s, 0.05)')
    return parser


def main(argv=None, prog='skin'):
    args = build_parser(prog).parse_args(sys.argv[1:] if argv is None else argv)
    with exit_on_user_error(f'{prog} {args.verb}'):
        from mvpose_nodes.vision.skin import SkinModel
        if args.alpha is not None and not args.alpha > 0:
            raise UserError(f'--alpha must be > 0 (got {args.alpha})')
        model = SkinModel.empty() if args.alpha is None else SkinModel.empty(alpha=args.alpha)
        images = 0
        for source in args.sources:
            for rgb, skin, person in training_pairs(source):
                valid = cv2.dilate(person.astype(np.uint8), np.ones((2 * args.band + 1,) * 2, np.uint8)) > 0
                model.add(rgb, skin, valid)
                images += 1
        if not images:
            raise UserError('no training image found in ' + ', '.join(map(str, args.sources)))
        args.output.parent.mkdir(parents=True, exist_ok=True)
        model.save(args.output)
        print(f'[skin] {images} images: {int(model.skin_counts.sum())} skin and {int(model.background_counts.sum())} '
              f'non-skin pixels -> {args.output}', file=sys.stderr)
    return 0


def training_pairs(source):
    """(RGB (H, W, 3) uint8, skin (H, W) bool, person (H, W) bool) of every training image in `source`."""
    from mvpose_nodes.studio.scene import SKIN_BIT
    if not source.exists():
        raise UserError(f"'{source}': no such bag or folder")
    if (source / 'metadata.yaml').is_file() or source.suffix == '.mcap':
        from mvpose_nodes.ros.camera_bag import frame_sets
        for frame_set in frame_sets(source):
            for number, rgb in frame_set.images.items():
                labels = frame_set.labels.get(number)
                if labels is None:
                    raise UserError(f"bag '{source}' has no ground-truth label masks for camera {number}")
                yield rgb, (labels & SKIN_BIT) > 0, labels > 0
        return
    masks = sorted(source.glob('*_skin.png'))
    if not masks:
        raise UserError(f"'{source}': neither a bag nor a folder with NAME_skin.png masks")
    for mask_path in masks:
        stem = mask_path.name[:-len('_skin.png')]
        image_path = next((p for p in (source / f'{stem}.png', source / f'{stem}.jpg') if p.is_file()), None)
        if image_path is None:
            raise UserError(f"'{mask_path}': no image {stem}.png or {stem}.jpg beside it")
        image, mask = cv2.imread(str(image_path)), cv2.imread(str(mask_path), cv2.IMREAD_GRAYSCALE)
        if image is None or mask is None or image.shape[:2] != mask.shape:
            raise UserError(f"'{mask_path}': unreadable, or not the size of {image_path.name}")
        skin = mask > 127
        yield cv2.cvtColor(image, cv2.COLOR_BGR2RGB), skin, skin  # real data: only the skin's surroundings count
