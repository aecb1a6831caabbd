"""`markers eval BAG`: marker mode (paper 001) against a synthetic marker bag's ground truth.

Three methods run over the bag's images, each initialised from the first frame's ground-truth markers
(standing in for an operator's labelling of the calibration frame): the nearest-neighbour baseline
(markers.NearestNeighbourTracker) and paper 001's region-constrained tracker (markers.MarkerTracker),
each camera on its own, and what the marker mode graph computes: the region tracker in every camera,
the cameras' tracks fused in 3D each frame (marker_views.MarkerViews) and fed back to the trackers.
Printed per marker: the mean and max 2D error [px] where the marker is visible and where it is hidden
(the prediction), and identity swaps; then the 3D markers against the true centres [mm] (for the
first two, triangulated from the detected markers by marker_triangulation).
"""
import sys
from pathlib import Path

import numpy as np

from mvpose_nodes.app.reports.accuracy import joint_errors_mm
from mvpose_nodes.tools.cli import ArgumentParser, UserError, exit_on_user_error

FUSED = 'regions + 3D fusion'   # the marker mode graph: marker_tracker per camera + marker_skeleton
SWAP_RATIO = 2.0     # a marker nearer another marker's true position than this times its own error ...
SWAP_MIN_PX = 5.0    # ... and more than this far from its own: an identity swap
TARGETS = {'swaps': 0, 'visible': 2.0, 'predicted': 6.0}   # issue 7's targets [-, px, px]


def markers_main(argv=None, prog='markers'):
    parser = ArgumentParser(prog=prog, description=__doc__.split('\n\n')[0])
    commands = parser.add_subparsers(dest='command', metavar='COMMAND', required=True)
    evaluate = commands.add_parser('eval', help='marker tracking against a synthetic marker bag',
                                   description=__doc__.split('\n\n')[1])
    evaluate.add_argument('bag', type=Path, help='a bag made by ./mvpose synth --markers')
    evaluate.add_argument('--cameras', type=int, nargs='+', metavar='K', help='cameras to track (default: all in the bag)')
    evaluate.add_argument('--pictures', type=Path, metavar='DIR',
                          help='also draw the fused tracks over every camera at the frame with the most hidden '
                               'markers and at the worst frame (DIR/markers_frame<N>_*.png)')
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    with exit_on_user_error(prog):
        evaluate_bag(args.bag, args.cameras, args.pictures)
    return 0


def evaluate_bag(bag, cameras=None, pictures=None):
    from mvpose_nodes.body.model import JOINT_NAMES
    from mvpose_nodes.ros.camera_bag import cameras_in, frame_sets
    from mvpose_nodes.markers.views import ViewTrackers
    from mvpose_nodes.markers.tracking import MarkerTracker, NearestNeighbourTracker
    from mvpose_nodes.app.progress import Progress

    cameras_in(bag, cameras)
    sets = [s for s in frame_sets(bag, cameras) if s.markers]
    if not sets:
        raise UserError(f"bag '{bag}' has no ground-truth markers (/cam<K>/ground_truth/markers): "
                        "make one with ./mvpose synth --markers")
    numbers = sorted(sets[0].markers)
    sets = [s for s in sets if all(k in s.markers and k in s.images for k in numbers)]
    camera_of = {k: sets[0].cameras[k] for k in numbers}
    methods = {'nearest neighbour': NearestNeighbourTracker, 'regions (paper 001)': MarkerTracker}
    trackers = {method: {k: make() for k in numbers} for method, make in methods.items()}
    fused = ViewTrackers([camera_of[k] for k in numbers])
    results = {method: {k: [] for k in numbers} for method in [*methods, FUSED]}
    fused_3d, truth_3d = [], []
    progress = Progress(len(sets), 'markers eval')
    for index, frame_set in enumerate(sets):
        truth_3d.append(frame_set.marker_centres if frame_set.marker_centres is not None else frame_set.truth)
        truth = {k: frame_set.markers[k] for k in numbers}
        tracks = {}
        for method in methods:
            for k in numbers:
                tracker = trackers[method][k]
                image = frame_set.images[k]
                # The labelled first frame's tracks are its labelling snapped to the detections.
                tracks[method, k] = tracker.initialise(image, *truth[k]) if index == 0 else tracker.track(image)
        points, positions, flags = fused.track([frame_set.images[k] for k in numbers],
                                               [truth[k] for k in numbers] if index == 0 else None)
        fused_3d.append(points)
        for c, k in enumerate(numbers):
            tracks[FUSED, k] = (positions[c], flags[c])
        for (method, k), (estimate, estimate_flags) in tracks.items():
            results[method][k].append((estimate, estimate_flags, *truth[k]))
        progress.update()
    progress.close()
    report(bag, results, camera_of, truth_3d, JOINT_NAMES, {FUSED: fused_3d})
    if pictures is not None:
        for path in draw_frames(pictures, sets, results[FUSED]):
            print(f'  wrote {path}')


def errors_and_swaps(runs):
    """From [(positions (15, 2), flags (15,), true (15, 2), visible (15,) bool)] over frames (one camera):
    errors (F, 15) [px], visible (F, 15) bool, swapped (F, 15) bool (a marker nearer another marker's true
    position than SWAP_RATIO times its own error, and more than SWAP_MIN_PX off)."""
    positions = np.array([r[0] for r in runs])
    true = np.array([r[2] for r in runs])
    visible = np.array([r[3] for r in runs], bool)
    errors = np.linalg.norm(positions - true, axis=2)
    to_others = np.linalg.norm(positions[:, :, None] - true[:, None], axis=3)   # (F, estimate, truth)
    count = positions.shape[1]
    to_others[:, np.arange(count), np.arange(count)] = np.inf
    swapped = (SWAP_RATIO * to_others.min(axis=2) < errors) & (errors > SWAP_MIN_PX)
    return errors, visible, swapped


def swap_events(swapped):
    """Identity swaps counted once each: per marker, the frames where a swap begins. swapped (F, M) bool."""
    begins = swapped & ~np.vstack([np.zeros((1, swapped.shape[1]), bool), swapped[:-1]])
    return int(begins.sum())


def report(bag, results, camera_of, truth_3d, names, fused_3d):
    methods = list(results)
    summary = {}
    print(f'markers eval: {bag}  (cameras {" ".join(map(str, sorted(camera_of)))}, {len(truth_3d)} frames)   '
          f'2D errors [px] against the true marker centres; "hidden" = the prediction while the marker is occluded')
    print(f'  {"":<16}' + ''.join(f'{m:<45}' for m in methods))
    print(f'  {"marker":<16}' + f'{"visible mean  max  hidden mean  max  swaps":<45}' * len(methods))
    per_method = {}
    for method in methods:
        per_camera = [errors_and_swaps(runs) for runs in results[method].values()]
        errors = np.concatenate([e for e, _, _ in per_camera])
        visible = np.concatenate([v for _, v, _ in per_camera])
        swaps = np.array([[swap_events(s[:, [m]]) for m in range(len(names))] for _, _, s in per_camera]).sum(axis=0)
        per_method[method] = errors, visible, swaps

    def cells(values):
        return (f'{values.mean():6.1f} {values.max():5.1f}' if len(values) else f'{"–":>6} {"–":>5}')
    for m, name in enumerate(names):
        row = f'  {name:<16}'
        for method in methods:
            errors, visible, swaps = per_method[method]
            row += (f'{cells(errors[visible[:, m], m]):>12}  {cells(errors[~visible[:, m], m]):>11}  '
                    f'{swaps[m]:>4}').ljust(45)
        print(row)
    print(f'  {"all":<16}' + ''.join(
        (f'{cells(e[v]):>12}  {cells(e[~v]):>11}  {s.sum():>4}').ljust(45) for e, v, s in per_method.values()))
    for method in methods:
        errors, visible, swaps = per_method[method]
        joints = fused_3d.get(method)
        if joints is None:
            joints = triangulated(results[method], camera_of)
        truth = np.array(truth_3d[:len(joints)], dtype=float)
        error_3d = joint_errors_mm(np.array(joints), truth)
        summary[method] = (errors[visible].mean() if visible.any() else np.nan,
                           errors[~visible].mean() if (~visible).any() else np.nan, int(swaps.sum()),
                           np.nanmean(error_3d), np.nanmax(error_3d))
    print('  totals                 visible mean [px]  hidden mean [px]  identity swaps  3D triangulated mean / max [mm]')
    for method, (v, h, s, mean_3d, max_3d) in summary.items():
        print(f'  {method:<22} {v:>12.2f} {h:>17.2f} {s:>15d}   {mean_3d:>10.1f} / {max_3d:.1f}')
    print(f'  targets: {TARGETS["swaps"]} identity swaps, visible mean <= {TARGETS["visible"]} px, '
          f'hidden (predicted) mean <= {TARGETS["predicted"]} px')


def draw_frames(directory, sets, runs):
    """The fused tracks drawn over every camera (reports.sheets.marker_sheet) at the frame with the most
    hidden markers and at the frame with the largest mean error; the paths written."""
    from mvpose_nodes.app.reports.sheets import marker_sheet
    cameras = sorted(runs)
    errors = np.mean([errors_and_swaps(runs[k])[0] for k in cameras], axis=(0, 2))       # (F,)
    hidden = np.sum([[~r[3] for r in runs[k]] for k in cameras], axis=(0, 2))          # (F,)
    written = []
    for kind, f in (('most_hidden', int(np.argmax(hidden))), ('worst', int(np.argmax(errors)))):
        frame = sets[f].frame
        title = (f'frame {frame}: {int(hidden[f])} hidden marker views, mean error {errors[f]:.1f} px '
                 f'(regions + 3D fusion)')
        written.append(marker_sheet({k: sets[f].images[k] for k in cameras},
                                    {k: runs[k][f][:2] for k in cameras}, {k: runs[k][f][2:] for k in cameras},
                                    Path(directory) / f'markers_frame{frame}_{kind}.png', title=title))
    return written


def triangulated(runs, camera_of):
    """(F, 15, 3) [m]: each frame's markers triangulated from the cameras' tracks (marker_triangulation),
    for the trackers that do not fuse their views themselves."""
    from mvpose_nodes.markers.triangulation import triangulate_markers
    cameras = sorted(runs)
    joints, previous = [], None
    for f in range(min(len(runs[k]) for k in cameras)):
        estimate, _ = triangulate_markers([camera_of[k] for k in cameras], [runs[k][f][0] for k in cameras],
                                          [runs[k][f][1] for k in cameras], previous)
        previous = estimate if np.all(np.isfinite(estimate)) else previous
        joints.append(estimate)
    return np.array(joints)
