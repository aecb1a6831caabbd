"""The evaluation pictures of the demo, drawn with NumPy and OpenCV only (no matplotlib, no rclpy):

- `error_plot`: paper 000's Fig. 12, the mean joint error (Eq. 12) [mm] per frame, against the
  paper's mean (44.4 mm) and our target (25 mm);
- `contact_sheet`: paper 000's Fig. 10, every camera with the fitted and the ground-truth
  skeletons projected on;
- `animation`: an MP4 of the fitted skeleton over one camera's images, or in 3D seen from a
  virtual camera circling the person;
- `marker_sheet`: marker mode, every camera's tracked markers beside their true positions.

`draw_skeleton` is the one skeleton drawing function of the project (`preview` uses it too).

Conventions: joints are (15, 3) float [m] in the world (z up, floor z = 0) in the order of
body_model.JOINT_NAMES, NaN where a joint (or a whole frame) has no fit; images are RGB uint8
(H, W, 3); pixels [px] as in camera.py. The files are written as BGR by cv2.imwrite /
cv2.VideoWriter, so they look right in any viewer.
"""
import math
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from mvpose_nodes.body.model import BONES, JOINT_NAMES
from mvpose_nodes.body.camera import intrinsics, look_at

INDEX = {name: i for i, name in enumerate(JOINT_NAMES)}
# RGB. Fitted skeleton: left side green, right side orange, centre (torso, head) yellow; truth white.
COLOURS = {'left': (60, 220, 60), 'right': (255, 140, 30), 'centre': (250, 230, 40), 'truth': (255, 255, 255)}
JOINT_DOT = (40, 40, 40)              # RGB of the fitted skeleton's joint dots
NO_IMAGE_GREY = (58, 58, 62)          # RGB background of a camera without a recorded image
FLOOR_GRID = (110, 110, 118)          # RGB floor grid lines
FLOOR_EXTENT = 3.0                    # [m] the studio floor grid spans ±FLOOR_EXTENT around the origin
FLOOR_STEP = 0.5                      # [m] between grid lines
LIMB_GROUPS = {                       # per-limb curves of the error plot
    'arms': ('left_shoulder', 'left_elbow', 'left_wrist', 'right_shoulder', 'right_elbow', 'right_wrist'),
    'legs': ('left_hip', 'left_knee', 'left_ankle', 'right_hip', 'right_knee', 'right_ankle'),
    'torso, head': ('pelvis', 'neck', 'head'),
}
FONT = cv2.FONT_HERSHEY_SIMPLEX
SHIFT = 4                             # sub-pixel bits of the plot's anti-aliased lines


# ---------------------------------------------------------------- drawing primitives

def bone_side(child):
    """'left', 'right' or 'centre': the colour key of the bone ending at joint `child`."""
    return next((side for side in ('left', 'right') if child.startswith(side)), 'centre')


def draw_skeleton(image, camera, joints, truth, thickness=None):
    """Draw the 14 bones and 15 joints of `joints` (15, 3) [m] projected by `camera` onto `image`
    (RGB uint8, drawn in place, the camera's pixel grid). truth: white bones and dots, else bones
    coloured by side with dark joint dots. thickness [px] of the bones (default: image width / 400,
    at least 2); joint dots have radius thickness + 2. Joints behind the camera or NaN are skipped."""
    joints = np.asarray(joints, dtype=float)
    pixels, depth = camera.project(joints)
    drawable = np.isfinite(pixels).all(axis=1) & (depth > 0) & (np.abs(pixels) < 1e6).all(axis=1)
    if thickness is None:
        thickness = max(2, image.shape[1] // 400)
    for parent, child in BONES:
        a, b = INDEX[parent], INDEX[child]
        if not (drawable[a] and drawable[b]):
            continue
        colour = COLOURS['truth' if truth else bone_side(child)]
        cv2.line(image, tuple(np.round(pixels[a]).astype(int)), tuple(np.round(pixels[b]).astype(int)),
                 colour, thickness, cv2.LINE_AA)
    for pixel, ok in zip(pixels, drawable):
        if ok:
            cv2.circle(image, tuple(np.round(pixel).astype(int)), thickness + 2,
                       COLOURS['truth'] if truth else JOINT_DOT, -1, cv2.LINE_AA)


def scaled_camera(camera, scale):
    """`camera` seeing the same view on an image resized by `scale` (pixel centres stay pixel centres)."""
    K = np.array(camera.K, dtype=float)
    K[:2, :2] *= scale
    K[:2, 2] = (K[:2, 2] + 0.5) * scale - 0.5
    return replace(camera, K=K, width=max(1, round(camera.width * scale)), height=max(1, round(camera.height * scale)))


def draw_floor_grid(image, camera, centre=(0.0, 0.0), extent=FLOOR_EXTENT, step=FLOOR_STEP, colour=FLOOR_GRID):
    """Lines of the floor z = 0 every `step` [m] within ±`extent` [m] of `centre` (x, y) [m], projected
    by `camera` onto `image` (in place); the lines through `centre` are drawn brighter."""
    height, width = image.shape[:2]
    count = int(round(extent / step))
    offsets = np.arange(-count, count + 1) * step
    along = np.linspace(-count * step, count * step, 8 * count + 1)
    bright = tuple(min(255, c + 50) for c in colour)
    for axis in (0, 1):
        for offset in offsets:
            points = np.zeros((len(along), 3))
            points[:, axis] = centre[axis] + offset
            points[:, 1 - axis] = centre[1 - axis] + along
            pixels, depth = camera.project(points)
            for i in range(len(along) - 1):
                if depth[i] < 0.2 or depth[i + 1] < 0.2:
                    continue
                a, b = np.clip(np.round(pixels[i:i + 2]), -1e5, 1e5).astype(int)
                visible, a, b = cv2.clipLine((0, 0, width, height), tuple(a), tuple(b))
                if visible:
                    cv2.line(image, a, b, bright if abs(offset) < 1e-9 else colour, 1, cv2.LINE_AA)


def put_text(image, text, origin, scale=0.6, colour=(255, 255, 255), thickness=1, box=True):
    """Text at `origin` (x, y of its baseline start) [px]; box: on a darkened box so it reads on any image."""
    x, y = (int(round(v)) for v in origin)
    if box:
        (w, h), base = cv2.getTextSize(text, FONT, scale, thickness)
        x0, y0 = max(0, x - 4), max(0, y - h - 4)
        x1, y1 = min(image.shape[1], x + w + 4), min(image.shape[0], y + base + 3)
        if x1 > x0 and y1 > y0:
            image[y0:y1, x0:x1] = (image[y0:y1, x0:x1] * 0.45).astype(np.uint8)
    cv2.putText(image, text, (x, y), FONT, scale, colour, thickness, cv2.LINE_AA)


def write_png(path, rgb):
    """Write an RGB uint8 image as PNG (folders made as needed); the path written."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)):
        raise OSError(f'could not write {path}')
    return path


# ---------------------------------------------------------------- paper 000 Fig. 12: error per frame

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


def error_plot(per_frame_errors_mm, frame_numbers, path, paper_mean=44.4, target=25.0, per_joint=None,
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
            values = per_joint[:, [INDEX[n] for n in names]]
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


# ---------------------------------------------------------------- paper 000 Fig. 10: the cameras

def camera_dict(cameras):
    """{number: Camera} from a dict or an iterable of Cameras (e.g. camera.studio_rig())."""
    return dict(cameras) if isinstance(cameras, dict) else {camera.number: camera for camera in cameras}


def skeleton_tile(camera, tile_width, image=None, fitted=None, truth=None, fitted_thickness=None):
    """One camera's picture resized to `tile_width` [px] wide (RGB uint8, height by the camera's
    aspect ratio) with the truth (white, thinner) and the fitted skeleton (on top) drawn at tile
    resolution; without an image a grey tile with the studio floor grid. Also the scaled camera."""
    scale = tile_width / camera.width
    tile_camera = scaled_camera(camera, scale)
    size = (tile_camera.width, tile_camera.height)
    if image is None:
        tile = np.empty((size[1], size[0], 3), np.uint8)
        tile[:] = NO_IMAGE_GREY
        draw_floor_grid(tile, tile_camera)
    else:
        image = np.asarray(image, dtype=np.uint8)
        if image.ndim == 2:
            image = cv2.cvtColor(image, cv2.COLOR_GRAY2RGB)
        tile = cv2.resize(image, size, interpolation=cv2.INTER_AREA if image.shape[1] > size[0] else cv2.INTER_LINEAR)
    thickness = fitted_thickness or max(2, round(tile_width / 160))
    if truth is not None:
        draw_skeleton(tile, tile_camera, truth, truth=True, thickness=max(1, thickness - 1))
    if fitted is not None:
        draw_skeleton(tile, tile_camera, fitted, truth=False, thickness=thickness)
    return tile, tile_camera


def draw_legend(tile, fitted, truth):
    """'fitted' (its three colours) and 'truth' (white) on a dark box at the bottom left of a tile."""
    items = [(label, colours) for label, colours, shown in
             (('fitted', [COLOURS['left'], COLOURS['centre'], COLOURS['right']], fitted),
              ('truth', [COLOURS['truth']], truth)) if shown]
    if not items:
        return
    row = tile.shape[0] - 12
    total = sum(12 * len(colours) + 20 + cv2.getTextSize(label, FONT, 0.5, 1)[0][0] for label, colours in items)
    y0, x1 = max(0, row - 18), min(tile.shape[1], 8 + total)
    tile[y0:row + 7, 4:x1] = (tile[y0:row + 7, 4:x1] * 0.45).astype(np.uint8)
    x = 10
    for label, colours in items:
        for colour in colours:
            cv2.line(tile, (x, row - 5), (x + 10, row - 5), colour, 3)
            x += 12
        cv2.putText(tile, label, (x + 4, row), FONT, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
        x += 20 + cv2.getTextSize(label, FONT, 0.5, 1)[0][0]


def tile_sheet(tiles, columns, tile_width, title=None, title_scale=0.8, footer=0):
    """The tiles (RGB, tile_width wide, any height) in rows of `columns`, each row as tall as the tallest
    tile, under a 40 px title band when `title`, over `footer` px left black; black where no tile."""
    columns = max(1, min(columns, len(tiles)))
    rows = math.ceil(len(tiles) / columns)
    tile_height = max(t.shape[0] for t in tiles)
    band = 40 if title else 0
    sheet = np.zeros((band + rows * tile_height + footer, columns * tile_width, 3), np.uint8)
    if title:
        put_text(sheet, title, (12, 28), title_scale, thickness=2)
    for i, tile in enumerate(tiles):
        r, c = divmod(i, columns)
        top = band + r * tile_height
        sheet[top:top + tile.shape[0], c * tile_width:(c + 1) * tile_width] = tile
    return sheet


def contact_sheet(images, cameras, fitted_joints, truth_joints, path, columns=4, tile_width=480,
                  used_cameras=None, title=None):
    """Paper 000's Fig. 10 as a PNG: one tile per camera, the skeletons projected with that camera.

    images: {camera number: RGB uint8 (H, W, 3)} (None or a missing number: a dark grey tile with the
    studio floor grid, so the skeletons still show). cameras: {number: Camera} or an iterable of
    Cameras; tiles in camera-number order, `columns` per row. fitted_joints, truth_joints: (15, 3)
    [m] or None; fitted coloured (left green, right orange, torso/head yellow, dark joint dots),
    truth white and thinner beneath it. used_cameras: optional set of numbers used by the fit: those
    tiles get a yellow frame and 'used for fit'. The sheet is columns × rows tiles of tile_width [px]
    by the tallest tile's height (camera aspect ratio), plus a 40 px band on top if `title`; black
    where no tile. Returns the Path written (folders made as needed)."""
    cameras = camera_dict(cameras)
    if not cameras:
        raise ValueError('contact_sheet needs at least one camera')
    images = images or {}
    used_cameras = None if used_cameras is None else {int(k) for k in used_cameras}
    tiles = []
    for number, camera in sorted(cameras.items()):
        image = images.get(number)
        tile, _ = skeleton_tile(camera, tile_width, image, fitted_joints, truth_joints)
        label = f'cam {number}' + ('' if image is not None else '  (no image)')
        scale = min(0.8, max(0.45, tile_width / 700))
        put_text(tile, label, (10, round(40 * scale)), scale, thickness=2)
        if used_cameras is not None and number in used_cameras:
            cv2.rectangle(tile, (1, 1), (tile.shape[1] - 2, tile.shape[0] - 2), COLOURS['centre'], 3)
            text = 'used for fit'
            put_text(tile, text, (tile.shape[1] - 12 - cv2.getTextSize(text, FONT, 0.8 * scale, 1)[0][0],
                                  round(40 * scale)), 0.8 * scale,
                     colour=COLOURS['centre'])
        draw_legend(tile, fitted_joints is not None, truth_joints is not None)
        tiles.append(tile)
    return write_png(path, tile_sheet(tiles, columns, tile_width, title))


# ---------------------------------------------------------------- marker mode

MARKER_FLAG_COLOURS = ((60, 220, 60), (250, 210, 40), (230, 40, 40))   # RGB of FLAG_DETECTED, _PREDICTED, _LOST
MARKER_SHORT_NAMES = {'pelvis': 'P', 'neck': 'N', 'head': 'H'}


def marker_label(name):
    """'left_wrist' -> 'LW'; pelvis, neck, head -> 'P', 'N', 'H'."""
    return MARKER_SHORT_NAMES.get(name) or ''.join(part[0].upper() for part in name.split('_'))


def marker_sheet(images, tracks, truth, path, columns=3, tile_width=560, title=None):
    """Marker mode's tracks over the images, one tile per camera, cropped to the person.

    images: {camera number: RGB uint8 (H, W, 3)}; tracks: {number: (positions (15, 2) [px], flags (15,)
    FLAG_*)}; truth: {number: (positions (15, 2) [px], visible (15,) bool)}. Each estimate is a dot
    coloured by its flag (detected green, predicted yellow, lost red) with its short name (LW = left
    wrist); the true position is a white ring (thin where the marker is hidden), joined to the estimate
    by a red line when they are more than 3 px apart. Returns the Path written."""
    tiles = []
    for number in sorted(images):
        image = images[number]
        positions, flags = (np.asarray(a) for a in tracks[number])
        true_positions, visible = (np.asarray(a) for a in truth[number])
        points = np.vstack([true_positions, positions[np.isfinite(positions).all(axis=1)]])
        low, high = points.min(axis=0), points.max(axis=0)
        pad = 0.15 * max(high - low) + 20
        x0, y0 = np.maximum(np.floor(low - pad), 0).astype(int)
        x1, y1 = np.minimum(np.ceil(high + pad), (image.shape[1] - 1, image.shape[0] - 1)).astype(int)
        scale = tile_width / max(x1 - x0, 1)
        tile = cv2.resize(image[y0:y1, x0:x1], (tile_width, max(1, round((y1 - y0) * scale))), interpolation=cv2.INTER_AREA)

        def at(p):
            return (int(round((p[0] - x0) * scale)), int(round((p[1] - y0) * scale)))
        for i, name in enumerate(JOINT_NAMES):
            cv2.circle(tile, at(true_positions[i]), 9, COLOURS['truth'], 2 if visible[i] else 1, cv2.LINE_AA)
            if not np.isfinite(positions[i]).all():
                continue
            if np.linalg.norm(positions[i] - true_positions[i]) > 3.0:
                cv2.line(tile, at(positions[i]), at(true_positions[i]), (230, 40, 40), 2, cv2.LINE_AA)
            colour = MARKER_FLAG_COLOURS[min(int(flags[i]), 2)]
            cv2.circle(tile, at(positions[i]), 5, colour, -1, cv2.LINE_AA)
            x, y = at(positions[i])
            put_text(tile, marker_label(name), (x + 8, y - 6), 0.45, colour=colour)
        put_text(tile, f'cam {number}', (10, 26), 0.7, thickness=2)
        tiles.append(tile)
    if not tiles:
        raise ValueError('marker_sheet needs at least one camera image')
    sheet = tile_sheet(tiles, columns, tile_width, title, title_scale=0.7, footer=34)
    y, x = sheet.shape[0] - 12, 12
    for label, colour in zip(('detected', 'predicted (hidden)', 'lost'), MARKER_FLAG_COLOURS):
        cv2.circle(sheet, (x + 6, y - 5), 5, colour, -1, cv2.LINE_AA)
        put_text(sheet, label, (x + 16, y), 0.5, box=False)
        x += 30 + cv2.getTextSize(label, FONT, 0.5, 1)[0][0]
    cv2.circle(sheet, (x + 8, y - 5), 8, COLOURS['truth'], 2, cv2.LINE_AA)
    put_text(sheet, 'true position (thin: hidden); red line: off by more than 3 px', (x + 22, y), 0.5, box=False)
    return write_png(path, sheet)


# ---------------------------------------------------------------- animation

def orbit_cameras(joint_sets, count, width, height, fps, degrees_per_second, start_azimuth_deg):
    """`count` virtual cameras (number 0) circling the people's mean floor position at 1.7 m height,
    turning `degrees_per_second`, zoomed so that every joint of `joint_sets` stays in view."""
    points = np.concatenate([np.asarray(j, dtype=float).reshape(-1, 3) for j in joint_sets])
    points = points[np.isfinite(points).all(axis=1)]
    centre = points[:, :2].mean(axis=0) if len(points) else np.zeros(2)
    reach = float(np.max(np.linalg.norm(points[:, :2] - centre, axis=1))) if len(points) else 1.0
    distance = max(4.0, 2.0 * reach + 2.5)
    target = np.array([centre[0], centre[1], 0.9])
    focal = min(0.45 * width * distance / (reach + 0.6), 0.45 * height * distance / 1.3)
    K = intrinsics(focal, width, height)
    cameras = []
    for i in range(count):
        azimuth = math.radians(start_azimuth_deg + degrees_per_second * i / fps)
        position = target + [distance * math.cos(azimuth), distance * math.sin(azimuth), 1.7 - 0.9]
        cameras.append(look_at(0, position, target, K, width, height))
    return cameras, centre


def write_strip(path, frames, limit=8, thumb_width=320):
    """A PNG of up to `limit` evenly spaced frames side by side (the fallback when MP4 fails)."""
    picks = np.unique(np.linspace(0, len(frames) - 1, min(limit, len(frames))).round().astype(int))
    thumbs = [cv2.resize(frames[i], (thumb_width, round(thumb_width * frames[i].shape[0] / frames[i].shape[1])),
                         interpolation=cv2.INTER_AREA) for i in picks]
    return write_png(path, np.concatenate(thumbs, axis=1))


def animation(frames_of_joints, path, camera=None, images=None, fps=25, truth=None, frame_numbers=None,
              width=640, degrees_per_second=12.0, start_azimuth_deg=-60.0):
    """An MP4 (fourcc 'mp4v', `fps` frames per second) of the fitted skeleton, one video frame per pose.

    frames_of_joints: (F, 15, 3) float [m], NaN for frames without a fit ('no fit' is written).
    truth: optional (F, 15, 3) [m], drawn white and thinner in the same view. camera: a Camera to
    see through; images: then optionally F RGB uint8 images of that camera (a list, None entries or
    None for all: grey with the floor grid). Without a camera: a 3D view from a virtual camera
    circling the person slowly (`degrees_per_second`) over a 0.5 m floor grid. frame_numbers: (F,)
    ints for the labels (default 0..F−1). Frames are `width` [px] wide (rounded to even sizes),
    16:9 in 3D, the camera's aspect ratio otherwise. The file is `path` with suffix .mp4; if this
    OpenCV cannot write MP4, a PNG strip of up to 8 frames (suffix .png) instead. Returns the Path
    actually written (folders made as needed)."""
    poses = np.asarray(frames_of_joints, dtype=float).reshape(-1, len(JOINT_NAMES), 3)
    count = len(poses)
    if count == 0:
        raise ValueError('animation needs at least one frame')
    truths = None if truth is None else np.asarray(truth, dtype=float).reshape(count, len(JOINT_NAMES), 3)
    numbers = list(range(count)) if frame_numbers is None else [int(n) for n in frame_numbers]
    width = int(width) // 2 * 2
    if camera is not None:
        height = round(width * camera.height / camera.width) // 2 * 2
        views = [scaled_camera(camera, width / camera.width)] * count
        floor_centre = (0.0, 0.0)
    else:
        height = round(width * 9 / 16) // 2 * 2
        views, floor_centre = orbit_cameras([poses] + ([truths] if truths is not None else []), count, width, height,
                                            fps, degrees_per_second, start_azimuth_deg)
        floor_centre = tuple(np.round(floor_centre / FLOOR_STEP) * FLOOR_STEP)
    thickness = max(2, round(width / 210))
    frames = []
    for i in range(count):
        view = views[i]
        image = None if images is None else images[i]
        if image is None:
            canvas = np.empty((height, width, 3), np.uint8)
            canvas[:] = NO_IMAGE_GREY if camera is not None else (34, 36, 42)
            draw_floor_grid(canvas, view, floor_centre)
        else:
            canvas = cv2.resize(np.asarray(image, dtype=np.uint8), (width, height), interpolation=cv2.INTER_AREA)
        # the view's pixel grid is width × height up to rounding of the aspect ratio: fine for drawing
        if truths is not None and np.isfinite(truths[i]).any():
            draw_skeleton(canvas, view, truths[i], truth=True, thickness=max(1, thickness - 1))
        fitted = np.isfinite(poses[i]).any()
        if fitted:
            draw_skeleton(canvas, view, poses[i], truth=False, thickness=thickness)
        put_text(canvas, f'frame {numbers[i]}' + ('' if fitted else '   no fit'), (10, 24), 0.6, thickness=1)
        if camera is not None:
            label = f'cam {camera.number}'
            put_text(canvas, label, (width - 12 - cv2.getTextSize(label, FONT, 0.6, 1)[0][0], 24), 0.6)
        draw_legend(canvas, True, truths is not None)
        frames.append(canvas)
    path = Path(path).with_suffix('.mp4')
    path.parent.mkdir(parents=True, exist_ok=True)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*'mp4v'), float(fps), (width, height))
    try:
        if writer.isOpened():
            for frame in frames:
                writer.write(cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
    finally:
        writer.release()
    if writer_ok(path):
        return path
    path.unlink(missing_ok=True)
    return write_strip(path.with_suffix('.png'), frames)


def writer_ok(path):
    """Whether `path` is a non-empty video file OpenCV can read a frame of."""
    if not path.is_file() or path.stat().st_size == 0:
        return False
    capture = cv2.VideoCapture(str(path))
    try:
        return capture.isOpened() and capture.read()[0]
    finally:
        capture.release()
