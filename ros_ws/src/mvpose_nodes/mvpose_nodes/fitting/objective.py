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

The transform itself (exact_distances, at the end) is compiled with numba: the two passes of Felzenszwalb
and Huttenlocher ("Distance transforms of sampled functions", Theory of Computing 8, 2012), as OpenCV's
distanceTransform does them with DIST_MASK_PRECISE: along each column the distance to the nearest seed, then
along each row the lower envelope of the parabolas (q − p)² + f(p), in float32 arithmetic as OpenCV's. Each
distance is the correctly rounded square root of its (integer) squared distance; the opencv-python 5
wheel's is one unit in the last place off on about a fifth of the pixels (its square root is approximate),
which is all that tells the two apart. It takes about two thirds of OpenCV's time on the fitter's maps (one
thread; tests/test_distance_transform.py checks the values, not the time): the column pass runs row by row
(in memory order), the envelope is built over the columns that have a seed only and, per row, between the
row's own seeds, and each envelope segment's distances are written in one loop. Cached on disk like
compiled.py.
"""
import functools
from dataclasses import dataclass, field

import cv2
import numpy as np
from numba import njit

from mvpose_nodes.fitting import numba_cache  # noqa: F401  (first: the cache folder of this version's sources)
from mvpose_nodes.vision.contour import SIDE_A, SIDE_B

SEGMENT_POINTS = 100  # N of Eq. 4
MAP_MARGIN_PX = 50    # a part's maps reach this far beyond its contour pixels, so its segments rarely leave them
BILINEAR_STEPS = 32   # map look-ups resolve 1/32 of a map cell, as cv2.remap (INTER_BITS = 5)
# The boundary maps are computed and looked up on a grid this many times coarser (within a pixel of exact):
# 2.7 times cheaper (1080p: 3.7 instead of 10 ms per view, the fitter's largest cost beside the fit
# itself), and measured no worse: the demo walk 29.5 against 31.3 mm, 22 tuning cases of the suite 169
# against 188 mm mean. OpenCV's approximate DIST_MASK_5 at full size was less cheap and worse (40 mm).
# Read on that grid, in each part's own box, not resized: 18.4 -> 7.4 ms per frame set (docs/method.md).
MAP_COARSENING = 2
# Every map starts on a 64-byte line: OpenCV's vector code can round the last bit differently with the
# destination's alignment (its resize did), and a map must not depend on where in memory it was made.
MAP_ALIGNMENT = 16  # float32s


class MapArena:
    """float32 memory for the distance maps of one frame set's views, handed out as consecutive slices of
    one array, each starting on a MAP_ALIGNMENT boundary: compiled.pack_frame then passes the views' maps to
    the search as that array, without copying them together (which took 3–10 ms per frame set on a busy
    machine). `floats`: an upper bound of what the maps take (map_floats); beyond it, maps get memory of
    their own (and are copied)."""

    def __init__(self, floats):
        # Untouched pages cost nothing: a bound will do.
        self.buffer = np.empty(int(floats) + MAP_ALIGNMENT, np.float32)
        self.used = 0

    def take(self, count):
        """A (count,) float32 slice not handed out before, its first element on a MAP_ALIGNMENT boundary."""
        count = int(count)
        start = self.used + (-(self.buffer.ctypes.data // self.buffer.itemsize + self.used)) % MAP_ALIGNMENT
        if start + count > len(self.buffer):
            return MapArena(count).take(count)
        self.used = start + count
        return self.buffer[start:self.used]


def map_floats(contour_points, map_count):
    """An upper bound of the floats that `map_count` boundary maps (boundary_distances) and the Outline's
    map (outline_of) of one contour (N, 2) [px] take, with their alignment."""
    extent = np.ptp(contour_points, axis=0) + 1 if len(contour_points) else np.zeros(2, int)
    return (map_count * int(np.prod((extent + 2 * MAP_MARGIN_PX) // MAP_COARSENING + 2))
            + int(np.prod(extent + 2 * OUTLINE_MARGIN_PX)) + (map_count + 2) * MAP_ALIGNMENT)


@dataclass(frozen=True)
class BoundaryDistances:
    """One camera's distance maps for one frame.

    maps: (label, side) -> (H, W) float32 [px], the Euclidean distance to the nearest contour pixel of that
    part and side (only (label, side) pairs that have pixels are present) on a grid MAP_COARSENING times
    coarser than the image's: element [i, j] is the distance at the centre of the image pixels x0 + C·j …
    x0 + C·j + C − 1, y0 + C·i … (C = MAP_COARSENING). The two sides of a part share one box, the part's
    contour pixels' box grown by MAP_MARGIN_PX and clipped to the image, whose first pixel is
    origins[label] (x0, y0) [px] (a multiple of C). widths: label ->
    float [px], the Hausdorff distance between the part's two boundaries: the widest the part gets (for the
    enclosure term). buffer: (N,) float32, every map flattened one after the other (the maps are views of
    it; compiled.py reads them there without copying), offsets: (label, side) -> the index of the map's
    first element.
    """
    maps: dict
    origins: dict
    widths: dict
    buffer: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float32), compare=False, repr=False)
    offsets: dict = field(default_factory=dict)

    def swapped(self, label_a, label_b):
        """The same maps with two part labels exchanged (a view that had the person's left and right
        the wrong way round)."""
        exchange = {label_a: label_b, label_b: label_a}

        def relabelled_sides(by_side):
            return {(exchange.get(label, label), side): value for (label, side), value in by_side.items()}
        def relabelled(by_label):
            return {exchange.get(label, label): value for label, value in by_label.items()}
        return BoundaryDistances(relabelled_sides(self.maps), relabelled(self.origins), relabelled(self.widths),
                                 self.buffer, relabelled_sides(self.offsets))

    def distances(self, label, side, points):
        """Distances [px] (M,) float64 from points (M, 2) [px] (x, y) to the (label, side) boundary.

        Bilinear interpolation inside the part's box, so the cost is continuous in the segment's end points.
        A point outside the box gets the value at the nearest box point plus its distance to the box: an
        upper bound of the true distance, exact when the nearest boundary pixel lies straight inward from
        the box edge (the margin makes that typical), and never small for a segment far off the part.
        """
        return bilinear(self.maps[(label, side)], np.asarray(points, dtype=float) - self.origins[label])

    def both_sides(self, label, points):
        """(distances to SIDE_A, distances to SIDE_B) of points (M, 2)."""
        return self.distances(label, SIDE_A, points), self.distances(label, SIDE_B, points)


def bilinear(distance_map, local):
    """Bilinear look-up of an (H, W) float32 map on the MAP_COARSENING grid (BoundaryDistances.maps) at
    points (M, 2) [px] (x, y) in image pixels from the map's box origin, in float64 (M,), with OpenCV's
    remap weights: positions rounded to 1/BILINEAR_STEPS of the map's pixel (far below what the fit
    resolves). A point outside the map gets the value at the nearest map point plus its distance to it.
    compiled._bilinear does the same per point."""
    height, width = distance_map.shape
    grid = (local + 0.5) / MAP_COARSENING - 0.5   # image pixel centres in the map's pixels
    clamped = np.clip(grid, 0, (width - 1, height - 1))
    outside = MAP_COARSENING * np.hypot(*(grid - clamped).T)
    steps = np.rint(clamped * BILINEAR_STEPS).astype(int)
    low = steps // BILINEAR_STEPS
    high = np.minimum(low + 1, (width - 1, height - 1))
    fraction = (steps % BILINEAR_STEPS) / BILINEAR_STEPS
    fx, fy = fraction[:, 0], fraction[:, 1]
    v00, v01 = (distance_map[low[:, 1], x].astype(float) for x in (low[:, 0], high[:, 0]))
    v10, v11 = (distance_map[high[:, 1], x].astype(float) for x in (low[:, 0], high[:, 0]))
    top = v00 + fx * (v01 - v00)
    bottom = v10 + fx * (v11 - v10)
    return top + fy * (bottom - top) + outside


def boundary_distances(contour_labels, image_size, labels=None, margin=MAP_MARGIN_PX, arena=None):
    """BoundaryDistances of one camera's ContourLabels for the parts in `labels` (default: every label
    with pixels on both sides), their maps in `arena` (a MapArena) if given. image_size: (width, height)
    [px]. One exact Euclidean distance transform (exact_distances) per (label, side)
    from that side's boundary pixels, restricted to the part's box (a third
    of the whole contour's box on average, and as exact within it), on the image's grid MAP_COARSENING
    times coarser (a boundary pixel moves by half a pixel), written into the BoundaryDistances' buffer;
    looked up bilinearly, the maps are within a pixel of the exact distances."""
    groups = side_groups(contour_labels)
    if labels is None:
        labels = {label for label, side in groups if side == SIDE_A} & {label for label, side in groups if side == SIDE_B}
    boxes = {}
    for label in labels:
        own = [pixels for (group_label, _), pixels in groups.items() if group_label == label]
        if own:
            boxes[label] = part_box(np.concatenate(own), image_size, margin)
    present = [(label, side) for label in boxes for side in (SIDE_A, SIDE_B) if (label, side) in groups]
    sizes = [boxes[label][1][0] * boxes[label][1][1] for label, _ in present]
    spans = [-(-size // MAP_ALIGNMENT) * MAP_ALIGNMENT for size in sizes]   # each map aligned in the buffer
    buffer = (arena or MapArena(sum(spans))).take(sum(spans))
    maps, widths, offsets, side_pixels = {}, {}, {}, {}
    for (label, side), size, offset in zip(present, sizes, np.cumsum([0] + spans)):
        pixels = groups[(label, side)] - boxes[label][0]
        boundary = np.zeros(boxes[label][1], np.uint8)
        boundary[pixels[:, 1] // MAP_COARSENING, pixels[:, 0] // MAP_COARSENING] = 1
        offsets[(label, side)] = int(offset)
        maps[(label, side)] = buffer[offset:offset + size].reshape(boxes[label][1])
        exact_distances(boundary, maps[(label, side)], MAP_COARSENING)
        side_pixels[(label, side)] = pixels
    for label in boxes:
        if (label, SIDE_A) in maps and (label, SIDE_B) in maps:
            a, b = side_pixels[(label, SIDE_A)], side_pixels[(label, SIDE_B)]
            widths[label] = float(max(bilinear(maps[(label, SIDE_B)], a).max(),
                                      bilinear(maps[(label, SIDE_A)], b).max()))
    return BoundaryDistances(maps, {label: box[0] for label, box in boxes.items()}, widths, buffer, offsets)


def side_groups(contour_labels):
    """A ContourLabels' pixels by part and side: {(label, side): (M, 2) [px] (x, y), M > 0}, each group in
    contour order (one sort of the contour, not a mask over it per part and side)."""
    part_labels, sides = contour_labels.labels, contour_labels.sides
    if not len(part_labels):
        return {}
    order = np.lexsort((sides, part_labels))
    grouped_labels, grouped_sides = part_labels[order], sides[order]
    starts = np.flatnonzero(np.r_[True, (grouped_labels[1:] != grouped_labels[:-1]) | (grouped_sides[1:] != grouped_sides[:-1])])
    ends = np.r_[starts[1:], len(order)]
    return {(int(grouped_labels[start]), int(grouped_sides[start])): contour_labels.points[order[start:end]]
            for start, end in zip(starts, ends)}


def part_box(pixels, image_size, margin=MAP_MARGIN_PX):
    """The box of a part's distance maps: its contour pixels (M, 2) [px] (x, y), M > 0, grown by `margin`
    [px] and clipped to the image (image_size (width, height) [px]), its first corner on the
    MAP_COARSENING grid. Returns ((x0, y0) [px], (rows, columns) of the maps on that grid)."""
    first = np.maximum(pixels.min(axis=0) - margin, 0) // MAP_COARSENING * MAP_COARSENING
    last = np.minimum(pixels.max(axis=0) + margin, np.subtract(image_size, 1))
    cells = (last - first) // MAP_COARSENING + 1
    return (int(first[0]), int(first[1])), (int(cells[1]), int(cells[0]))


def segment_points(a, b, n=SEGMENT_POINTS):
    """n equally spaced points (n, 2) float64 [px] from a to b inclusive (the S_j of Eq. 4)."""
    a = np.asarray(a, dtype=float)
    return a + _fractions(n) * (np.asarray(b, dtype=float) - a)


@functools.lru_cache(maxsize=8)
def _fractions(n):
    """(n, 1): 0 … 1 in n equal steps (a linspace per evaluation was a tenth of the fitter's time)."""
    return np.linspace(0.0, 1.0, n)[:, None]


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


# The outline objective (beyond paper 000): the person's outline explained by the body model's capsules.
#
# Every bone is a capsule of radius R_b [m] around its projected segment (projected radius r = R_b·f/depth
# [px]). An outline point q belongs to the capsule it is nearest to, measured as d(q, segment) − r: 0 on
# that capsule's edge. Summed over the outline points with a robust (Cauchy) loss, this puts each bone
# midway between its part's two sides, as Eq. 4 does, without needing the outline labelled into parts,
# and whatever the radius: both sides are then equally far from the edge. It also sees what Eq. 4 cannot
# (the torso's yaw from the widths of hips and shoulders, the arms, which have no labelled sides). A
# terminal bone (head, forearm, shin) does not explain the outline beyond its end (hair, hand, foot).
# The second term keeps the segments inside the silhouette: the squared distance to it of points along
# each bone. Radii are generic adult ones (thickness varies with build and clothes; the midway property
# makes it matter little).
CAPSULE_RADII = {'torso': 0.13, 'head': 0.09, 'hip': 0.08, 'clavicle': 0.06, 'upper_arm': 0.05, 'forearm': 0.04,
                 'thigh': 0.07, 'shin': 0.05}   # [m], by bone name without side
TERMINAL_BONES = ('head', 'forearm', 'shin')
OUTLINE_STEP = 3           # every this many contour pixels is an outline point
OUTLINE_MARGIN_PX = 40     # the silhouette distance map reaches this far beyond the outline
INSIDE_SAMPLES = 8         # points per bone checked to lie inside the silhouette
EDGE_PX = 2                # contour pixels this near the image's edge are where the image cuts the person off


@dataclass(frozen=True)
class Outline:
    """One camera's outline for one frame: points (M, 2) float64 [px] (x, y), every OUTLINE_STEP-th pixel
    of the outer contour; outside: (H, W) float32 [px], each pixel's distance to the silhouette (0 inside),
    whose element [0, 0] is image pixel `origin` (x0, y0)."""
    points: np.ndarray
    outside: np.ndarray
    origin: tuple


def outline_of(contour_points, image_size=None, step=OUTLINE_STEP, margin=OUTLINE_MARGIN_PX, arena=None):
    """The Outline of an ordered closed contour (N, 2) [px] (x, y) (ContourLabels.points), its map in
    `arena` (a MapArena) if given; the silhouette is the contour's filled polygon (so the node, which
    receives only the contour, sees the same). With the image's (width, height) [px]: a person the image
    cuts off is seen only inside it, so the contour along the image's edge (within EDGE_PX) is not the
    person's outline and gives no outline points, and beyond the edge counts as inside the silhouette
    (unseen: a bone there costs nothing)."""
    points = np.asarray(contour_points)
    x0, y0 = points.min(axis=0) - margin
    x1, y1 = points.max(axis=0) + margin
    inside = np.zeros((y1 - y0 + 1, x1 - x0 + 1), np.uint8)
    cv2.drawContours(inside, [(points - (x0, y0)).reshape(-1, 1, 2).astype(np.int32)], -1, 1, cv2.FILLED)
    sampled = points[::step]
    if image_size is not None:
        width, height = image_size
        inside[:max(-y0, 0)] = 1
        inside[:, :max(-x0, 0)] = 1
        inside[max(height - y0, 0):] = 1
        inside[:, max(width - x0, 0):] = 1
        sampled = sampled[(sampled[:, 0] >= EDGE_PX) & (sampled[:, 0] < width - EDGE_PX)
                          & (sampled[:, 1] >= EDGE_PX) & (sampled[:, 1] < height - EDGE_PX)]
    outside = (arena or MapArena(inside.size)).take(inside.size).reshape(inside.shape)
    exact_distances(inside, outside)
    return Outline(sampled.astype(float), outside, (int(x0), int(y0)))


def capsule_residuals(points, starts, ends, radii, terminal):
    """d(q, segment) − r [px] (M, K) of points q (M, 2) to K projected capsules: segment starts and ends
    (K, 2) [px] (or (M, K, 2): each point its own capsules, e.g. those of its camera), radii (K,) or (M, K)
    [px], terminal (K,) bool (such a capsule gives +inf beyond its end)."""
    axis = ends - starts
    offset = points[:, None, :] - starts
    t = np.sum(offset * axis, axis=-1) / (np.sum(axis * axis, axis=-1) + 1e-9)
    gap = offset - np.clip(t, 0.0, 1.0)[..., None] * axis
    residuals = np.sqrt(np.sum(gap * gap, axis=-1)) - radii
    residuals[(t > 1.0) & terminal] = np.inf
    return residuals


def outline_cost(points, starts, ends, radii, terminal, scale, gate):
    """The outline term for the outline points assigned to K capsules: points (M, 2) [px], the rest as
    capsule_residuals. Each point's residual is that of its nearest capsule, at most `gate` [px] (an
    unexplained point costs a constant), under the Cauchy loss scale²·log(1 + (e/scale)²); each point
    stands for OUTLINE_STEP contour pixels. Returns the sum [px²]."""
    if not len(points):
        return 0.0
    nearest = np.minimum(capsule_residuals(points, starts, ends, radii, terminal).min(axis=1), gate)
    return OUTLINE_STEP * float(np.sum(cauchy_loss(nearest, scale)))


def cauchy_loss(residuals, scale):
    """scale²·log(1 + (e/scale)²) of residuals e [px] (any shape), the outline term's robust loss [px²]."""
    return scale ** 2 * np.log1p((residuals / scale) ** 2)


def outside_distances(outline, points):
    """Distances [px] (M,) of points (M, 2) [px] (x, y) outside one camera's Outline (0 inside the
    silhouette): the map's value at the nearest pixel of its box plus the distance to the box."""
    height, width = outline.outside.shape
    local = np.asarray(points, float) - outline.origin
    clamped = np.clip(local, 0, (width - 1, height - 1))
    pixel = np.rint(clamped).astype(int)
    return outline.outside[pixel[:, 1], pixel[:, 0]] + np.hypot(*(local - clamped).T)


def inside_cost(starts, ends, outline):
    """The sum of squared distances [px²] to the silhouette of one camera's Outline of INSIDE_SAMPLES points
    along each segment (starts, ends (K, 2) [px])."""
    samples = (starts[:, None] + _fractions(INSIDE_SAMPLES)[None] * (ends - starts)[:, None]).reshape(-1, 2)
    height, width = outline.outside.shape
    samples = np.clip(np.rint(samples - outline.origin), 0, (width - 1, height - 1)).astype(int)
    return float(np.sum(outline.outside[samples[:, 1], samples[:, 0]].astype(float) ** 2))


# ---------------------------------------------------------------- the exact distance transform (numba)

FAR = np.float32(1e15)   # OpenCV's "infinity" of the envelope (an exactly representable float32)


def exact_distances(seeds, out, scale=1.0):
    """Into out (H, W) float32: `scale` × the Euclidean distance [cells] from each cell to the nearest
    seed, seeds (H, W) uint8 nonzero at a seed (at least one). The square roots are correctly rounded;
    a scale that is a power of two (MAP_COARSENING) keeps them so."""
    if seeds.shape != out.shape or out.dtype != np.float32 or seeds.dtype != np.uint8:
        raise ValueError(f'exact_distances: seeds {seeds.dtype} {seeds.shape}, out {out.dtype} {out.shape}: '
                         'want uint8 seeds and a float32 out of one shape')
    if not seeds.any():
        raise ValueError(f'exact_distances: no seed in a map of {seeds.shape}')
    _transform(seeds, out, np.float32(scale))


@njit(cache=True, nogil=True, error_model='numpy')
def _transform(seeds, out, scale):
    """exact_distances without its checks."""
    rows, columns = seeds.shape
    # Along the columns, row by row: each cell's distance to the nearest seed at or below it (`below`,
    # rows or more: none), then to the nearest above or below (`along`, squared in f, per seeded column;
    # every column's, which the compiler turns into vector instructions, where the seeded ones alone,
    # gathered, were slower).
    below = np.empty((rows, columns), np.int32)
    along = np.full(columns, rows - 1, np.int32)
    for r in range(rows - 1, -1, -1):
        for c in range(columns):
            along[c] = 0 if seeds[r, c] else along[c] + 1
            below[r, c] = along[c]
    seeded = np.flatnonzero(along < rows)   # a column whose seeds are all beyond reach has none
    count = len(seeded)
    f = np.empty((rows, count), np.float32)
    along[:] = rows - 1
    for r in range(rows):
        for c in range(columns):
            along[c] = min(along[c] + 1, below[r, c])
        for a in range(count):
            d = along[seeded[a]]
            f[r, a] = np.float32(d * d)
    # Along the rows. A seed in the row itself is nearer than any seed beyond it, so the row's own seeds
    # split it into parts whose cells' nearest seeds lie within the part (its own seeds at its ends
    # included): the envelope is built per part, and none inside a run of seeds (a silhouette's inside).
    half_inverse = np.zeros(columns, np.float32)   # 0.5 / (q - p), rounded as OpenCV's table
    for c in range(1, columns):
        half_inverse[c] = np.float32(0.5 / c)
    z = np.empty(count + 1, np.float32)
    v = np.empty(count, np.int64)
    for r in range(rows):
        height, row = f[r], out[r]
        low, first = 0, 0   # the part's first seeded column (index into `seeded`) and first cell
        for a in range(count + 1):
            if a < count and height[a] != 0:
                continue
            if a < count and a > 0 and low == a - 1 and height[low] == 0 and seeded[a] == seeded[low] + 1:
                row[seeded[a]] = 0.0   # within a run of the row's seeds
            else:
                last = columns - 1 if a == count else seeded[a]
                _envelope(height, seeded, low, min(a, count - 1), first, last, row, scale, half_inverse, z, v)
            if a < count:
                low, first = a, seeded[a] + 1


@njit(cache=True, nogil=True, error_model='numpy')
def _envelope(height, seeded, low, high, first, last, row, scale, half_inverse, z, v):
    """Into row[first … last]: scale × the distance to the lowest of the parabolas (q − p)² + height[a] of the
    seeded columns p = seeded[a], a = low … high, by their lower envelope: segment k (parabola v[k]) is the
    lowest from z[k] to z[k + 1]."""
    v[0], z[0], z[1] = low, -FAR, FAR
    k = 0
    for a in range(low + 1, high + 1):
        q = seeded[a]
        while True:
            p = seeded[v[k]]
            s = (height[a] + np.float32(q * q) - height[v[k]] - np.float32(p * p)) * half_inverse[q - p]
            if s > z[k]:
                k += 1
                v[k], z[k], z[k + 1] = a, s, FAR
                break
            k -= 1
    for segment in range(k + 1):
        end = last if z[segment + 1] >= last else int(np.floor(z[segment + 1]))
        p, floor = np.int32(seeded[v[segment]]), height[v[segment]]
        for q in range(first, end + 1):
            offset = np.int32(q - p)
            row[q] = np.sqrt(np.float32(offset * offset) + floor) * scale
        first = max(first, end + 1)
