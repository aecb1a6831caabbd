"""Paper 000's Fig. 12: the mean joint error (Eq. 12) [mm] per frame, against the paper's mean and
the target, with per-limb curves; drawn with NumPy and OpenCV only (no matplotlib).
"""
import math

import cv2
import numpy as np

from mvpose_nodes.app.reports.accuracy import PAPER_MEAN_MM, TARGET_MEAN_MM
from mvpose_nodes.app.reports.drawing import FONT, write_png
from mvpose_nodes.body.model import JOINT_INDEX, JOINT_NAMES


LIMB_GROUPS = {                       # per-limb curves of the error plot
    'arms': ('left_shoulder', 'left_elbow', 'left_wrist', 'right_shoulder', 'right_elbow', 'right_wrist'),
    'legs': ('left_hip', 'left_knee', 'left_ankle', 'right_hip', 'right_knee', 'right_ankle'),
    'torso, head': ('pelvis', 'neck', 'head'),
}
SHIFT = 4                             # sub-pixel bits of the plot's anti-aliased lines


def nice_step(span, count):
    """A round tick step (1, 2, 2.5 or 5 × 10^k) giving about `count` intervals over `span`."""
    raw = span / max(count, 1)
    magnitude = 10 ** math.floor(math.log10(raw))
    return next(m * magnitude for m in (1, 2, 2.5, 5, 10) if m * magnitude >= raw)


def tick_label(value):
    return f'{value:.0f}' if abs(value - round(value)) < 1e-9 else f'{value:g}'


def dashed_hline(image, x0, x1, y, colour, thickness=2, dash=14, gap=9):
    x = x0
    while x < x1:
        cv2.line(image, (int(x), int(y)), (int(min(x + dash, x1)), int(y)), colour, thickness, cv2.LINE_AA)
        x += dash + gap


def polyline_with_gaps(image, xs, ys, colour, thickness, markers):
    """Lines between consecutive finite points (NaN breaks the line); isolated points as dots."""
    finite = np.isfinite(ys)
    scale = 1 << SHIFT
    start = None
    for i in range(len(ys) + 1):
        if i < len(ys) and finite[i]:
            start = i if start is None else start
            continue
        if start is not None:
            run = np.column_stack([xs[start:i], ys[start:i]])
            if len(run) > 1:
                cv2.polylines(image, [np.round(run * scale).astype(np.int32)], False, colour, thickness,
                              cv2.LINE_AA, SHIFT)
            if markers or len(run) == 1:
                for x, y in run:
                    cv2.circle(image, (int(round(x * scale)), int(round(y * scale))), (thickness + 2) * scale,
                               colour, -1, cv2.LINE_AA, SHIFT)
            start = None


def error_plot(per_frame_errors_mm, frame_numbers, path, paper_mean=PAPER_MEAN_MM, target=TARGET_MEAN_MM, per_joint=None,
               title='Mean joint error per frame (paper 000 Eq. 12)', size=(1200, 600)):
    """Paper 000's Fig. 12 as a PNG of `size` (width, height) [px] (default 1200×600), white background.

    per_frame_errors_mm: (F,) float [mm], the mean of the 15 joint errors of each frame; NaN where
    a frame has no fit (a gap in the line, shaded). frame_numbers: (F,) int, or None for 0..F−1.
    paper_mean, target: [mm] drawn as dashed horizontal lines (None: left out). per_joint: optional
    (F, 15) float [mm], each joint's error; adds thin curves of the mean of the arm, leg and
    torso/head joints. Returns the Path written (folders made as needed)."""
    errors = np.asarray(per_frame_errors_mm, dtype=float).reshape(-1)
    frames = np.arange(len(errors)) if frame_numbers is None else np.asarray(frame_numbers, dtype=float).reshape(-1)
    if len(frames) != len(errors):
        raise ValueError(f'{len(errors)} errors but {len(frames)} frame numbers')
    curves = []  # (label, values (F,) [mm], RGB, thickness)
    if per_joint is not None:
        per_joint = np.asarray(per_joint, dtype=float)
        if per_joint.shape != (len(errors), len(JOINT_NAMES)):
            raise ValueError(f'per_joint has shape {per_joint.shape}, expected ({len(errors)}, {len(JOINT_NAMES)})')
        palette = [(255, 127, 14), (148, 103, 189), (140, 86, 75)]
        for (label, names), colour in zip(LIMB_GROUPS.items(), palette):
            values = per_joint[:, [JOINT_INDEX[n] for n in names]]
            known = np.isfinite(values)
            sums = np.where(known, values, 0).sum(axis=1)
            mean = np.where(known.any(axis=1), sums / np.maximum(known.sum(axis=1), 1), np.nan)
            curves.append((label, mean, colour, 1))
    finite = np.isfinite(errors)
    mean_error = float(errors[finite].mean()) if finite.any() else float('nan')
    main_label = f'mean joint error (mean {mean_error:.1f} mm' if finite.any() else 'mean joint error (no fit'
    main_label += f', {int((~finite).sum())} of {len(errors)} frames without fit)' if (~finite).any() else ')'
    curves.insert(0, (main_label, errors, (31, 119, 180), 2))

    references = [(f'paper 000 mean {paper_mean:g} mm', paper_mean, (214, 39, 40)),
                  (f'target {target:g} mm', target, (44, 160, 44))]
    references = [r for r in references if r[1] is not None]
    entries = [(label, colour, thickness, False) for label, _, colour, thickness in curves]
    entries += [(label, colour, 2, True) for label, _, colour in references]
    if (~finite).any():
        entries.append(('frame without fit', (252, 226, 226), -1, False))

    width, height = size
    image = np.full((height, width, 3), 255, np.uint8)
    left, right, top = 95, width - 30, 60
    # the legend flows in rows under the plot: (entry, x, row number)
    placed, x, row = [], left, 0
    for entry in entries:
        entry_width = 50 + 8 + cv2.getTextSize(entry[0], FONT, 0.5, 1)[0][0] + 28
        if x + entry_width > right and x > left:
            x, row = left, row + 1
        placed.append((entry, x, row))
        x += entry_width
    line_height = 22
    legend_top = height - 10 - line_height * (row + 1)
    bottom = legend_top - 68
    # axes ranges
    if len(frames):
        x_min, x_max = float(frames.min()), float(frames.max())
    else:
        x_min, x_max = 0.0, 1.0
    if x_max - x_min < 1:
        x_min, x_max = x_min - 1, x_max + 1
    spacing = float(np.median(np.diff(np.sort(frames)))) if len(frames) > 1 else 1.0
    spacing = spacing if spacing > 0 else 1.0
    x_min, x_max = x_min - spacing / 2, x_max + spacing / 2
    peaks = [v for _, c, _, _ in curves for v in c[np.isfinite(c)]] + [v for v in (paper_mean, target) if v]
    y_top = max(peaks) * 1.12 if peaks and max(peaks) > 0 else 50.0
    y_step = nice_step(y_top, 6)
    y_max = math.ceil(y_top / y_step) * y_step

    def px(x):
        return left + (np.asarray(x, dtype=float) - x_min) / (x_max - x_min) * (right - left)

    def py(y):
        return bottom - np.clip(np.asarray(y, dtype=float), 0, y_max) / y_max * (bottom - top)

    # frames without a fit, shaded
    for frame in frames[~finite]:
        cv2.rectangle(image, (int(px(frame - spacing / 2)), top), (int(px(frame + spacing / 2)), bottom),
                      (252, 226, 226), -1)
    # grid and ticks
    for y in np.arange(0, y_max + y_step / 2, y_step):
        row = int(round(py(y)))
        cv2.line(image, (left, row), (right, row), (232, 232, 232), 1)
        cv2.line(image, (left - 6, row), (left, row), (0, 0, 0), 1)
        label = tick_label(y)
        (w, h), _ = cv2.getTextSize(label, FONT, 0.5, 1)
        cv2.putText(image, label, (left - 10 - w, row + h // 2), FONT, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
    x_step = max(1.0, nice_step(x_max - x_min, 10))
    for x in np.arange(math.ceil(x_min / x_step) * x_step, x_max + 1e-9, x_step):
        column = int(round(px(x)))
        cv2.line(image, (column, top), (column, bottom), (238, 238, 238), 1)
        cv2.line(image, (column, bottom), (column, bottom + 6), (0, 0, 0), 1)
        label = tick_label(x)
        (w, h), _ = cv2.getTextSize(label, FONT, 0.5, 1)
        cv2.putText(image, label, (column - w // 2, bottom + 12 + h), FONT, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.rectangle(image, (left, top), (right, bottom), (0, 0, 0), 1)
    # reference lines
    for _, value, colour in references:
        dashed_hline(image, left + 1, right - 1, py(value), colour)
    # data (thin per-limb curves below the main line)
    xs = px(frames)
    for label, values, colour, thickness in reversed(curves):
        polyline_with_gaps(image, xs, py(values), colour, thickness, markers=thickness > 1 and len(values) <= 150)
    # labels
    (w, h), _ = cv2.getTextSize(title, FONT, 0.8, 2)
    cv2.putText(image, title, ((width - w) // 2, 20 + h), FONT, 0.8, (0, 0, 0), 2, cv2.LINE_AA)
    (w, h), _ = cv2.getTextSize('frame', FONT, 0.6, 1)
    cv2.putText(image, 'frame', ((left + right - w) // 2, legend_top - 10), FONT, 0.6, (0, 0, 0), 1, cv2.LINE_AA)
    y_label = 'mean joint error [mm]'
    (w, h), base = cv2.getTextSize(y_label, FONT, 0.6, 1)
    strip = np.full((h + base + 4, w + 4, 3), 255, np.uint8)
    cv2.putText(strip, y_label, (2, h + 2), FONT, 0.6, (0, 0, 0), 1, cv2.LINE_AA)
    strip = cv2.rotate(strip, cv2.ROTATE_90_COUNTERCLOCKWISE)
    row0 = max(0, (top + bottom - strip.shape[0]) // 2)
    image[row0:row0 + strip.shape[0], 14:14 + strip.shape[1]] = strip[:height - row0]
    # legend
    for (label, colour, thickness, dashed), x, row in placed:
        y = legend_top + line_height * row + line_height // 2
        if thickness < 0:
            cv2.rectangle(image, (x, y - 7), (x + 40, y + 7), colour, -1)
        elif dashed:
            dashed_hline(image, x, x + 40, y, colour, thickness, dash=10, gap=6)
        else:
            cv2.line(image, (x, y), (x + 40, y), colour, thickness, cv2.LINE_AA)
        cv2.putText(image, label, (x + 50, y + 5), FONT, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
    return write_png(path, image)
