"""Paper 001's region tracking and marker assignment rules, for one camera (markers/tracking.py says
how they are combined): a region's window tracked by NCC λ-descent, and the markers of a region or
of the limbs paired with the detected blobs. Points (x, y) [px] as in markers/detection.py.
"""
import cv2
import numpy as np
from scipy.optimize import linear_sum_assignment

from mvpose_nodes.markers.detection import FLAG_DETECTED, FLAG_PREDICTED

UNASSIGNABLE = 1e9   # the Hungarian cost of a pair beyond its gate


def ncc(a, b):
    """Zero-mean normalised cross-correlation of two equal-shape arrays; 0 when either is flat."""
    a = a - a.mean()
    b = b - b.mean()
    denominator = np.sqrt(float(np.sum(a * a)) * float(np.sum(b * b)))
    return float(np.sum(a * b) / denominator) if denominator > 1e-12 else 0.0


class RegionTracker:
    """One region's window tracked by λ-descent NCC search, size choice and template update.

    `centre` (2,) and `size` (2,) [px] are the window's (the marker box plus its margin); the
    template has the pixel dimensions of the starting window, and every candidate window is
    resampled onto that grid. `path` lists the search's steps of the last `track` as
    (x, y, λ, ncc) of each accepted position (the start included, then one entry per move)."""

    def __init__(self, step=3, scale_step=0.02, alpha=0.9, update_min_ncc=0.5):
        self.step, self.scale_step, self.alpha, self.update_min_ncc = int(step), scale_step, alpha, update_min_ncc
        self.template = None
        self.centre = self.size = None
        self.path = []
        self.evaluations = 0

    def start(self, image, centre, size):
        """Template from the window (centre, size) of `image` (grey 2-D, or RGB: converted to grey)."""
        image = _grey(image)
        width, height = max(3, int(round(size[0]))), max(3, int(round(size[1])))
        self.template_shape = (height, width)
        self.centre = np.asarray(centre, np.float64).copy()
        self.size = np.array([width, height], np.float64)
        self.template = self.sample(image, self.centre, self.size)

    def sample(self, image, centre, size):
        """The window of `image` at `centre` with `size` [px], resampled on the template's grid:
        template pixel u maps to x = centre_x + (u − (w − 1)/2)·size_x/w (likewise y)."""
        height, width = self.template_shape
        sx, sy = size[0] / width, size[1] / height
        matrix = np.array([[sx, 0.0, centre[0] - (width - 1) / 2.0 * sx],
                           [0.0, sy, centre[1] - (height - 1) / 2.0 * sy]])
        return cv2.warpAffine(image, matrix, (width, height), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                              borderMode=cv2.BORDER_REPLICATE)

    def score(self, image, centre, size):
        self.evaluations += 1
        return ncc(self.template, self.sample(image, centre, size))

    def update_template(self, window):
        """T ← α·T + (1 − α)·window."""
        self.template = (self.alpha * self.template + (1.0 - self.alpha) * window).astype(np.float32)

    def track(self, image, x_range=None, y_range=None):
        """The region in `image`: (centre (2,), size (2,), ncc). `x_range`, `y_range`: (low, high)
        bounds for the centre (None: no bound on that side); candidates outside are not evaluated.
        Without x_range the centre stays within ± one window width of the previous centre."""
        image = _grey(image)
        self.evaluations = 0
        if x_range is None:
            x_range = (self.centre[0] - self.size[0], self.centre[0] + self.size[0])
        low = np.array([_bound(x_range, 0, -np.inf), _bound(y_range, 0, -np.inf)])
        high = np.array([_bound(x_range, 1, np.inf), _bound(y_range, 1, np.inf)])
        centre = self.centre.copy()
        best = self.score(image, centre, self.size)
        step = self.step
        self.path = [(centre[0], centre[1], step, best)]
        while step > 0:
            moved = False
            candidates = [centre + offset for offset in ((step, 0), (-step, 0), (0, step), (0, -step))]
            for candidate in candidates:
                if np.any(candidate < low) or np.any(candidate > high):
                    continue
                value = self.score(image, candidate, self.size)
                if value > best:
                    best, best_centre, moved = value, candidate, True
            if moved:
                centre = best_centre
                self.path.append((centre[0], centre[1], step, best))
            else:
                step -= 1
        size = self.size
        factors = (1.0 - self.scale_step, 1.0, 1.0 + self.scale_step)
        for fx in factors:
            for fy in factors:
                if fx == 1.0 and fy == 1.0:
                    continue
                candidate = self.size * (fx, fy)
                value = self.score(image, centre, candidate)
                if value > best:
                    best, size = value, candidate
        self.centre, self.size = centre, size
        if best >= self.update_min_ncc:
            self.update_template(self.sample(image, centre, size))
        return centre.copy(), size.copy(), best


def _grey(image):
    if image.ndim == 3:
        return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY).astype(np.float32)
    return image.astype(np.float32)


def _bound(limits, index, default):
    if limits is None or limits[index] is None:
        return default
    return float(limits[index])


# Assignment rules (module functions so that each case can be tested on its own)

def inside(points, centre, size):
    """(N,) bool: points within the axis-aligned box (centre, size)."""
    points = np.asarray(points, np.float64).reshape(-1, 2)
    return np.all(np.abs(points - np.asarray(centre)) <= np.asarray(size) / 2.0, axis=1)


def gated_assignment(predicted, detections, gate):
    """Hungarian pairing of predicted points (M, 2) with detections (N, 2); gate: a scalar or (M,) [px]
    per point. Pairs farther than their gate are dropped; the cost is distance / gate, so that an
    uncertain prediction (a wide gate) does not take a detection from a confident one. (M,) int: the
    detection index per point, −1 when none."""
    result = np.full(len(predicted), -1, dtype=int)
    if len(predicted) == 0 or len(detections) == 0:
        return result
    distance = np.linalg.norm(np.asarray(predicted)[:, None, :] - np.asarray(detections)[None, :, :], axis=2)
    gate = np.broadcast_to(np.asarray(gate, np.float64).reshape(-1, 1), (len(predicted), 1))
    cost = np.where(distance <= gate, distance / np.maximum(gate, 1e-9), UNASSIGNABLE)
    rows, cols = linear_sum_assignment(cost)
    for row, col in zip(rows, cols):
        if distance[row, col] <= gate[row, 0]:
            result[row] = col
    return result


def assign_head(previous, displacement, detections, centre, size):
    """Region 1. (position (2,), flag, detection index or −1): the only detection inside the box
    (centre, size); of several, the nearest to previous + displacement; none: that prediction."""
    predicted = np.asarray(previous, np.float64) + displacement
    detections = np.asarray(detections, np.float64).reshape(-1, 2)
    candidates = np.flatnonzero(inside(detections, centre, size))
    if len(candidates) == 0:
        return predicted, FLAG_PREDICTED, -1
    if len(candidates) > 1:
        candidates = candidates[[np.argmin(np.linalg.norm(detections[candidates] - predicted, axis=1))]]
    return detections[candidates[0]].copy(), FLAG_DETECTED, int(candidates[0])


def assign_group(previous, displacement, detections, centre, box_size, reference, window_factor=1.1):
    """Regions 2 and 3: three markers. previous (3, 2) at t − 1, displacement S (2,), detections
    (N, 2), the region's marker box (centre, box_size = h); the search window is window_factor·h
    around the centre, the gate (h_x + h_y)/4; reference (3, 2): the positions of the last frame
    with all three detected. Returns (positions (3, 2), flags (3,), the detection index per marker
    (3,), −1 when not detected). The rules for 2/1/0 found are in the module docstring."""
    previous = np.asarray(previous, np.float64)
    box_size = np.asarray(box_size, np.float64)
    predicted = previous + np.asarray(displacement, np.float64)
    detections = np.asarray(detections, np.float64).reshape(-1, 2)
    candidates = np.flatnonzero(inside(detections, centre, window_factor * box_size))
    gate = float(box_size[0] + box_size[1]) / 4.0
    match = gated_assignment(predicted, detections[candidates], gate)
    index = np.full(len(predicted), -1, dtype=int)
    index[match >= 0] = candidates[match[match >= 0]]
    found = index >= 0
    positions = predicted.copy()
    positions[found] = detections[index[found]]
    flags = np.where(found, FLAG_DETECTED, FLAG_PREDICTED).astype(np.uint8)
    if found.sum() == 2:
        a, b = np.flatnonzero(found)
        (c,) = np.flatnonzero(~found)
        positions[c] = similarity_complete(reference[a], reference[b], reference[c], positions[a], positions[b])
    elif found.sum() == 1:
        (a,) = np.flatnonzero(found)
        positions[~found] = predicted[~found] + (positions[a] - predicted[a])
    return positions, flags, index


def similarity_complete(ref_a, ref_b, ref_c, a, b):
    """The image of ref_c under the similarity (rotation, uniform scale, translation) taking
    ref_a → a and ref_b → b; a translation when ref_a == ref_b."""
    za, zb, zc = (complex(*p) for p in (ref_a, ref_b, ref_c))
    wa, wb = complex(*a), complex(*b)
    ratio = (wb - wa) / (zb - za) if abs(zb - za) > 1e-9 else 1.0
    w = wa + ratio * (zc - za)
    return np.array([w.real, w.imag])
