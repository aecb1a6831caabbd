"""The skeleton animation: an MP4 of the fitted skeleton over one camera's images, or in 3D seen from a
virtual camera circling the person; a PNG strip where this OpenCV cannot write MP4.
Conventions as in drawing.py.
"""
import math
from pathlib import Path

import cv2
import numpy as np

from mvpose_nodes.app.reports.drawing import (FLOOR_STEP, FONT, draw_floor_grid, draw_skeleton, put_text,
                                              scaled_camera, write_png)
from mvpose_nodes.app.reports.sheets import NO_IMAGE_GREY, draw_legend
from mvpose_nodes.body.model import JOINT_NAMES
from mvpose_nodes.body.camera import intrinsics, look_at
from mvpose_nodes.studio.i3dpost import FRAME_RATE


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


def animation(frames_of_joints, path, camera=None, images=None, fps=FRAME_RATE, truth=None, frame_numbers=None,
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
