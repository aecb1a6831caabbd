"""The per-limb fitting objective of paper 000 (Sec. 5.2, Eq. 4–5).

Bone i projected into camera c is a 2D segment; S_1..S_N (N = 100) are equally spaced points on it.
The matching body part's outline in that view has two boundaries, Bound_1 and Bound_2: the labelled
contour's pixels with the part's label and SIDE_A, resp. SIDE_B. Eq. 4:

    F_c,i = | Σ_j min_k ‖S_j − Bound1_k‖ − Σ_j min_k ‖S_j − Bound2_k‖ |

is smallest when the projected bone runs down the middle between the two boundaries, and Eq. 5 sums it
over the cameras that see the limb: F_i = Σ_c F_c,i.

The nearest-boundary distances are read from Euclidean distance transforms computed once per camera and
frame (one per part label and side), so one evaluation is 2·N map look-ups per camera instead of N·K
point distances. Pixels: x right (column), y down (row), integer coordinates at pixel centres.
"""
from dataclasses import dataclass, field

import cv2
import numpy as np

from mvpose_nodes.contour import SIDE_A, SIDE_B

SEGMENT_POINTS = 100  # N of Eq. 4
MAP_MARGIN_PX = 50    # the maps reach this far beyond the contour, so fitted segments rarely leave them


@dataclass(frozen=True)
class BoundaryDistances:
    """One camera's distance maps for one frame.

    origin: (x0, y0) [px], the image pixel of every map's element [0, 0] (all maps share one box: the
    contour's bounding box grown by MAP_MARGIN_PX, clipped to the image). maps: (label, side) -> (H, W)
    float32 [px], the Euclidean distance from each pixel to the nearest contour pixel of that part and side
    (only (label, side) pairs that have pixels are present). widths: label -> float [px], the Hausdorff
    distance between the part's two boundaries: the widest the part gets (for the enclosure term).
    """
    origin: tuple
    maps: dict
    widths: dict
    _stacked: dict = field(default_factory=dict, compare=False, repr=False)  # label -> (H, W, 2) both sides

    def swapped(self, label_a, label_b):
        """The same maps with two part labels exchanged (a view that had the person's left and right
        the wrong way round)."""
        exchange = {label_a: label_b, label_b: label_a}
        return BoundaryDistances(self.origin, {(exchange.get(label, label), side): m for (label, side), m in self.maps.items()},
                                 {exchange.get(label, label): w for label, w in self.widths.items()})

    def distances(self, label, side, points):
        """Distances [px] (M,) float64 from points (M, 2) [px] (x, y) to the (label, side) boundary.

        Bilinear interpolation inside the box, so the cost is continuous in the segment's end points. A
        point outside the box gets the value at the nearest box point plus its distance to the box: an
        upper bound of the true distance, exact when the nearest boundary pixel lies straight inward from
        the box edge (the margin makes that typical), and never small for a segment far off the part.
        """
        return self._interpolate(self.maps[(label, side)], points)

    def both_sides(self, label, points):
        """(distances to SIDE_A, distances to SIDE_B) of points (M, 2): one interpolation of both maps."""
        stacked = self._stacked.get(label)
        if stacked is None:
            stacked = self._stacked[label] = np.dstack([self.maps[(label, SIDE_A)], self.maps[(label, SIDE_B)]])
        both = self._interpolate(stacked, points)
        return both[:, 0], both[:, 1]

    def _interpolate(self, distance_map, points):
        """Bilinear look-up of an (H, W) or (H, W, K) map at points (M, 2), plus the distance outside the box."""
        height, width = distance_map.shape[:2]
        local = np.asarray(points, dtype=float) - self.origin
        clamped = np.clip(local, 0, (width - 1, height - 1))
        outside = np.hypot(*(local - clamped).T)
        # Lower corner at most the second-to-last index: at the far edge the fraction is then 1.
        corner = np.minimum(np.floor(clamped).astype(int), (max(width - 2, 0), max(height - 2, 0)))
        fx, fy = (clamped - corner).T
        x, y = corner.T
        x1, y1 = np.minimum(x + 1, width - 1), np.minimum(y + 1, height - 1)
        if distance_map.ndim == 3:
            fx, fy, outside = fx[:, None], fy[:, None], outside[:, None]
        top = distance_map[y, x] * (1 - fx) + distance_map[y, x1] * fx
        bottom = distance_map[y1, x] * (1 - fx) + distance_map[y1, x1] * fx
        return top * (1 - fy) + bottom * fy + outside


def boundary_distances(contour_labels, image_size, labels=None, margin=MAP_MARGIN_PX):
    """BoundaryDistances of one camera's ContourLabels for the parts in `labels` (default: every label
    with pixels on both sides). image_size: (width, height) [px]. One cv2.distanceTransform (DIST_L2,
    DIST_MASK_PRECISE: exact Euclidean distances) per (label, side) on a mask that is 0 on that side's
    boundary pixels, restricted to the contour's box (about 1 ms per map for a 1080p person)."""
    points, part_labels, sides = contour_labels.points, contour_labels.labels, contour_labels.sides
    if labels is None:
        labels = set(part_labels[sides == SIDE_A].tolist()) & set(part_labels[sides == SIDE_B].tolist())
    if not len(points):
        return BoundaryDistances((0, 0), {}, {})
    x0, y0 = np.maximum(points.min(axis=0) - margin, 0)
    x1, y1 = np.minimum(points.max(axis=0) + margin, np.subtract(image_size, 1))
    maps, widths = {}, {}
    for label in labels:
        side_pixels = {}
        for side in (SIDE_A, SIDE_B):
            pixels = points[(part_labels == label) & (sides == side)] - (x0, y0)
            if not len(pixels):
                continue
            mask = np.ones((y1 - y0 + 1, x1 - x0 + 1), np.uint8)
            mask[pixels[:, 1], pixels[:, 0]] = 0
            maps[(label, side)] = cv2.distanceTransform(mask, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
            side_pixels[side] = pixels
        if len(side_pixels) == 2:
            a, b = side_pixels[SIDE_A], side_pixels[SIDE_B]
            widths[label] = float(max(maps[(label, SIDE_B)][a[:, 1], a[:, 0]].max(),
                                      maps[(label, SIDE_A)][b[:, 1], b[:, 0]].max()))
    return BoundaryDistances((int(x0), int(y0)), maps, widths)


def segment_points(a, b, n=SEGMENT_POINTS):
    """n equally spaced points (n, 2) float64 [px] from a to b inclusive (the S_j of Eq. 4)."""
    return np.linspace(np.asarray(a, dtype=float), np.asarray(b, dtype=float), n)


def _camera_cost(d1, d2, width, enclosure_weight):
    """Eq. 4 from the distances (N,) [px] of S_j to Bound_1 and Bound_2, plus the optional enclosure term.

    Eq. 4 alone is 0 for any segment equidistant from both boundaries, also one far off the part (e.g.
    beyond its end, on its extended midline). For a point between the boundaries d1 + d2 is about the
    part's local width, at most `width` (their Hausdorff distance); a point δ outside a straight part has
    d1 + d2 = width + 2δ. So Σ_j max(0, d1_j + d2_j − width) is 0 for a segment anywhere on the part, leaves
    Eq. 4's optimum there unchanged, and grows like Eq. 4 (2 px per px and point) as the segment leaves it.
    """
    cost = abs(d1.sum() - d2.sum())
    if enclosure_weight:
        cost += enclosure_weight * np.maximum(d1 + d2 - width, 0).sum()
    return float(cost)


def limb_cost(segments, distances, label, n=SEGMENT_POINTS, enclosure_weight=0.0):
    """F_i of paper 000 Eq. 5: the sum over cameras of Eq. 4 for one bone. Returns (cost [px], cameras_used).

    segments: per camera (a, b), the bone's projected end points [px] (x, y), or None (camera not used);
    distances: the matching BoundaryDistances; label: the part's LABEL_*; n: points per segment.
    enclosure_weight: weight of the "stay on the part" term (see _camera_cost); 0 is the paper's objective.
    A camera whose part lacks SIDE_A or SIDE_B pixels contributes nothing; cameras_used lists the indices
    of the cameras that did. About 60 µs per camera (two look-ups of n = 100 points).
    """
    cost, cameras_used = 0.0, []
    for camera, (segment, maps) in enumerate(zip(segments, distances)):
        if segment is None or label not in maps.widths:
            continue
        points = segment_points(*segment, n)
        cost += _camera_cost(*maps.both_sides(label, points), maps.widths[label], enclosure_weight)
        cameras_used.append(camera)
    return cost, cameras_used


def limb_cost_brute_force(segments, contour_labels, label, n=SEGMENT_POINTS, enclosure_weight=0.0):
    """limb_cost computed directly from the boundary point lists (min over all boundary pixels), for tests.
    contour_labels: per camera the ContourLabels (instead of BoundaryDistances)."""
    cost, cameras_used = 0.0, []
    for camera, (segment, contour) in enumerate(zip(segments, contour_labels)):
        part = contour.labels == label
        bound_1 = contour.points[part & (contour.sides == SIDE_A)].astype(float)
        bound_2 = contour.points[part & (contour.sides == SIDE_B)].astype(float)
        if segment is None or not len(bound_1) or not len(bound_2):
            continue
        points = segment_points(*segment, n)
        d1, d2 = (np.linalg.norm(points[:, None] - bound[None], axis=2).min(axis=1) for bound in (bound_1, bound_2))
        width = max(np.linalg.norm(bound_1[:, None] - bound_2[None], axis=2).min(axis=axis).max() for axis in (0, 1))
        cost += _camera_cost(d1, d2, width, enclosure_weight)
        cameras_used.append(camera)
    return cost, cameras_used
