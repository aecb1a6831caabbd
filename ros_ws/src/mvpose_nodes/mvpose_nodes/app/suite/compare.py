"""`eval compare`: two runs of `eval suite` (before and after a change) case by case.

A change to the fitter's evidence or costs moves most cases by a few mm and a few by hundreds, either
way, when it changes which labelling of the body (turned round, legs or arms exchanged) the fit settles
on (docs/method.md, session 30). So two means side by side say little: this pairs the cases of the same
draws (by the draw's seed and the case's number, checked by its motion, rig, body and imaging), and
prints per motion set the mean of the paired differences with its bootstrap interval
(app/reports/accuracy.paired_difference), how many cases moved by more than --moved mm either way, the
cases within the paper's 44.4 mm and the left/right swaps before and after, and the cases that moved
most.

Each side is one or more `eval suite` output folders (or their cases.json, suite.FIGURES_FILE), e.g. the
same seeds run before and after: `eval compare --before out/a1 out/a2 --after out/b1 out/b2`.
"""
import json
import sys
from pathlib import Path

import numpy as np

from mvpose_nodes.tools.cli import ArgumentParser, UserError, exit_on_user_error

DESCRIPTION_KEYS = ('motion', 'rig', 'body', 'imaging')   # a case's identity beside its draw's seed and number
CONFIDENCE = 0.9


def build_parser(prog):
    parser = ArgumentParser(prog=prog, description=__doc__.split('\n\n')[0])
    parser.add_argument('--before', type=Path, nargs='+', required=True, metavar='RUN',
                        help="`eval suite` output folders (or their cases.json) of the code before the change")
    parser.add_argument('--after', type=Path, nargs='+', required=True, metavar='RUN',
                        help='the same draws run with the code after it')
    parser.add_argument('--moved', type=float, default=10.0, metavar='MM',
                        help='a case whose mean error changed by more than this counts as moved (default 10 mm)')
    parser.add_argument('--show', type=int, default=5, metavar='N', help='list the N cases that moved most (default 5)')
    return parser


def load_runs(paths):
    """{(draw seed, case number): case figures (suite.case_figures)} of `eval suite` runs (folders or their
    cases.json). UserError (one line, naming the file) for a missing or unreadable file, or one case twice."""
    from mvpose_nodes.app.suite import FIGURES_FILE
    cases = {}
    for path in paths:
        file = path / FIGURES_FILE if path.is_dir() else path
        try:
            run = json.loads(file.read_text())
            seed = run['run']['seed']
            rows = [(seed, row['index'], row) for row in run['cases']]
        except FileNotFoundError:
            raise UserError(f"'{file}': no such file (an `eval suite` output folder holds {FIGURES_FILE})") from None
        except (OSError, ValueError, KeyError, TypeError) as error:
            raise UserError(f"'{file}': not an `eval suite` {FIGURES_FILE} ({type(error).__name__}: {error})") from None
        for seed, index, row in rows:
            if (seed, index) in cases:
                raise UserError(f"'{file}': case {index} of seed {seed} is already in an earlier run on this side")
            cases[(seed, index)] = row
    return cases


def paired_cases(before, after):
    """The (key, before row, after row) of the cases both sides ran, in key order, and the keys only one side
    has. UserError when a case of the same seed and number is another case (another draw: --motions,
    --frames, --cameras or --resolution differ)."""
    common = sorted(set(before) & set(after))
    for key in common:
        differing = [k for k in DESCRIPTION_KEYS if before[key].get(k) != after[key].get(k)]
        if differing:
            raise UserError(f'case {key[1]} of seed {key[0]} is not the same case before and after ({differing[0]}: '
                            f"'{before[key].get(differing[0])}' against '{after[key].get(differing[0])}'): "
                            'compare runs of the same draw')
    return [(key, before[key], after[key]) for key in common], sorted(set(before) ^ set(after))


def summary_line(name, pairs, moved):
    """One motion set's comparison, or None when none of its cases has a skeleton on both sides."""
    from mvpose_nodes.app.reports.accuracy import PAPER_MEAN_MM, paired_difference
    answered = [(b, a) for _, b, a in pairs if b['mean'] is not None and a['mean'] is not None]
    if not answered:
        return None
    before = np.array([b['mean'] for b, _ in answered])
    after = np.array([a['mean'] for _, a in answered])
    mean, low, high = paired_difference(before, after, CONFIDENCE)
    swaps_before, swaps_after = sum(b['swaps'] for _, b, _ in pairs), sum(a['swaps'] for _, _, a in pairs)
    interval = f'{mean:+.1f} [{low:+.1f}, {high:+.1f}]'
    return (f'  {name:<9}{len(answered):>6}{before.mean():>10.1f} / {np.median(before):<9.1f}'
            f'{after.mean():>10.1f} / {np.median(after):<9.1f}{interval:<24}'
            f'{int(np.sum(after < before - moved)):>5} / {int(np.sum(after > before + moved)):<6}'
            f'{int(np.sum(before <= PAPER_MEAN_MM)):>5} -> {int(np.sum(after <= PAPER_MEAN_MM)):<5}'
            f'{swaps_before:>6} -> {swaps_after}')


def main(argv=None, prog='eval compare'):
    args = build_parser(prog).parse_args(sys.argv[1:] if argv is None else argv)
    with exit_on_user_error(prog):
        from mvpose_nodes.app.suite import MOTION_SETS, SWAP_GRACE_FRAMES
        from mvpose_nodes.app.reports.accuracy import PAPER_MEAN_MM
        if args.moved < 0 or args.show < 0:
            raise UserError('--moved and --show take 0 or more')
        pairs, unpaired = paired_cases(load_runs(args.before), load_runs(args.after))
        if not pairs:
            raise UserError('the two sides have no case in common (the same --seed and case numbers are needed)')
        print(f'eval compare: {len(pairs)} case{"s" * (len(pairs) != 1)} run before and after'
              + (f' ({len(unpaired)} run on one side only, left out)' if unpaired else '')
              + f'; errors in mm, each case its mean over its frame sets')
        print(f'  {"set":<9}{"cases":>6}{"before mean / median":^22}{"after mean / median":^22}'
              f'{"after − before [" + format(CONFIDENCE, ".0%") + "]":<24}{"better / worse":^14}'
              f'{"≤ " + format(PAPER_MEAN_MM, "g") + " mm":^14}{"swaps":^14}')
        for name in MOTION_SETS + ('all',):
            chosen = [p for p in pairs if name == 'all' or p[1]['set'] == name]
            line = summary_line(name, chosen, args.moved)
            if line and (name != 'all' or len({p[1]['set'] for p in pairs}) > 1):
                print(line)
        changes = sorted(((a['mean'] - b['mean'], key, b, a) for key, b, a in pairs
                          if b['mean'] is not None and a['mean'] is not None and a['mean'] != b['mean']),
                         key=lambda c: -abs(c[0]))
        if args.show and changes:
            print(f'  moved most (better / worse: by more than {args.moved:g} mm; swaps: after the first '
                  f'{SWAP_GRACE_FRAMES} frame sets):')
            for change, (seed, index), b, a in changes[:args.show]:
                print(f'    seed {seed} case {index:>2} {b["motion"][:34]:<34} {b["mean"]:6.1f} -> {a["mean"]:6.1f} '
                      f'({change:+.1f})  swaps {b["swaps"]} -> {a["swaps"]}')
    return 0
