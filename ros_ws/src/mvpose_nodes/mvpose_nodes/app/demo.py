"""`./mvpose demo`: the whole graph on the synthetic i3DPost walk, evaluated and drawn.

Makes `bags/i3dpost_walk_synth` (cameras 3, 5, 7, frames 52–101, 1080p) when it is missing, starts
three camera_features nodes and the skeleton_fitter as separate processes (launch/mvpose.launch.yaml),
plays the bag to them over DDS with `bag play`, prints a line per fitted frame, records the fitted and
true skeletons to a bag, prints paper 000's Table 2 beside the paper's numbers, and writes under one
output folder: the per-frame error plot (paper Fig. 12), a contact sheet of the fitted skeleton over
all 8 studio cameras beside the truth (Fig. 10), an MP4 of the fit over camera 5, and the motion as
BVH.
"""
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from mvpose_nodes.tools.cli import ArgumentParser, UserError, exit_on_user_error

DEMO_BAG = Path('bags/i3dpost_walk_synth')
DEMO_SYNTH_ARGUMENTS = ('--cameras', '3', '5', '7', '--frames', '52-101')
OUTPUT = Path('output/demo')
PLAYBACK_RATE = 0.05   # of the bag's 25 frames per second: what the graph keeps up with on 2 cores, a start included
#                        (its labellings compared: 0.5-0.7 s a frame set over its first 5, fitting/hypotheses.py)
ANIMATION_CAMERA = 5


def main(argv=None, prog='demo'):
    parser = ArgumentParser(prog=prog, description=__doc__.split('\n\n')[0])
    parser.add_argument('--bag', type=Path, help=f'camera bag to replay (default {DEMO_BAG}, made if missing)')
    parser.add_argument('-o', '--output', type=Path, help=f'folder for the results (default {OUTPUT}; replaced)')
    parser.add_argument('--rate', type=float, default=PLAYBACK_RATE,
                        help=f'playback speed, 1 = real time (default {PLAYBACK_RATE}: every frame set gets fitted '
                             'on a 2-core machine)')
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    with exit_on_user_error(prog):
        if not args.rate > 0:
            raise UserError(f'--rate must be positive (got {args.rate})')
        from mvpose_nodes.app.main import repository_root
        root = repository_root()
        bag = args.bag or root / DEMO_BAG
        if not bag.exists():
            print(f'[demo] making {bag} with `./mvpose synth {" ".join(DEMO_SYNTH_ARGUMENTS)}` (about 30 s)', flush=True)
            tool(['synth', *DEMO_SYNTH_ARGUMENTS, '-o', str(bag)])
        output = args.output or root / OUTPUT
        return demo(bag, output, args.rate)


def tool(arguments):
    """Run another ./mvpose subcommand in this environment; stop the demo if it fails."""
    result = subprocess.run([sys.executable, '-m', 'mvpose_nodes.app.main', *arguments])
    if result.returncode != 0:
        sys.exit(result.returncode)


def demo(bag, output, rate):
    from mvpose_nodes.app.graph_run import GRAPH_CAMERAS, run_graph, write_run_bag
    started = time.monotonic()
    if output.exists():
        shutil.rmtree(output)
    output.mkdir(parents=True)
    print(f'[demo] starting 3 × camera_features (/cam3, /cam5, /cam7) and skeleton_fitter, then playing {bag} '
          f'at {rate:g}× (node logs: {output / "graph.log"})', flush=True)
    run = run_graph(bag, output / 'graph.log', rate=rate, on_skeleton=live_line)
    if not run.fitted:
        raise UserError(f'no skeleton came out of the graph; see {run.log}')
    recorded = output / 'fitted'
    write_run_bag(run, recorded)
    print(f'[demo] {len(run.fitted)} of {run.frame_sets} frame sets fitted in {run.playback_seconds:.0f} s of '
          f'playback; recorded to {recorded}', flush=True)
    pictures = evaluate_and_draw(bag, run, output, GRAPH_CAMERAS)
    tool(['export', str(recorded), '--format', 'bvh', '-o', str(output / 'fitted.bvh')])
    summary(bag, run, pictures, output, time.monotonic() - started)
    if len(run.fitted) < run.frame_sets:
        print(f'[demo] FAILED: {run.frame_sets - len(run.fitted)} of the {run.frame_sets} frame sets got no fitted '
              f"skeleton (missing, or STATUS_LOST); the nodes' log: {run.log}", file=sys.stderr, flush=True)
        return 1
    return 0


def live_line(message, run):
    """One compact line per fitted frame: frame, count, status, fit time, and the error where the truth is known."""
    from mvpose_nodes.app.reports.accuracy import joint_errors_mm
    from mvpose_nodes.io.motion_export import STATUS_NAMES
    from mvpose_nodes.ros.camera_bag import frame_number_of
    from mvpose_nodes.ros.conversions import joints_from_skeleton, stamp_ns
    stamp = stamp_ns(message.header)
    status = STATUS_NAMES.get(message.status, str(message.status))
    truth = run.truth.get(stamp)
    error = ''
    if truth is not None:
        mean = joint_errors_mm(joints_from_skeleton(message), joints_from_skeleton(truth)).mean()
        error = f'  mean joint error {mean:5.1f} mm'
    print(f'[demo] frame {frame_number_of(stamp):4d}  {len(run.fitted):3d}/{run.frame_sets}  {status:<12} '
          f'fit {1000 * message.fit_time:4.0f} ms{error}', flush=True)


def evaluate_and_draw(bag, run, output, used_cameras):
    """Table 2 on the terminal; the error plot, contact sheet and animation on disk. {name: Path}."""
    from mvpose_nodes.body.camera import studio_rig
    from mvpose_nodes.ros.camera_bag import frame_number_of, frame_sets
    from mvpose_nodes.app.reports.accuracy import joint_errors_mm, print_table_2
    from mvpose_nodes.app.reports.animation import animation
    from mvpose_nodes.app.reports.plots import error_plot
    from mvpose_nodes.app.reports.sheets import contact_sheet
    from mvpose_nodes.ros.conversions import joints_from_skeleton
    pictures = {}
    stamps = sorted(run.fitted)
    fitted = np.array([joints_from_skeleton(run.fitted[s]) for s in stamps])
    truth_stamps = [s for s in stamps if s in run.truth]
    if truth_stamps:
        truth = np.array([joints_from_skeleton(run.truth[s]) for s in truth_stamps])
        matched = np.array([joints_from_skeleton(run.fitted[s]) for s in truth_stamps])
        print()
        print_table_2(matched, truth, output / 'fitted')
        print()
        all_stamps = sorted(run.truth)   # every played frame: the ones without a fit are gaps in the plot
        per_joint = np.full((len(all_stamps), fitted.shape[1]), np.nan)
        for row, stamp in enumerate(all_stamps):
            if stamp in run.fitted:
                per_joint[row] = joint_errors_mm(joints_from_skeleton(run.fitted[stamp]),
                                                 joints_from_skeleton(run.truth[stamp]))
        pictures['error plot'] = error_plot(per_joint.mean(axis=1), [frame_number_of(s) for s in all_stamps],
                                            output / 'error_per_frame.png', per_joint=per_joint)
    middle = stamps[len(stamps) // 2]
    images, cameras, frames = {}, {}, []
    for frame_set in frame_sets(bag):
        if frame_set.stamp_ns == middle:
            images, cameras = dict(frame_set.images), dict(frame_set.cameras)
        if ANIMATION_CAMERA in frame_set.images:
            frames.append((frame_set.stamp_ns, frame_set.images[ANIMATION_CAMERA], frame_set.cameras[ANIMATION_CAMERA]))
    if run.truth:   # a synthetic bag: the studio's other cameras show the fit from where it was not seen
        cameras = {**{camera.number: camera for camera in studio_rig()}, **cameras}
    true_middle = joints_from_skeleton(run.truth[middle]) if middle in run.truth else None
    pictures['contact sheet'] = contact_sheet(
        images, cameras, joints_from_skeleton(run.fitted[middle]), true_middle,
        output / f'contact_sheet_frame{frame_number_of(middle)}.png', used_cameras=set(used_cameras),
        title=f'frame {frame_number_of(middle)}: fitted skeleton (colour) and ground truth (white)')
    if frames:
        poses = np.array([joints_from_skeleton(run.fitted[s]) if s in run.fitted else np.full((15, 3), np.nan)
                          for s, _, _ in frames])
        truths = None
        if run.truth:
            truths = np.array([joints_from_skeleton(run.truth[s]) if s in run.truth else np.full((15, 3), np.nan)
                               for s, _, _ in frames])
        pictures['animation'] = animation(poses, output / f'fit_over_cam{ANIMATION_CAMERA}.mp4', camera=frames[0][2],
                                          images=[image for _, image, _ in frames], truth=truths,
                                          frame_numbers=[frame_number_of(s) for s, _, _ in frames])
    return pictures


def summary(bag, run, pictures, output, seconds):
    from mvpose_nodes.app.reports.accuracy import PAPER_MEAN_MM, joint_errors_mm
    from mvpose_nodes.ros.conversions import joints_from_skeleton
    error = ''
    matched = [s for s in run.fitted if s in run.truth]
    if matched:
        mean = np.mean([joint_errors_mm(joints_from_skeleton(run.fitted[s]), joints_from_skeleton(run.truth[s])).mean()
                        for s in matched])
        error = (f' Their mean joint error against the ground truth is {mean:.1f} mm (paper 000: {PAPER_MEAN_MM} mm '
                 'on i3DPost).')
    fit_ms = 1000 * np.median([m.fit_time for m in run.fitted.values()])
    listed = '; '.join(f'{name}: {path}' for name, path in pictures.items())
    print(f'[demo] What was shown: {bag} was replayed over DDS to three camera_features processes and a '
          f'skeleton_fitter process, which fitted {len(run.fitted)} of its {run.frame_sets} frame sets '
          f'(median fit {fit_ms:.0f} ms per frame set).{error} Written to {output}: {listed}; the fitted '
          f'motion as BVH ({output / "fitted.bvh"}) and the recorded skeletons ({output / "fitted"}). '
          f'The demo took {seconds:.0f} s.', flush=True)
