"""Accuracy against the ground truth, as paper 000 reports it: per-joint errors, Eq. 12's per-frame mean,
Table 2's layout beside the paper's own numbers, and left/right limb swaps.

Joints are (F, 15, 3) or (15, 3) float [m] in body.model.JOINT_NAMES order; errors are in mm.
"""
import numpy as np

from mvpose_nodes.body.model import JOINT_INDEX, JOINT_NAMES

# Paper 000 Table 2: mean Euclidean error per joint P1..P15 [mm] on i3DPost, and its overall mean.
PAPER_JOINT_ERRORS_MM = (36.6, 25.9, 67.0, 72.3, 35.4, 86.1, 69.3, 27.0, 132.2, 30.0, 15.8, 11.1, 31.9, 13.4, 12.4)
PAPER_MEAN_MM = 44.4
TARGET_MEAN_MM = 25.0   # this project's aim for the mean joint error
SWAPPABLE_JOINTS = ('ankle', 'knee', 'wrist', 'elbow')


def joint_errors_mm(fitted, truth):
    """Euclidean error of every joint [mm]: (..., 15) from fitted and truth (..., 15, 3) [m]."""
    return np.linalg.norm(fitted - truth, axis=-1) * 1000.0


def swapped_pairs(fitted, truth):
    """(F, 4) bool: per frame and left/right pair (SWAPPABLE_JOINTS), whether the fitted pair lies nearer
    the other side's truth than its own; fitted and truth (F, 15, 3) [m] (NaN: never swapped)."""
    distance = joint_errors_mm(fitted, truth)
    swapped = []
    for side in SWAPPABLE_JOINTS:
        left, right = JOINT_INDEX[f'left_{side}'], JOINT_INDEX[f'right_{side}']
        straight = distance[:, left] + distance[:, right]
        crossed = (np.linalg.norm(fitted[:, left] - truth[:, right], axis=1)
                   + np.linalg.norm(fitted[:, right] - truth[:, left], axis=1)) * 1000.0
        swapped.append(crossed < straight)
    return np.column_stack(swapped)


def limb_swaps(fitted, truth):
    """How many (frame, left/right pair) have the pair nearer the other side's truth; (F, 15, 3) each."""
    return int(swapped_pairs(fitted, truth).sum())


def print_table_2(fitted, truth, bag):
    """Paper 000 Table 2 layout, Eq. 12 and limb swaps on stdout; fitted and truth (F, 15, 3) [m]."""
    delta = np.abs(fitted - truth) * 1000.0                       # [mm]
    distance = joint_errors_mm(fitted, truth)                     # (F, 15)
    per_frame = distance.mean(axis=1)                             # Eq. 12
    print(f'eval: {bag}  ({len(fitted)} frames matched by stamp)   errors in mm')
    print(f'  {"joint":<18} {"|ΔX| mean±std":>15} {"|ΔY| mean±std":>15} {"|ΔZ| mean±std":>15} '
          f'{"mean dist":>10} {"paper":>7}')
    for j, name in enumerate(JOINT_NAMES):
        cells = ' '.join(f'{delta[:, j, a].mean():>7.1f}±{delta[:, j, a].std():<7.1f}' for a in range(3))
        print(f'  P{j + 1:<2} {name:<14} {cells} {distance[:, j].mean():>10.1f} {PAPER_JOINT_ERRORS_MM[j]:>7.1f}')
    cells = ' '.join(f'{delta[..., a].mean():>7.1f}±{delta[..., a].std():<7.1f}' for a in range(3))
    print(f'  {"mean":<18} {cells} {distance.mean():>10.1f} {PAPER_MEAN_MM:>7.1f}')
    print(f'  Eq. 12 per frame: mean {per_frame.mean():.1f} mm, median {np.median(per_frame):.1f}, '
          f'max {per_frame.max():.1f}  (paper: {PAPER_MEAN_MM} mm Table 2 mean; aim <= {TARGET_MEAN_MM:g} mm)')
    print(f'  left/right limb swaps (a left/right joint pair nearer the other side\'s truth): '
          f'{limb_swaps(fitted, truth)}')


def paired_difference(before, after, confidence=0.9, resamples=10000, seed=0):
    """The mean of the paired differences after − before of N cases' figures (N,) and its percentile bootstrap
    interval at `confidence` (the cases resampled with replacement `resamples` times, from a Generator seeded
    `seed`, so the same figures give the same interval): (mean, low, high), in the figures' unit. A change to
    the fitter moves a few cases by hundreds of mm either way (which labelling of the body it settles on) and
    leaves the rest as they were, so a difference of means means little without how much it rests on them."""
    before, after = np.asarray(before, float), np.asarray(after, float)
    if before.shape != after.shape or before.ndim != 1 or not len(before):
        raise ValueError('paired_difference needs the same N > 0 cases before and after')
    differences = after - before
    means = np.random.default_rng(seed).choice(differences, (resamples, len(differences))).mean(axis=1)
    tail = 100 * (1 - confidence) / 2
    low, high = np.percentile(means, [tail, 100 - tail])
    return float(differences.mean()), float(low), float(high)
