"""Initial 3D joint positions from the 2D keypoints of several calibrated views (paper 000 Sec. 3.1:
"the 2D keypoints from the 3 views give initial 3D positions"), by linear triangulation.

DLT after Hartley & Zisserman, Multiple View Geometry (2nd ed.), Sec. 12.2: each view with ideal
normalised coordinates (u, v) of the point and normalised camera matrix P = [R | t] gives two rows
u·P³ − P¹ and v·P³ − P² of A X = 0 (Pⁱ: row i of P); X is the right singular vector of A's smallest
singular value. Normalised coordinates (distortion removed, K divided out) are of order 1 like the
world coordinates in metres, which conditions A better than pixels (H&Z Sec. 4.4).
"""
import itertools

import numpy as np


def dlt_point(cameras, normalized, weights):
    """The DLT point (3,) [m] from ideal normalised coordinates (C, 2) (distortion removed, K divided out:
    Camera.undistort_pixels) and row weights (C,) (all used; at least 2 views)."""
    rows = []
    for camera, (u, v), weight in zip(cameras, normalized, weights):
        P = np.column_stack([camera.R, camera.t])
        rows += [weight * (u * P[2] - P[0]), weight * (v * P[2] - P[1])]
    homogeneous = np.linalg.svd(np.array(rows))[2][-1]
    return homogeneous[:3] / homogeneous[3]


def _squared_errors(cameras, point, pixels):
    """Squared reprojection errors (C,) [px²] of world point (3,) [m] against distorted pixels (C, 2)."""
    return np.array([np.sum((camera.project(point[None])[0][0] - pixel) ** 2)
                     for camera, pixel in zip(cameras, pixels)])


def _usable(pixels, weights):
    """Views with a finite observation and a positive weight: bool (C,)."""
    return np.all(np.isfinite(pixels), axis=1) & (weights > 0)


def triangulate(cameras, pixels, weights=None):
    """One 3D point from its observations in several views.

    cameras: C Camera objects; pixels: (C, 2) [px] distorted image points (x, y), a NaN row = not seen;
    weights: optional (C,) ≥ 0 confidences (e.g. the keypoint detector's), scaling each view's DLT rows,
    0 = view not used. Returns (point (3,) float64 [m], RMS reprojection error [px] over the used views,
    with distortion), or None with fewer than 2 usable views. No cheirality check: a point behind a
    camera is returned as it is (its reprojection error shows it).
    """
    pixels = np.asarray(pixels, dtype=float).reshape(len(cameras), 2)
    weights = np.ones(len(cameras)) if weights is None else np.asarray(weights, dtype=float)
    used = np.flatnonzero(_usable(pixels, weights))
    if len(used) < 2:
        return None
    views = [cameras[index] for index in used]
    normalized = np.array([camera.undistort_pixels(pixels[index][None])[0] for camera, index in zip(views, used)])
    point = dlt_point(views, normalized, weights[used])
    return point, float(np.sqrt(_squared_errors(views, point, pixels[used]).mean()))


def best_assignment(cameras, left_pixels, right_pixels, weights=None):
    """Resolve per-view left/right swaps of a symmetric keypoint pair (a single view cannot tell them apart).

    left_pixels, right_pixels: (C, 2) [px] the pair as labelled in each view (NaN row = not seen); weights:
    optional (C, 2) confidences of the (left, right) observations. Tries every way of swapping the pair in
    views 2..C (view 1 fixes which point is "left"; 2^(C−1) combinations, fine for C ≤ 8) and keeps the one
    whose two triangulated points have the smallest total squared reprojection error. Returns (left (3,) [m],
    right (3,) [m], swaps (C,) bool: True where the view's labels were exchanged), or None when no
    combination gives both points 2 usable views. About 65 ms for 8 views, 1 ms for 3.
    """
    count = len(cameras)
    pixels = np.stack([left_pixels, right_pixels], axis=1).astype(float)  # (C, 2 labels, 2)
    weights = np.ones((count, 2)) if weights is None else np.asarray(weights, dtype=float)
    # Undistort every observation once; the combinations only permute them.
    normalized = np.stack([camera.undistort_pixels(pair) for camera, pair in zip(cameras, pixels)])
    views = np.arange(count)
    best, best_error = None, np.inf
    for tail in itertools.product((False, True), repeat=count - 1):
        swaps = np.array((False, *tail))
        points, error = [], 0.0
        for label in (0, 1):
            chosen = (swaps ^ bool(label)).astype(int)  # which labelled observation each view gives this point
            used = np.flatnonzero(_usable(pixels[views, chosen], weights[views, chosen]))
            if len(used) < 2:
                break
            used_cameras = [cameras[index] for index in used]
            points.append(dlt_point(used_cameras, normalized[used, chosen[used]], weights[used, chosen[used]]))
            error += _squared_errors(used_cameras, points[-1], pixels[used, chosen[used]]).sum()
        else:
            # Every observation feeds exactly one of the two points, so the totals compare like with like.
            if error < best_error:
                best, best_error = (points[0], points[1], swaps), error
    return best
