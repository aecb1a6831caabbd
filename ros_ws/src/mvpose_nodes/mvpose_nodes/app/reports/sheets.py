"""Contact sheets: paper 000's Fig. 10 (every camera with the fitted and the ground-truth skeletons
projected on) and marker mode's sheet (every camera's tracked markers beside their true positions).
Conventions as in drawing.py.
"""
import math

import cv2
import numpy as np

from mvpose_nodes.app.reports.drawing import (COLOURS, FONT, draw_floor_grid, draw_skeleton, put_text,
                                              scaled_camera, write_png)
from mvpose_nodes.body.model import JOINT_NAMES


NO_IMAGE_GREY = (58, 58, 62)          # RGB background of a camera without a recorded image


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
