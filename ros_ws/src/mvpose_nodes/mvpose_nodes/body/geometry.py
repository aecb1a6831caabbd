"""Rotations as matrices and quaternions ([x, y, z, w], the ROS order), and paper 004's exact
rotation between two bone vectors.

All functions take and return float64 NumPy arrays; a leading batch axis is allowed where noted.
"""
import numpy as np

PARALLEL_TOLERANCE = 1e-12  # |sin φ| below this: the two vectors are taken as parallel


# The kinematics turn single 3-vectors hundreds of times per fitted frame set, where NumPy's general
# routines (np.cross's and np.linalg.norm's axis handling) cost several times the arithmetic: the functions
# here do the same arithmetic in the same order (the same bits) with fewer calls.

def norm(vectors, axis=-1, keepdims=False):
    """Euclidean lengths along `axis` of float arrays, as np.linalg.norm computes them along an axis."""
    return np.sqrt(np.add.reduce(vectors * vectors, axis=axis, keepdims=keepdims))


def normalize(vectors, axis=-1):
    """Unit vectors along `axis` (zero vectors stay zero)."""
    vectors = np.asarray(vectors, dtype=float)
    length = norm(vectors, axis, keepdims=True)
    return np.divide(vectors, length, out=np.zeros_like(vectors), where=length > 0)


def cross(a, b):
    """a × b of (..., 3) vectors, as np.cross computes it."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def quaternion_from_axis_angle(axis, angle):
    """q = [sin(φ/2)·n, cos(φ/2)] for a unit axis n and angle φ [rad] (paper 004 Eq. 4)."""
    half = 0.5 * np.asarray(angle, dtype=float)
    return np.concatenate([np.sin(half)[..., None] * np.asarray(axis, dtype=float), np.cos(half)[..., None]], axis=-1)


def rotation_between(r, r_prime):
    """The quaternion of the smallest rotation taking direction r to direction r' (paper 004 Eq. 3–4):
    axis n = nor(r × r'), cos φ = r·r' / (|r||r'|). Parallel vectors give the identity; anti-parallel
    ones a half turn about an axis perpendicular to r. Shapes (3,) or (N, 3) -> (4,) or (N, 4)."""
    r, r_prime = normalize(r), normalize(r_prime)
    normal = cross(r, r_prime)
    sin_phi = norm(normal)
    cos_phi = np.clip(np.add.reduce(r * r_prime, axis=-1), -1.0, 1.0)
    phi = np.arctan2(sin_phi, cos_phi)
    axis = normalize(normal)
    parallel = sin_phi <= PARALLEL_TOLERANCE
    if np.any(parallel):
        # Any axis perpendicular to r serves: r × the least-aligned basis axis.
        basis = np.eye(3)[np.argmin(np.abs(r), axis=-1)]
        axis = np.where(parallel[..., None], normalize(cross(r, basis)), axis)
    return quaternion_from_axis_angle(axis, phi)


def matrix_from_quaternion(q):
    """3×3 rotation matrix (or N×3×3) of unit quaternion(s) [x, y, z, w]."""
    q = normalize(q)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    entries = [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
               2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
               2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]
    return np.stack(entries, -1).reshape(q.shape[:-1] + (3, 3))


def quaternion_from_matrix(matrix):
    """Unit quaternion [x, y, z, w] (w >= 0) of a 3×3 rotation matrix (Shepperd's method, stable for all angles)."""
    m = np.asarray(matrix, dtype=float)
    trace = np.trace(m)
    candidates = np.array([trace, m[0, 0], m[1, 1], m[2, 2]])
    best = int(np.argmax(candidates))
    if best == 0:
        s = 2.0 * np.sqrt(1.0 + trace)
        q = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s]
    else:
        i = best - 1
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + m[i, i] - m[j, j] - m[k, k])
        q = [0.0, 0.0, 0.0, (m[k, j] - m[j, k]) / s]
        q[i] = 0.25 * s
        q[j] = (m[j, i] + m[i, j]) / s
        q[k] = (m[k, i] + m[i, k]) / s
    q = np.array(q)
    return q if q[3] >= 0 else -q


def rotation_about(axis, angle):
    """3×3 matrix of a rotation by `angle` [rad] about `axis` (Rodrigues)."""
    return matrix_from_quaternion(quaternion_from_axis_angle(normalize(axis), angle))
