"""`eval suite`: the fitter's accuracy over randomised studio cases, not one walk.

Each case is drawn at random (seeded: studio/cases.py) over motions (studio/catalogue.py: CMU and AMP
motion capture and scripted actions, started anywhere), rigs, bodies, clothes and imaging. It is
rendered with the studio frame by frame, every camera at its own jittered instant; each image goes
through JPEG at the case's quality, the camera_features pipeline and its messages (serialised and read
back, as they cross DDS), and each frame set through ros/frame_set_fitting.py, the code the
skeleton_fitter node runs. Nothing crosses DDS, so a case's figures do not depend on the machine's load.

Printed: a row per case (motion, rig, body, mean / median / worst-frame error, frames with a left/right
swap after the first SWAP_GRACE_FRAMES, frame sets without a skeleton, median fit time), and per motion
set (tuning, held-out, stress) the mean, median, 90th percentile and worst of the cases' mean errors,
plus each joint's mean. Written to --output: every case's row as JSON (FIGURES_FILE, which `eval compare`
reads), the worst case's per-frame error plot and an overlay of its worst frame over the cameras it used.

With --features-cache DIR a case's feature messages are kept after their first computation and read back
the next time (rendering and features are 90 % of the suite's time), for fitter work: the key is
the case and the code and data that make its features (suite.features.FEATURE_SOURCES and the skin
model), so a change to those is never read from a stale cache, and a change to this module's tables is
not one of them.
"""
import json
import math
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mvpose_nodes.app.suite.features import case_features, case_motion, placed_window, render_camera
from mvpose_nodes.body.kinematics import LENGTH_FRACTIONS
from mvpose_nodes.tools.cli import ArgumentParser, UserError, end_with_parent, exit_on_user_error

SWAP_GRACE_FRAMES = 10   # the first frames of a case may still be sorting left from right (issue 13's target)
MOTION_SETS = ('tuning', 'held-out', 'stress')
FIGURES_FILE = 'cases.json'   # in --output: every case's row of the table (write_figures), for `eval compare`


def build_parser(prog):
    parser = ArgumentParser(prog=prog, description=__doc__.split('\n\n')[0])
    parser.add_argument('--cases', type=int, default=12, metavar='N', help='cases to draw (default 12)')
    parser.add_argument('--seed', type=int, default=0, help='seed of the draw (default 0)')
    parser.add_argument('--cameras', type=int, nargs='+', metavar='K',
                        help='use these cameras in every case (default: any 3, or all 8, drawn per case)')
    parser.add_argument('--motions', default='all',
                        help="'all', 'tuning', 'held-out', 'stress', or motion names separated by commas")
    parser.add_argument('--frames', type=int, default=50, help='frame sets per case (default 50, 2 s)')
    parser.add_argument('--only', type=int, nargs='+', metavar='INDEX',
                        help='run only these cases of the draw (as numbered in the table), e.g. to look at one again')
    parser.add_argument('--resolution', default='1920x1080', help='WIDTHxHEIGHT (default 1920x1080)')
    parser.add_argument('-j', '--jobs', type=int, default=2, help='cases rendered and fitted at once (default 2)')
    parser.add_argument('--true-lengths', nargs='*', choices=list(LENGTH_FRACTIONS), metavar='KEY',
                        help="diagnosis: fit with the person's true bone lengths (from the motion) instead of "
                             'measuring them, to see how much of the error the measurement of the person costs; '
                             f"with KEYs ({', '.join(LENGTH_FRACTIONS)}) only those, the others measured")
    parser.add_argument('--gaps', type=int, nargs='+', metavar='G',
                        help='fit only some frame sets, as the skeleton_fitter does at `bag play` speed when it '
                             'cannot keep up: each next one G frame sets on, G drawn per step (seeded by the '
                             'case) from these, e.g. --gaps 1 2 2 3 (default: every frame set)')
    parser.add_argument('-o', '--output', type=Path, default=Path('output/suite'),
                        help=f"folder for every case's figures ({FIGURES_FILE}) and the worst case's pictures "
                             '(default output/suite)')
    parser.add_argument('--features-cache', type=Path, metavar='DIR',
                        help="keep each case's feature messages in DIR and read them back on later runs (for "
                             'fitter work; renewed when the studio, features or conversion code changes)')
    return parser


def motion_set(name):
    from mvpose_nodes.studio.catalogue import HELD_OUT_MOTIONS, STRESS_MOTIONS
    return 'held-out' if name in HELD_OUT_MOTIONS else 'stress' if name in STRESS_MOTIONS else 'tuning'


def chosen_motions(text):
    """The motion names --motions selects, in catalogue order; UserError naming the known ones."""
    from mvpose_nodes.studio.catalogue import MOTIONS
    if text == 'all':
        return tuple(MOTIONS)
    if text in MOTION_SETS:
        return tuple(name for name in MOTIONS if motion_set(name) == text)
    names = tuple(n.strip() for n in text.split(',') if n.strip())
    unknown = [n for n in names if n not in MOTIONS]
    if unknown or not names:
        raise UserError(f"--motions: unknown {', '.join(unknown) or 'empty list'} (known: all, "
                        f"{', '.join(MOTION_SETS)}, {', '.join(MOTIONS)})")
    return names


def draw_cases(args, resolution):
    """The cases of a run: motions cycled through in a seeded order (every chosen motion once before any
    twice), everything else drawn per case by studio.cases.draw_case, each window kept in view (in_view)."""
    from mvpose_nodes.studio.cases import case_rng, draw_case
    motions = chosen_motions(args.motions)
    order = [motions[i] for i in np.random.default_rng(args.seed).permutation(len(motions))]
    return [in_view(draw_case(case_rng(args.seed, index), index, (order[index % len(order)],),
                              args.frames, resolution, cameras=args.cameras)) for index in range(args.cases)]


def in_view(case):
    """The case with its window shortened at its end, if need be, until every frame of it shows the whole
    person to at least studio.cases.MIN_FULL_VIEWS of its cameras (studio.cases.full_views): a studio
    captures what happens inside its ring, and no fit can follow a person the cameras do not see. (Drawn
    over the tuning motions, 8 of 34 cases had 2–25 frames that at most one camera saw whole: runs of 8 m
    across rings of 6–10 m, and walks to the edge.) At least 2 frames are kept."""
    from dataclasses import replace
    from mvpose_nodes.studio.cases import MIN_FULL_VIEWS, full_views
    from mvpose_nodes.studio.catalogue import load_motion
    motion = load_motion(case.motion, height=case.height)
    for frames in range(case.frames, 2, -1):
        if (full_views(case, placed_window(motion, case, frames).joints) >= MIN_FULL_VIEWS).all():
            return case if frames == case.frames else replace(case, frames=frames)
    return replace(case, frames=min(2, case.frames))


def main(argv=None, prog='eval suite'):
    args = build_parser(prog).parse_args(sys.argv[1:] if argv is None else argv)
    with exit_on_user_error(prog):
        from mvpose_nodes.app.synth import parse_resolution
        from mvpose_nodes.app.progress import Progress
        if args.cases < 1 or args.frames < 2 or args.jobs < 1 or min(args.gaps or [1]) < 1:
            raise UserError('--cases, --jobs and --gaps take at least 1, --frames at least 2')
        if args.cameras is not None and (len(set(args.cameras)) != len(args.cameras) or len(args.cameras) < 2
                                         or not all(1 <= k <= 8 for k in args.cameras)):
            raise UserError(f'--cameras takes 2 or more distinct camera numbers 1..8 (got {args.cameras})')
        cases = draw_cases(args, parse_resolution(args.resolution))
        if args.only:
            if not all(0 <= index < len(cases) for index in args.only):
                raise UserError(f'--only takes case numbers 0..{len(cases) - 1} of the --cases {len(cases)} drawn')
            cases = [cases[index] for index in args.only]
        print(f'[suite] {len(cases)} cases × {args.frames} frame sets, seed {args.seed}, {args.jobs} at once'
              + (f", the fitter given the true {' and '.join(args.true_lengths) or 'bone'} lengths (--true-lengths)"
                 if args.true_lengths is not None else '')
              + (f", the fitter given one frame set in every {' or '.join(map(str, sorted(set(args.gaps))))} "
                 '(--gaps)' if args.gaps else ''),
              file=sys.stderr, flush=True)
        progress = Progress(len(cases), 'suite', unit='cases')
        results = []
        import cv2
        cv2.setNumThreads(1)   # no OpenCV pool thread to fork with a mutex held (as in synth.synthesize)
        with ProcessPoolExecutor(max_workers=args.jobs, initializer=end_with_parent) as pool:
            for result in pool.map(run_case, cases, [args.true_lengths] * len(cases),
                                   [args.features_cache] * len(cases), [args.gaps] * len(cases)):
                results.append(result)
                progress.update()
        progress.close()
        rows = report(results)
        figures = write_figures(rows, args, args.output / FIGURES_FILE)
        print(f'[suite] every case\'s figures: {figures} (`eval compare` pairs them with another run\'s)', file=sys.stderr)
        pictures(max(results, key=lambda r: r.mean_error), args.output)
    return 0


@dataclass
class CaseResult:
    case: object
    statuses: list                # Skeleton.status per frame set, None where no skeleton came
    fit_seconds: list
    joints: np.ndarray            # (F, 15, 3) [m] fitted, NaN where none
    truth: np.ndarray             # (F, 15, 3) [m]
    passed_over: np.ndarray       # (F,) bool: frame sets not given to the fitter (--gaps)

    @property
    def unanswered(self):
        """Frame sets given to the fitter that got no skeleton."""
        return sum(status is None and not passed for status, passed in zip(self.statuses, self.passed_over))

    @property
    def errors(self):
        """(F, 15) [mm] per joint; NaN rows where no skeleton came."""
        from mvpose_nodes.app.reports.accuracy import joint_errors_mm
        return joint_errors_mm(self.joints, self.truth)

    @property
    def swapped(self):
        """(F,) bool: a left/right pair nearer the other side's truth."""
        from mvpose_nodes.app.reports.accuracy import swapped_pairs
        return swapped_pairs(self.joints, self.truth).any(axis=1)

    @property
    def mean_error(self):
        errors = self.errors
        return float(np.nanmean(errors)) if np.isfinite(errors).any() else math.inf

    @property
    def per_frame(self):
        """(F,) [mm] the mean joint error of each frame set, NaN where no skeleton came."""
        return self.errors.mean(axis=1)


def run_case(case, true_lengths=None, features_cache=None, gaps=None):
    """Render, extract and fit the frame sets of a case; its CaseResult. true_lengths: None to measure the
    person, [] to give the fitter the motion's bone lengths instead, or length keys (kinematics.LENGTH_FRACTIONS)
    to give it those of them, the others measured; features_cache: a folder for the case's
    feature messages (case_features), or None; gaps: None to fit every frame set, else the steps [frame
    sets] to draw from (rng seeded by case.seed) from one fitted frame set to the next, the first fitted."""
    from mvpose_nodes.body.kinematics import lengths_of
    from mvpose_nodes.fitting.settings import FitterSettings
    from mvpose_nodes.ros.conversions import joints_from_skeleton
    from mvpose_nodes.ros.frame_set_fitting import FrameSetFitter

    motion = case_motion(case)
    cameras = {c.number: c for c in case.rig if c.number in case.cameras}
    true = lengths_of(motion.joints)
    fitting = FrameSetFitter(FitterSettings(), case.cameras, lengths=true if true_lengths == [] else None,
                             known_lengths={key: true[key] for key in true_lengths or ()})
    count = len(motion.joints)
    joints = np.full((count, 15, 3), np.nan)
    statuses, seconds = [None] * count, []
    passed_over = np.zeros(count, bool) if gaps is None else passed_over_by(count, gaps, case.seed)
    skipped = 0
    for index, (stamp, messages) in enumerate(case_features(case, motion, features_cache)):
        if passed_over[index]:
            skipped += 1
            continue
        result = fitting.fit(stamp, {number: (cameras[number], *pair) for number, pair in messages.items()},
                             skipped=skipped)
        skipped = 0
        if result.message is not None:
            joints[index] = joints_from_skeleton(result.message)
            statuses[index] = result.message.status
            seconds.append(result.message.fit_time)
    return CaseResult(case, statuses, seconds, joints, motion.joints, passed_over)


def passed_over_by(count, gaps, seed):
    """(count,) bool: the frame sets a fitter that cannot keep up passes over: the first is fitted, each
    next one a step drawn from `gaps` [frame sets] (ints ≥ 1) on, by a Generator seeded `seed`."""
    fitted = np.cumsum(np.r_[0, np.random.default_rng(seed).choice(gaps, size=count - 1)])
    passed_over = np.ones(count, bool)
    passed_over[fitted[fitted < count]] = False
    return passed_over


def case_figures(result):
    """A case's row of the table: {'index', 'set', 'motion', 'rig', 'body', 'imaging' (studio.cases.describe_case),
    'mean', 'median', 'worst' [mm] of its frame sets' mean joint errors (None without a skeleton), 'swaps' (frame
    sets with a left/right swap after the first SWAP_GRACE_FRAMES), 'none' (frame sets without a skeleton),
    'fit_ms' (median fit time, None without a fit)}."""
    from mvpose_nodes.studio.cases import describe_case
    per_frame = result.per_frame
    finite = per_frame[np.isfinite(per_frame)]
    return {'index': result.case.index, 'set': motion_set(result.case.motion), **describe_case(result.case),
            **({'mean': float(np.mean(finite)), 'median': float(np.median(finite)), 'worst': float(np.max(finite))}
               if len(finite) else {'mean': None, 'median': None, 'worst': None}),
            'swaps': int(result.swapped[SWAP_GRACE_FRAMES:].sum()), 'none': int(result.unanswered),
            'fit_ms': 1000 * float(np.median(result.fit_seconds)) if result.fit_seconds else None}


def report(results):
    """The per-case table and the per-set summary on stdout; returns the table's rows (case_figures)."""
    from mvpose_nodes.app.reports.accuracy import PAPER_MEAN_MM
    from mvpose_nodes.body.model import JOINT_NAMES
    print(f'eval suite: {len(results)} cases   errors in mm (the mean joint error of a frame set, Eq. 12)')
    print(f'  {"#":>2} {"set":<8} {"motion":<24} {"rig":<30} {"body":<40} {"mean":>6} {"median":>6} '
          f'{"worst":>6} {"swaps":>5} {"none":>4} {"fit ms":>6}')
    rows = [case_figures(result) for result in results]
    for row in rows:
        cells = (f'{row["mean"]:6.1f} {row["median"]:6.1f} {row["worst"]:6.1f}' if row['mean'] is not None
                 else f'{"–":>6} {"–":>6} {"–":>6}')
        fit_ms = math.nan if row['fit_ms'] is None else row['fit_ms']
        print(f'  {row["index"]:>2} {row["set"]:<8} {row["motion"][:24]:<24} {row["rig"][:30]:<30} '
              f'{row["body"][:40]:<40} {cells} {row["swaps"]:>5} {row["none"]:>4} {fit_ms:>6.0f}')
    for name in MOTION_SETS:
        chosen = [(r, row) for r, row in zip(results, rows) if row['set'] == name]
        if not chosen:
            continue
        means = np.array([r.mean_error for r, _ in chosen])
        worst = chosen[int(np.argmax(means))][0]
        print(f'  {name}: {len(chosen)} cases: mean {np.mean(means):.1f}, median {np.median(means):.1f}, '
              f'90th percentile {np.percentile(means, 90):.1f}, worst {np.max(means):.1f} (case {worst.case.index}, '
              f'{worst.case.motion}); cases over {PAPER_MEAN_MM} mm: {int(np.sum(means > PAPER_MEAN_MM))}; '
              f'swapped frames after the first {SWAP_GRACE_FRAMES}: '
              f'{sum(row["swaps"] for _, row in chosen)}; frame sets without a skeleton: '
              f'{sum(row["none"] for _, row in chosen)}')
    joint_means = np.nanmean(np.concatenate([r.errors for r in results]), axis=0)
    print('  per joint (all cases): ' + ', '.join(f'{n} {m:.0f}' for n, m in zip(JOINT_NAMES, joint_means)))
    return rows


def write_figures(rows, args, path):
    """The table's rows (case_figures) as JSON in `path`, with the draw's seed and the run's settings, for
    `eval compare`. Returns the path."""
    run = {'seed': args.seed, 'motions': args.motions, 'frames': args.frames, 'resolution': args.resolution,
           'cameras': args.cameras, 'gaps': args.gaps, 'true_lengths': args.true_lengths}
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({'run': run, 'cases': rows}, indent=1) + '\n')
    return path


def pictures(worst, output):
    """The worst case's per-frame error plot and its worst frame's overlay over the cameras it used."""
    from mvpose_nodes.app.reports.plots import error_plot
    from mvpose_nodes.app.reports.sheets import contact_sheet
    from mvpose_nodes.studio import scene
    case = worst.case
    per_frame = worst.per_frame
    plot = error_plot(per_frame, None, Path(output) / f'worst_case_{case.index}_error_per_frame.png',
                      per_joint=worst.errors, title=f'Worst case {case.index} ({case.motion}): mean joint error per frame')
    index = int(np.nanargmax(per_frame)) if np.isfinite(per_frame).any() else 0
    motion = case_motion(case)
    cameras = {c.number: c for c in case.rig if c.number in case.cameras}
    images = {k: render_camera(case, scene.prepare_camera(cameras[k], texture_seed=k), motion, index)[0]
              for k in case.cameras}
    fitted = worst.joints[index] if np.isfinite(worst.joints[index]).all() else None
    sheet = contact_sheet(images, cameras, fitted, worst.truth[index],
                          Path(output) / f'worst_case_{case.index}_frame_{index}.png', columns=min(4, len(images)),
                          title=f'case {case.index} ({case.motion}) frame {index}: fit (colour), truth (white)')
    print(f'[suite] worst case {case.index}: {plot}, {sheet}', file=sys.stderr)

