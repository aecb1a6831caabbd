"""Drawing primitives of every picture the project makes (NumPy and OpenCV only, no matplotlib, no rclpy).

`draw_skeleton` is the one skeleton drawing function of the project (contact sheets, animations and
`preview` use it). Conventions: joints are (15, 3) float [m] in the world (z up, floor z = 0) in the
order of body.model.JOINT_NAMES, NaN where a joint (or a whole frame) has no fit; images are RGB uint8
(H, W, 3); pixels [px] as in body/camera.py. Files are written as BGR by cv2.imwrite, so they look
right in any viewer.
"""
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from mvpose_nodes.body.model import BONES, JOINT_INDEX


# RGB. Fitted skeleton: left side green, right side orange, centre (torso, head) yellow; truth white.
COLOURS = {'left': (60, 220, 60), 'right': (255, 140, 30), 'centre': (250, 230, 40), 'truth': (255, 255, 255)}
JOINT_DOT = (40, 40, 40)              # RGB of the fitted skeleton's joint dots
FLOOR_GRID = (110, 110, 118)          # RGB floor grid lines
FLOOR_EXTENT = 3.0                    # [m] the studio floor grid spans ±FLOOR_EXTENT around the origin
FLOOR_STEP = 0.5                      # [m] between grid lines
FONT = cv2.FONT_HERSHEY_SIMPLEX


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
        a, b = JOINT_INDEX[parent], JOINT_INDEX[child]
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
