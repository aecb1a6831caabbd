"""Initial 3D joint positions from the 2D keypoints of several calibrated views (paper 000 Sec. 3.1:
"the 2D keypoints from the 3 views give initial 3D positions"), by linear triangulation.

DLT after Hartley & Zisserman, Multiple View Geometry (2nd ed.), Sec. 12.2: each view with ideal
normalised coordinates (u, v) of the point and normalised camera matrix P = [R | t] gives two rows
u·P³ − P¹ and v·P³ − P² of A X = 0 (Pⁱ: row i of P); X is the right singular vector of A's smallest
singular value. Normalised coordinates (distortion removed, K divided out) are of order 1 like the
world coordinates in metres, which conditions A better than pixels (H&Z Sec. 4.4).

The problems of a frame set (every keypoint, each way of labelling a left/right pair, each view left
out in turn) are solved together as arrays (`Rig`, `dlt_points`, `Rig.squared_errors`): a view that
does not take part gives zero rows, which leave A's null space as it is.
"""
import itertools
from dataclasses import dataclass

import numpy as np

from mvpose_nodes.body.camera import plumb_bob


@dataclass(frozen=True)
class Rig:
    """C cameras as arrays: projections (C, 3, 4) [R | t], R (C, 3, 3), t (C, 3) [m], K (C, 3, 3) [px],
    D (C, 5) (body.camera.Camera)."""
    cameras: tuple
    projections: np.ndarray
    R: np.ndarray
    t: np.ndarray
    K: np.ndarray
    D: np.ndarray

    @classmethod
    def of(cls, cameras):
        cameras = tuple(cameras)
        R = np.array([camera.R for camera in cameras], float).reshape(-1, 3, 3)
        t = np.array([camera.t for camera in cameras], float).reshape(-1, 3)
        return cls(cameras, np.concatenate([R, t[:, :, None]], axis=2), R, t,
                   np.array([camera.K for camera in cameras], float).reshape(-1, 3, 3),
                   np.array([camera.D for camera in cameras], float).reshape(-1, 5))

    def normalized(self, pixels):
        """Ideal normalised coordinates (C, M, 2) of distorted pixels (C, M, 2) [px] (NaN stays NaN): one
        Camera.undistort_pixels call per camera."""
        return np.stack([camera.undistort_pixels(points).reshape(-1, 2)
                         for camera, points in zip(self.cameras, pixels)])

    def squared_errors(self, points, pixels):
        """Squared reprojection errors (N, C) [px²] of world points (N, 3) [m] in every camera, against
        distorted pixels (N, C, 2) [px] (Camera.project in every camera at once)."""
        in_camera = np.einsum('cij,nj->nci', self.R, points) + self.t
        with np.errstate(divide='ignore', invalid='ignore'):
            normalized = in_camera[..., :2] / in_camera[..., 2:]
        projected = np.einsum('cij,ncj->nci', self.K[:, :2, :2], plumb_bob(normalized, self.D)) + self.K[:, :2, 2]
        return np.sum((projected - pixels) ** 2, axis=-1)


def dlt_points(projections, normalized, weights):
    """N DLT points (N, 3) [m] at once: projections (C, 3, 4) the views' [R | t], normalized (N, C, 2) ideal
    normalised coordinates, weights (N, C) each view's row weight (0: not used, and then its coordinates may
    be NaN). A problem needs 2 used views; otherwise its point is meaningless."""
    used = weights > 0
    coordinates = np.where(used[..., None], normalized, 0.0)
    rows = (weights * used)[..., None, None] * (coordinates[..., None] * projections[:, 2][:, None, :]
                                                - projections[:, :2])   # (N, C, 2, 4)
    homogeneous = np.linalg.svd(rows.reshape(len(rows), -1, 4))[2][:, -1]
    with np.errstate(divide='ignore', invalid='ignore'):   # a problem without 2 views
        return homogeneous[:, :3] / homogeneous[:, 3:]


def dlt_point(cameras, normalized, weights):
    """The DLT point (3,) [m] from ideal normalised coordinates (C, 2) (distortion removed, K divided out:
    Camera.undistort_pixels) and row weights (C,) (all used; at least 2 views)."""
    return dlt_points(Rig.of(cameras).projections, np.asarray(normalized, float)[None],
                      np.asarray(weights, float)[None])[0]


def usable(pixels, weights):
    """Observations with finite pixels and a positive weight: bool, the shape of weights ((..., C, 2) pixels)."""
    return np.all(np.isfinite(pixels), axis=-1) & (weights > 0)


def triangulate_many(rig, pixels, weights, normalized=None):
    """N points triangulated at once: pixels (N, C, 2) [px] distorted (NaN: not seen), weights (N, C) ≥ 0
    (0: view not used), normalized (N, C, 2) their Rig.normalized coordinates if already known. Returns
    points (N, 3) [m], their squared reprojection errors (N, C) [px²] in the views used (with distortion;
    0 in the others) and the number of views used (N,); a point with fewer than 2 views is meaningless."""
    seen = usable(pixels, weights)
    if normalized is None:
        normalized = rig.normalized(np.swapaxes(pixels, 0, 1)).swapaxes(0, 1)
    points = dlt_points(rig.projections, normalized, np.where(seen, weights, 0.0))
    with np.errstate(invalid='ignore'):
        squared = np.where(seen, rig.squared_errors(points, np.where(seen[..., None], pixels, 0.0)), 0.0)
    return points, squared, seen.sum(axis=1)


def rms_of(squared, count):
    """RMS reprojection errors (N,) [px] of triangulate_many's squared errors and view counts (NaN without
    2 views)."""
    return np.sqrt(squared.sum(axis=1) / np.where(count >= 2, count, np.nan))


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
    points, squared, count = triangulate_many(Rig.of(cameras), pixels[None], weights[None])
    return None if count[0] < 2 else (points[0], float(rms_of(squared, count)[0]))


def best_assignment(cameras, left_pixels, right_pixels, weights=None, rig=None, normalized=None):
    """Resolve per-view left/right swaps of a symmetric keypoint pair (a single view cannot tell them apart).

    left_pixels, right_pixels: (C, 2) [px] the pair as labelled in each view (NaN row = not seen); weights:
    optional (C, 2) confidences of the (left, right) observations; rig (a Rig of the cameras) and
    normalized (C, 2, 2) the pair's Rig.normalized coordinates if already known. Tries every way of
    swapping the pair in views 2..C (view 1 fixes which point is "left"; 2^(C−1) combinations, fine for
    C ≤ 8) and keeps the one whose two triangulated points have the smallest total squared reprojection
    error (the first of equals). Returns (left (3,) [m], right (3,) [m], swaps (C,) bool: True where the
    view's labels were exchanged), or None when no combination gives both points 2 usable views.
    """
    count = len(cameras)
    rig = rig or Rig.of(cameras)
    pixels = np.stack([left_pixels, right_pixels], axis=1).astype(float)  # (C, 2 labels, 2)
    weights = np.ones((count, 2)) if weights is None else np.asarray(weights, dtype=float)
    if normalized is None:
        normalized = rig.normalized(pixels)
    return best_assignments(rig, pixels[None], weights[None], np.asarray(normalized, float)[None])[0]


def best_assignments(rig, pixels, weights, normalized):
    """best_assignment of P pairs at once (one triangulate_many call for all their combinations): pixels
    (P, C, 2 labels, 2) [px], weights (P, C, 2), normalized (P, C, 2, 2) their Rig.normalized coordinates.
    Returns a list of P results, each (left, right, swaps) or None, as best_assignment's."""
    pairs, count = pixels.shape[:2]
    swaps = np.array([(False, *tail) for tail in itertools.product((False, True), repeat=count - 1)])  # (S, C)
    # Which labelled observation each view gives the pair's first and second point: (2 S, C).
    chosen = np.concatenate([swaps, ~swaps]).astype(int)
    views = np.arange(count)
    points, squared, used = triangulate_many(rig, pixels[:, views, chosen].reshape(-1, count, 2),
                                             weights[:, views, chosen].reshape(-1, count),
                                             normalized[:, views, chosen].reshape(-1, count, 2))
    points = points.reshape(pairs, 2 * len(swaps), 3)
    # Every observation feeds exactly one of the two points, so the totals compare like with like.
    errors = squared.sum(axis=1).reshape(pairs, 2, -1).sum(axis=1)
    valid = (used.reshape(pairs, 2, -1) >= 2).all(axis=1)
    results = []
    for pair in range(pairs):
        if not valid[pair].any():
            results.append(None)
            continue
        best = int(np.flatnonzero(valid[pair])[np.argmin(errors[pair][valid[pair]])])
        results.append((points[pair, best], points[pair, len(swaps) + best], swaps[best]))
    return results
