"""`features eval BAG` and `features bench BAG`: the camera-feature pipeline measured offline.

eval compares with a synthetic bag's ground truth: silhouette IoU, skin precision / recall / F1,
2D keypoint error per keypoint against the projected ground-truth joints (root against the pelvis),
left/right swaps, and contour-label agreement with the ground-truth part labels (contour pixels
over the arms are left out: paper 000 labels them torso or leg on purpose).
bench times the pipeline per frame on one core, stage by stage, and JPEG decoding beside it.
"""
import os
import sys
import time
from pathlib import Path

import numpy as np

from mvpose_nodes.tools.cli import ArgumentParser, exit_on_user_error

TARGETS = {'iou': 0.97, 'skin_f1': 0.85, 'median_px': 15.0}  # issue targets at 1080p
TARGETED_KEYPOINTS = ('head', 'left_wrist', 'right_wrist', 'left_ankle', 'right_ankle')
TRUTH_JOINT = {'root': 'pelvis'}  # keypoints whose ground truth is another joint


def build_parser(prog):
    parser = ArgumentParser(prog=prog, description=__doc__.split('\n\n')[0])
    verbs = parser.add_subparsers(dest='verb', metavar='VERB', required=True)
    for verb, summary in (('eval', 'accuracy against a synthetic bag\'s ground truth'),
                          ('bench', 'per-frame time of the pipeline on one core')):
        command = verbs.add_parser(verb, help=summary, description=summary)
        command.add_argument('bag', type=Path, help='camera bag (synthetic, for eval)')
        command.add_argument('--cameras', type=int, nargs='+', metavar='K', help='cameras to use (default all)')
        command.add_argument('--params', type=Path, help='camera_features parameters YAML (default: the package\'s)')
        command.add_argument('--skin-model', type=Path, help='skin model .npz (default: the package\'s)')
    return parser


def main(argv=None, prog='features'):
    args = build_parser(prog).parse_args(sys.argv[1:] if argv is None else argv)
    with exit_on_user_error(f'{prog} {args.verb}'):
        if args.verb == 'bench':
            # One core, as the figure is defined: before OpenCV and NumPy start their thread pools.
            for variable in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS'):
                os.environ[variable] = '1'
            import cv2
            cv2.setNumThreads(1)
        extractor = make_extractor(args.params, args.skin_model)
        (evaluate if args.verb == 'eval' else benchmark)(args, extractor)
    return 0


def make_extractor(params_path, skin_model_path):
    from mvpose_nodes.ros.params import default_skin_model_path, load_feature_settings
    from mvpose_nodes.vision.features import FeatureExtractor
    from mvpose_nodes.vision.skin import SkinModel
    return FeatureExtractor(load_feature_settings(params_path), SkinModel.load(skin_model_path or default_skin_model_path()))


def evaluate(args, extractor):
    from scipy import ndimage
    from mvpose_nodes.body.model import JOINT_NAMES, LABEL_LEFT_ARM, LABEL_RIGHT_ARM
    from mvpose_nodes.ros.camera_bag import cameras_in, frame_sets
    from mvpose_nodes.tools.cli import UserError
    from mvpose_nodes.vision.features import KEYPOINT_NAMES, contour_label_agreement
    from mvpose_nodes.app.progress import Progress
    from mvpose_nodes.vision.skin import mask_counts
    from mvpose_nodes.studio.scene import SKIN_BIT

    ious, skin_counts, agreements, no_person = [], np.zeros(3), [], 0
    errors = {name: [] for name in KEYPOINT_NAMES}
    offsets = {name: [] for name in KEYPOINT_NAMES}  # (dx, dy) [px] estimate − truth
    matched = {name: [] for name in KEYPOINT_NAMES}  # error after matching left/right pairs to the truth
    swaps = {name: 0 for name in KEYPOINT_NAMES}
    images = 0
    cameras_in(args.bag, args.cameras)
    progress = Progress(count_images(args.bag, args.cameras), 'eval', unit='images')
    for frame_set in frame_sets(args.bag, args.cameras):
        if frame_set.truth is None or not frame_set.labels:
            raise UserError(f"bag '{args.bag}' has no ground truth (/mvpose/ground_truth and label masks): "
                            'eval needs a synthetic bag')
        for number, rgb in frame_set.images.items():
            labels = frame_set.labels[number] & ~np.uint8(SKIN_BIT)
            truth_skin = (frame_set.labels[number] & SKIN_BIT) > 0
            features = extractor(rgb)
            images += 1
            progress.update()
            truth_person = labels > 0
            ious.append(np.logical_and(features.silhouette, truth_person).sum()
                        / max(1, np.logical_or(features.silhouette, truth_person).sum()))
            skin_counts += mask_counts(features.skin, truth_skin)
            if not features.person:
                no_person += 1
                continue
            pixels, _ = frame_set.cameras[number].project(frame_set.truth)
            truth_2d = {name: pixels[JOINT_NAMES.index(TRUTH_JOINT.get(name, name))] for name in KEYPOINT_NAMES}
            for name, keypoint in features.keypoints.items():
                if not keypoint.visible:
                    continue
                error = float(np.hypot(keypoint.x - truth_2d[name][0], keypoint.y - truth_2d[name][1]))
                errors[name].append(error)
                offsets[name].append((keypoint.x - truth_2d[name][0], keypoint.y - truth_2d[name][1]))
            for name, error, swapped in pair_matched(features.keypoints, truth_2d):
                matched[name].append(error)
                swaps[name] += swapped
            # Ground-truth part under each contour pixel: that of the nearest person pixel.
            nearest = ndimage.distance_transform_edt(labels == 0, return_distances=False, return_indices=True)
            part = labels[nearest[0], nearest[1]]
            part[(part == LABEL_LEFT_ARM) | (part == LABEL_RIGHT_ARM)] = 0
            agreements.append(contour_label_agreement(features.contour, part))
    progress.close()
    report(args.bag, images, no_person, ious, skin_counts, errors, offsets, matched, swaps, agreements)


def pair_matched(keypoints, truth_2d):
    """(name, error [px], swapped) per keypoint with left/right pairs matched to the truth: the
    assignment of the pair's estimates to its two true points with the smaller total error (a
    single view cannot always tell the person's left from right; sides are scored separately)."""
    results = []
    for name, keypoint in keypoints.items():
        if keypoint.visible and not name.startswith(('left', 'right')):
            results.append((name, float(np.hypot(keypoint.x - truth_2d[name][0], keypoint.y - truth_2d[name][1])), 0))
    for left in (n for n in keypoints if n.startswith('left')):
        right = left.replace('left', 'right')
        estimates = {n: (keypoints[n].x, keypoints[n].y) for n in (left, right) if keypoints[n].visible}

        def errors_of(assignment):
            return [(n, float(np.hypot(estimates[n][0] - truth_2d[t][0], estimates[n][1] - truth_2d[t][1])))
                    for n, t in assignment.items() if n in estimates]
        straight, crossed = errors_of({left: left, right: right}), errors_of({left: right, right: left})
        swapped = sum(e for _, e in crossed) < sum(e for _, e in straight)
        results += [(n, e, int(swapped)) for n, e in (crossed if swapped else straight)]
    return results


def count_images(bag_path, cameras):
    from mvpose_nodes.io.bagfile import BagReader
    from mvpose_nodes.ros.camera_bag import CAMERA_TOPIC
    return sum(info.message_count for name, info in BagReader(bag_path).topics.items()
               if (m := CAMERA_TOPIC.match(name)) and m['kind'].startswith('image_raw')
               and (cameras is None or int(m['camera']) in cameras))


def report(bag, images, no_person, ious, skin_counts, errors, offsets, matched, swaps, agreements):
    from mvpose_nodes.vision.skin import scores_of_counts
    precision, recall, f1 = scores_of_counts(*skin_counts)
    mean_iou = float(np.mean(ious)) if ious else 0.0

    def verdict(ok):
        return 'meets target' if ok else 'BELOW TARGET'
    print(f'features eval: {bag}  ({images} images, {no_person} without a person found)')
    print(f'  silhouette IoU         mean {mean_iou:.4f}  min {min(ious, default=0):.4f}   '
          f'target >= {TARGETS["iou"]}: {verdict(mean_iou >= TARGETS["iou"])}')
    print(f'  skin                   precision {precision:.3f}  recall {recall:.3f}  F1 {f1:.3f}   '
          f'target F1 >= {TARGETS["skin_f1"]}: {verdict(f1 >= TARGETS["skin_f1"])}')
    print(f'  contour labels         agreement {np.mean(agreements) if agreements else 0:.3f} '
          '(contour pixels over the arms left out)')
    print('  keypoint errors [px]: "as labelled" uses the side the detector gave; "matched" pairs each left/right')
    print('  estimate with the true point of the assignment that fits best (sides are scored in "side right").')
    print(f'  {"keypoint":<14} {"found":>9} {"as labelled":>12} {"matched":>8} {"mean":>7} {"p90":>7} '
          f'{"side right":>11}   target (matched median)')
    for name in errors:
        values = matched[name]
        if not values:
            print(f'  {name:<14} {0:>4}/{images - no_person:<4} {"-":>12}')
            continue
        median = float(np.median(values))
        sides = f'{100 * (1 - swaps[name] / len(values)):>10.0f}%' if name.startswith(('left', 'right')) else f'{"":>11}'
        mark = (f'<= {TARGETS["median_px"]:g}: ' + ('ok' if median <= TARGETS['median_px'] else 'MISSED')) \
            if name in TARGETED_KEYPOINTS else ''
        print(f'  {name:<14} {len(values):>4}/{images - no_person:<4} {np.median(errors[name]):>12.1f} {median:>8.1f} '
              f'{np.mean(values):>7.1f} {np.percentile(values, 90):>7.1f} {sides}   {mark}')


def benchmark(args, extractor):
    import cv2
    from mvpose_nodes.ros.camera_bag import cameras_in, frame_sets
    from mvpose_nodes.vision.decoding import decode_image
    cameras_in(args.bag, args.cameras)
    decode, stages, totals = [], {}, []
    for frame_set in frame_sets(args.bag, args.cameras):
        for rgb in frame_set.images.values():
            ok, jpeg = cv2.imencode('.jpg', cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 90])
            started = time.perf_counter()
            decode_image(jpeg)
            decode.append(time.perf_counter() - started)
            started = time.perf_counter()
            features = extractor(rgb)
            totals.append(time.perf_counter() - started)
            for stage, seconds in features.timings.items():
                stages.setdefault(stage, []).append(seconds)
    if not totals:
        return
    height, width = rgb.shape[:2]
    print(f'features bench: {args.bag}  {len(totals)} images of {width}×{height}, one core')
    print(f'  {"stage":<22} {"median ms":>10} {"p95 ms":>8}')
    for stage, seconds in stages.items():
        print(f'  {stage:<22} {1e3 * np.median(seconds):>10.2f} {1e3 * np.percentile(seconds, 95):>8.2f}')
    print(f'  {"pipeline (all stages)":<22} {1e3 * np.median(totals):>10.2f} {1e3 * np.percentile(totals, 95):>8.2f}'
          f'   target <= 25 ms median: {"met" if np.median(totals) <= 0.025 else "MISSED"}')
    print(f'  {"JPEG decode (beside)":<22} {1e3 * np.median(decode):>10.2f} {1e3 * np.percentile(decode, 95):>8.2f}')
