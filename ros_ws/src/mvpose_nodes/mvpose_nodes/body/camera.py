"""Calibrated pinhole cameras with plumb_bob distortion, the i3DPost-like studio rig and rings like it.

Conventions: world frame in metres, z up, floor at z = 0. X_cam = R · X_world + t; camera
(optical) frame x right, y down, z forward. Pixels: x right (column), y down (row), origin
at the centre of the top-left pixel. Distortion D = [k1, k2, p1, p2, k3] (ROS plumb_bob,
OpenCV's model).
"""
import math
from dataclasses import dataclass, field, replace

import numpy as np

from mvpose_nodes.body.geometry import matrix_from_quaternion, normalize, quaternion_from_matrix

# The i3DPost-like rig (Gkalelis et al. 2009 describe 8 cameras on a ring around a blue studio).
RIG_CAMERAS = 8
RIG_RADIUS = 4.0           # [m] ring diameter about 8 m
RIG_HEIGHT = 2.0           # [m] camera height
RIG_TARGET = (0.0, 0.0, 0.7)  # [m] where every camera looks: the middle of the capture area, below the hips
RIG_FOCAL = 1400.0         # [px] at 1920×1080; the walk of frames 52–101 stays whole in cameras 3, 5 and 7
                           # (at least 70 px from every border) while filling about 55 % of the height
RIG_RESOLUTION = (1920, 1080)


@dataclass(frozen=True)
class Camera:
    """One calibrated camera. Arrays are float64: K 3×3 [px], D (5,), R 3×3, t (3,) [m]."""
    number: int
    width: int
    height: int
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    D: np.ndarray = field(default_factory=lambda: np.zeros(5))

    @property
    def name(self):
        return f'cam{self.number}'

    @property
    def center(self):
        """[m] optical centre in the world, (3,)."""
        return -self.R.T @ self.t

    def to_camera(self, points):
        """World points (N, 3) [m] -> camera-frame points (N, 3) [m]."""
        return np.asarray(points, dtype=float) @ self.R.T + self.t

    def project(self, points):
        """World points (N, 3) [m] -> pixels (N, 2) with distortion, and depths (N,) [m] (<= 0: behind)."""
        camera_points = self.to_camera(points)
        depth = camera_points[:, 2]
        with np.errstate(divide='ignore', invalid='ignore'):
            normalized = camera_points[:, :2] / depth[:, None]
        return self.pixels_from_normalized(self.distort(normalized)), depth

    def distort(self, normalized):
        """Ideal normalised coordinates (N, 2) -> distorted ones (plumb_bob)."""
        if not self.D.any():
            return normalized
        return plumb_bob(normalized, self.D)

    def pixels_from_normalized(self, normalized):
        return normalized @ self.K[:2, :2].T + self.K[:2, 2]

    def undistort_pixels(self, pixels):
        """Distorted pixels (N, 2) -> ideal normalised coordinates (N, 2) (OpenCV's iterative inverse)."""
        import cv2
        points = np.asarray(pixels, dtype=np.float64).reshape(-1, 1, 2)
        if not np.any(self.D):
            return (points.reshape(-1, 2) - self.K[:2, 2]) @ np.linalg.inv(self.K[:2, :2]).T
        return cv2.undistortPoints(points, self.K, self.D).reshape(-1, 2)

    def rays(self, normalized):
        """Unit viewing directions in the world (N, 3) through ideal normalised coordinates (N, 2)."""
        directions = np.column_stack([normalized, np.ones(len(normalized))])
        return normalize(directions @ self.R)

    @property
    def projection_matrix(self):
        """P = K [R | t], 3×4, for DLT triangulation (ignores distortion)."""
        return self.K @ np.column_stack([self.R, self.t])

    def pose(self):
        """The optical frame's pose in the world: position (3,) [m], orientation quaternion [x, y, z, w]."""
        return self.center, quaternion_from_matrix(self.R.T)

    @classmethod
    def from_pose(cls, number, width, height, K, position, orientation, D=None):
        """A camera from its optical frame's pose in the world (the camera_pose topic) and intrinsics."""
        R = matrix_from_quaternion(np.asarray(orientation, dtype=float)).T
        return cls(number, int(width), int(height), np.asarray(K, dtype=float).reshape(3, 3), R,
                   -R @ np.asarray(position, dtype=float), np.zeros(5) if D is None else np.asarray(D, dtype=float))

    def with_distortion(self, D):
        return replace(self, D=np.asarray(D, dtype=float))


def plumb_bob(normalized, D):
    """Ideal normalised coordinates (..., 2) distorted by plumb_bob coefficients D (..., 5) (k1, k2, p1, p2,
    k3), which broadcast against them (one camera's (5,), or one row per camera)."""
    k1, k2, p1, p2, k3 = np.moveaxis(np.asarray(D, dtype=float), -1, 0)
    x, y = normalized[..., 0], normalized[..., 1]
    r2 = x * x + y * y
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    return np.stack([x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
                     y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y], axis=-1)


def look_at(number, position, target, K, width, height, world_up=(0.0, 0.0, 1.0)):
    """A camera at `position` [m] whose optical axis points at `target` [m], image x level with the floor."""
    forward = normalize(np.subtract(target, position))
    right = normalize(np.cross(forward, world_up))
    down = np.cross(forward, right)
    R = np.stack([right, down, forward])  # rows: the camera axes in world coordinates
    return Camera(number, width, height, np.asarray(K, dtype=float), R, -R @ np.asarray(position, dtype=float))


def intrinsics(focal, width, height):
    """K of a camera with square pixels and the principal point at the image centre."""
    return np.array([[focal, 0.0, (width - 1) / 2], [0.0, focal, (height - 1) / 2], [0.0, 0.0, 1.0]])


def studio_rig(resolution=RIG_RESOLUTION, cameras=range(1, RIG_CAMERAS + 1)):
    """The i3DPost-like ring: camera K at angle (K−1)·45° around the centre, all aimed at RIG_TARGET.

    The focal length scales with the image width, so every resolution sees the same view. (ring_rig
    with its defaults; the demo's cameras, so it must not change.)"""
    return ring_rig(resolution, cameras=cameras)


def ring_rig(resolution=RIG_RESOLUTION, diameter=2 * RIG_RADIUS, height=RIG_HEIGHT, aim=RIG_TARGET,
             focal_scale=1.0, principal_offsets=(0.0, 0.0), cameras=range(1, RIG_CAMERAS + 1)):
    """A studio_rig-like ring of RIG_CAMERAS cameras, camera K at angle (K−1)·45° around the world's
    origin, each at `height` looking at its `aim` point with the image x axis level.

    resolution: (width, height) [px].
    diameter: [m] of the ring of camera centres.
    height: [m] camera height above the floor, one for all or one per camera (8,).
    aim: [m] the world point each camera's optical axis passes through, (3,) for all or (8, 3).
    focal_scale: the focal length as a multiple of RIG_FOCAL (which is for a 1920 px wide image and is
        scaled with the width, as in studio_rig), one for all or one per camera (8,).
    principal_offsets: [px of this resolution] (dx, dy) of the principal point from the image centre,
        (2,) for all or (8, 2).
    cameras: the camera numbers 1..8 to make, in this order.
    Per-camera values are indexed by camera number − 1. With the defaults this is studio_rig, exactly."""
    width, image_height = resolution
    heights = _per_camera(height, ())
    aims = _per_camera(aim, (3,))
    scales = _per_camera(focal_scale, ())
    offsets = _per_camera(principal_offsets, (2,))
    radius = diameter / 2
    rig = []
    for number in cameras:
        if not 1 <= number <= RIG_CAMERAS:
            raise ValueError(f'camera number {number} is not in 1..{RIG_CAMERAS}')
        index = number - 1
        K = intrinsics(RIG_FOCAL * scales[index] * width / RIG_RESOLUTION[0], width, image_height)
        K[:2, 2] += offsets[index]
        angle = 2 * math.pi * (number - 1) / RIG_CAMERAS
        position = (radius * math.cos(angle), radius * math.sin(angle), heights[index])
        rig.append(look_at(number, position, aims[index], K, width, image_height))
    return rig


def _per_camera(value, shape):
    """(RIG_CAMERAS,) + shape float64: `value` of that shape repeated for every camera, or given per camera."""
    value = np.asarray(value, dtype=float)
    if value.shape not in (shape, (RIG_CAMERAS,) + shape):
        raise ValueError(f'expected shape {shape} or {(RIG_CAMERAS,) + shape}, got {value.shape}')
    return np.broadcast_to(value, (RIG_CAMERAS,) + shape)
