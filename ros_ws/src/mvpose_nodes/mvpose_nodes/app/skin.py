"""`skin train`: build the skin colour model (paper 000 Sec. 3.2) from images with skin masks.

Sources: synthetic bags (their /cam<K>/ground_truth/labels masks mark skin), a folder of image / mask
pairs (NAME.png or .jpg with NAME_skin.png, white = skin) for real data, or --studio N: N people drawn
and rendered as the evaluation suite draws them (every skin tone, hair colour, shirt and trouser colour,
exposure, white balance, noise, blur and JPEG quality of studio/cases.py), posed in the suite's tuning
motions. The pixels that count are the person and a band of background around it (DEFAULT_BAND px), so
that the backdrop's colours are learned as non-skin while the rest of a mostly empty frame does not
swamp the histogram.

--studio learns the hair and clothes of many people as non-skin where their colours differ from skin.
The package's model was trained on synthetic bags instead: docs/method.md says what --studio 80 gave.
"""
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import cv2
import numpy as np

from mvpose_nodes.tools.cli import ArgumentParser, UserError, end_with_parent, exit_on_user_error

DEFAULT_BAND = 40  # [px] of background around the person that counts as non-skin training data
DEFAULT_STUDIO_SEED = 1000   # of --studio's draw: far from the small seeds the suite is run with
STUDIO_CAMERAS = 3           # cameras rendered per drawn person (the first of the case's)
STUDIO_FRAMES = 2            # instants per camera, drawn in the person's motion window


def build_parser(prog):
    parser = ArgumentParser(prog=prog, description=__doc__.split('\n\n')[0])
    verbs = parser.add_subparsers(dest='verb', metavar='VERB', required=True)
    train = verbs.add_parser('train', help='build a skin model from bags, image/mask folders or studio renders',
                             description=' '.join(__doc__.split('\n\n')[1:3]).replace('\n', ' '))
    train.add_argument('sources', nargs='*', type=Path, help='synthetic bags and/or folders of image/mask pairs')
    train.add_argument('-o', '--output', type=Path, required=True, help='model file to write (.npz)')
    train.add_argument('--studio', type=int, default=0, metavar='N',
                       help=f'also N people drawn and rendered by the studio ({STUDIO_CAMERAS} cameras × '
                            f'{STUDIO_FRAMES} instants each, 1920×1080)')
    train.add_argument('--seed', type=int, default=DEFAULT_STUDIO_SEED,
                       help=f"seed of --studio's draw (default {DEFAULT_STUDIO_SEED})")
    train.add_argument('-j', '--jobs', type=int, default=2, help='--studio people rendered at once (default 2)')
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
        if args.studio < 0 or args.jobs < 1:
            raise UserError(f'--studio takes 0 or more people and --jobs at least 1 (got {args.studio}, {args.jobs})')
        if not args.sources and not args.studio:
            raise UserError('give bags or folders to train on, or --studio N')
        model = SkinModel.empty() if args.alpha is None else SkinModel.empty(alpha=args.alpha)
        images = 0
        for source in args.sources:
            images += add_pairs(model, training_pairs(source), args.band)
        if args.studio:
            images += add_studio(model, args.studio, args.seed, args.band, args.jobs)
        if not images:
            raise UserError('no training image found in ' + ', '.join(map(str, args.sources)))
        args.output.parent.mkdir(parents=True, exist_ok=True)
        model.save(args.output)
        print(f'[skin] {images} images: {int(model.skin_counts.sum())} skin and {int(model.background_counts.sum())} '
              f'non-skin pixels -> {args.output}', file=sys.stderr)
    return 0


def add_pairs(model, pairs, band):
    """Count (RGB, skin, person) training pairs into `model`: skin and, as non-skin, the rest of the person
    and `band` px of background around it. Returns how many images were added."""
    images = 0
    for rgb, skin, person in pairs:
        valid = cv2.dilate(person.astype(np.uint8), np.ones((2 * band + 1,) * 2, np.uint8)) > 0
        model.add(rgb, skin, valid)
        images += 1
    return images


def add_studio(model, people, seed, band, jobs):
    """Count `people` studio renders (studio_pairs) into `model`, `jobs` at once, with a progress bar.
    Returns how many images were added."""
    from mvpose_nodes.app.progress import Progress
    progress = Progress(people, 'skin', unit='people')
    images = 0
    cv2.setNumThreads(1)   # no OpenCV pool thread to fork with a mutex held (as in the suite)
    with ProcessPoolExecutor(max_workers=jobs, initializer=end_with_parent) as pool:
        for person, count in pool.map(studio_model, range(people), [seed] * people, [band] * people):
            model.merge(person)
            images += count
            progress.update()
    progress.close()
    return images


def studio_model(index, seed, band):
    """(SkinModel of person `index` of the --studio draw seeded `seed` alone, how many images it counts)."""
    from mvpose_nodes.vision.skin import SkinModel
    model = SkinModel.empty()
    return model, add_pairs(model, studio_pairs(index, seed), band)


def studio_pairs(index, seed):
    """(RGB (H, W, 3) uint8 through the case's JPEG, skin (H, W) bool, person (H, W) bool) of person `index`
    of the draw seeded `seed`: a suite case over the tuning motions (studio.cases.draw_case), its first
    STUDIO_CAMERAS cameras at STUDIO_FRAMES instants of its motion window drawn from the same seed."""
    from mvpose_nodes.app.suite import chosen_motions
    from mvpose_nodes.app.suite.features import case_motion, render_camera
    from mvpose_nodes.studio import scene
    from mvpose_nodes.studio.cases import case_rng, draw_case
    from mvpose_nodes.studio.catalogue import motion_length
    motions = {name: motion_length(name) for name in chosen_motions('tuning')}
    case = draw_case(case_rng(seed, index), index, motions, 50, (1920, 1080))
    motion = case_motion(case)
    cameras = {c.number: c for c in case.rig}
    instants = np.random.default_rng([seed, index, 7])
    for number in case.cameras[:STUDIO_CAMERAS]:
        view = scene.prepare_camera(cameras[number], texture_seed=number)
        for frame in instants.integers(0, len(motion.joints), STUDIO_FRAMES):
            rgb, labels = render_camera(case, view, motion, int(frame))
            yield rgb, (labels & scene.SKIN_BIT) > 0, labels > 0


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
