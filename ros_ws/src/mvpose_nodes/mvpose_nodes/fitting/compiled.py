"""The stage objective compiled with numba (its forward kinematics: compiled_kinematics.py): what the
Nelder–Mead searches (compiled_search.py) evaluate.

StageSearch.stage_cost (stage_search.py, with objective.py) is the readable numpy reference of a
stage's objective; `stage_objective` here computes the same number in one compiled call, which equals
the reference to 1e-9 (relative; tests/test_compiled.py on random poses). A search evaluates the
objective 50–150 times per stage; in numpy most of each evaluation's ~300 µs was the interpreter's
overhead of some hundred small array operations, compiled it is a few µs.

The frame's evidence is packed once per frame (`pack_frame`: cameras, silhouette maps and boundary
maps, flattened into one buffer each) and a stage's once per search (`StageSearch.stage_pack`: its
outline points, keypoint targets, bones, priors), so an evaluation passes only the trial values. Compiled functions are
cached on disk (numba's cache=True; ./mvpose sets NUMBA_CACHE_DIR to .venv/numba-cache), so only the
first run on a machine compiles (about 20 s; fitter.warm_up does it at a node's start, not in its first
fit). They release the GIL (nogil), so the node's executor thread takes messages while a search runs.
Units and axes as in objective.py: pixels x right, y down; metres; radians.
"""
from typing import NamedTuple

import numpy as np
from numba import njit

from mvpose_nodes.fitting import numba_cache  # noqa: F401  (first: the cache folder of this version's sources)
from mvpose_nodes.body.model import LABEL_HEAD, LABEL_LEFT_LEG, LABEL_RIGHT_LEG, LABEL_TORSO
from mvpose_nodes.fitting.compiled_kinematics import CHAIN_END, CHAIN_START, forward_joints, twist_excess
from mvpose_nodes.fitting.objective import (BILINEAR_STEPS, INSIDE_SAMPLES, MAP_COARSENING, OUTLINE_STEP,
                                            SEGMENT_POINTS, _fractions)
from mvpose_nodes.vision.contour import SIDE_A, SIDE_B

MAP_LABELS = (LABEL_TORSO, LABEL_HEAD, LABEL_LEFT_LEG, LABEL_RIGHT_LEG)  # the parts with labelled bones
LABEL_SLOT = {label: slot for slot, label in enumerate(MAP_LABELS)}
STEP_BITS = BILINEAR_STEPS.bit_length() - 1   # log2 of BILINEAR_STEPS, a power of two
INSIDE_MARGIN = 1e-6   # [map cells] far above the rounding of a segment's points (1e-12 for a map of 1e4 cells)

class FramePack(NamedTuple):
    """One frame's views for the compiled objective (V views, in the order of the fitter's view list).

    K, R: (V, 3, 3); t: (V, 3); D: (V, 5) plumb_bob (body.camera.Camera). Silhouette maps
    (objective.Outline.outside): has_outline (V,) bool, outside (N,) float32 the views' maps flattened one
    after the other, outside_at (V,) each one's first index, outside_shape (V, 2) (height, width),
    outside_origin (V, 2) (x0, y0) [px]. Boundary maps (objective.BoundaryDistances) of MAP_LABELS: slot
    (V, 4) bool (the part has both sides), boundary (M,) float32 the views' BoundaryDistances.buffer (one
    after the other, unless they share one), boundary_at (V, 4, 2) each side's map's first index in it,
    boundary_shape (V, 4, 2) (height, width) on the MAP_COARSENING grid and boundary_origin (V, 4, 2)
    (x0, y0) [px] of the part's maps (its two sides share one box), boundary_width (V, 4) [px]. The views'
    outline points (objective.Outline.points, for the assignment: outline_nearest): outline_x, outline_y
    (P,) [px] one view's after the other, outline_range (V, 2) each view's first and last + 1 index."""
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    D: np.ndarray
    has_outline: np.ndarray
    outside: np.ndarray
    outside_at: np.ndarray
    outside_shape: np.ndarray
    outside_origin: np.ndarray
    slot: np.ndarray
    boundary: np.ndarray
    boundary_at: np.ndarray
    boundary_shape: np.ndarray
    boundary_origin: np.ndarray
    boundary_width: np.ndarray
    outline_x: np.ndarray
    outline_y: np.ndarray
    outline_range: np.ndarray


class StagePack(NamedTuple):
    """One stage's search in arrays. indices (n,): the parameters searched; base (29,): the others'
    values; start, steps (n,) and low, high (n,) (±inf: no limit) for the priors; capsules (K,) bone
    indices, capsule_radius (K,) [m], capsule_terminal (K,) bool; assigned (V,) bool (the view has an
    outline assignment), points (P, 2) [px] and point_view (P,) the assigned outline points, grouped by
    view in view order; bones (B,) bone indices with labelled boundaries and bone_slot (B,) their MAP_LABELS
    slot; keypoint_view, keypoint_joint (Q,), keypoint_xy (Q, 2) [px], keypoint_weight (Q,); the limbs' twist and lateral limits
    (stage_search.twist_arrays: twist_bones (T,), twist_reference, twist_neutral (T, 3), twist_low,
    twist_high (T,) [rad], twist_hinge (T,), lateral_low, lateral_high (T,) [rad]); weights (10,): enclosure, outline,
    inside, outline scale, outline gate, boundary, keypoint, keypoint scale, smoothness, limit
    (FitterSettings)."""
    indices: np.ndarray
    base: np.ndarray
    start: np.ndarray
    steps: np.ndarray
    low: np.ndarray
    high: np.ndarray
    capsules: np.ndarray
    capsule_radius: np.ndarray
    capsule_terminal: np.ndarray
    assigned: np.ndarray
    points: np.ndarray
    point_view: np.ndarray
    bones: np.ndarray
    bone_slot: np.ndarray
    keypoint_view: np.ndarray
    keypoint_joint: np.ndarray
    keypoint_xy: np.ndarray
    keypoint_weight: np.ndarray
    twist_bones: np.ndarray
    twist_reference: np.ndarray
    twist_neutral: np.ndarray
    twist_low: np.ndarray
    twist_high: np.ndarray
    twist_hinge: np.ndarray
    lateral_low: np.ndarray
    lateral_high: np.ndarray
    weights: np.ndarray


def _joined(buffers):
    """One float32 array holding the arrays in `buffers` (None: none), and each one's start in it: without
    a copy when they all lie in one contiguous float32 array (a MapArena's, or one and the same array),
    else their concatenation."""
    present = [b for b in buffers if b is not None]
    if not present:
        return np.zeros(0, np.float32), [0] * len(buffers)
    roots = {id(_root(b)): _root(b) for b in present}
    if len(roots) == 1:
        root = next(iter(roots.values()))
        if root.dtype == np.float32 and root.flags.c_contiguous and all(b.flags.c_contiguous for b in present):
            first, flat = root.ctypes.data, root if root.ndim == 1 else root.reshape(-1)
            return flat, [(b.ctypes.data - first) // root.itemsize if b is not None else 0 for b in buffers]
    distinct = {id(b): b for b in present}
    starts, total = {}, 0
    for key, buffer in distinct.items():
        starts[key] = total
        total += buffer.size
    joined = np.concatenate([b.ravel() for b in distinct.values()])
    return joined, [starts[id(b)] if b is not None else 0 for b in buffers]


def _root(array):
    """The array that owns the memory `array` views (itself if it owns it)."""
    while array.base is not None and isinstance(array.base, np.ndarray):
        array = array.base
    return array


def pack_frame(views):
    """The FramePack of a list of fitter.View."""
    count, labels = len(views), len(MAP_LABELS)
    outside, outside_at = _joined([v.outline.outside if v.outline is not None else None for v in views])
    boundary, boundary_start = _joined([v.distances.buffer if v.distances is not None else None for v in views])
    slot, width, at = np.zeros((count, labels), np.bool_), np.zeros((count, labels)), np.zeros((count, labels, 2), np.int64)
    shape, origin = np.zeros((count, labels, 2), np.int64), np.zeros((count, labels, 2))
    for v, view in enumerate(views):
        distances = view.distances
        if distances is None:
            continue
        for k, label in enumerate(MAP_LABELS):
            if label not in distances.widths:
                continue
            slot[v, k], width[v, k] = True, distances.widths[label]
            origin[v, k], shape[v, k] = distances.origins[label], distances.maps[(label, SIDE_A)].shape
            at[v, k] = (boundary_start[v] + distances.offsets[(label, SIDE_A)],
                        boundary_start[v] + distances.offsets[(label, SIDE_B)])
    points = [v.outline.points if v.outline is not None else np.zeros((0, 2)) for v in views]
    ends = np.cumsum([len(p) for p in points], dtype=np.int64)
    points = np.concatenate(points).reshape(-1, 2) if points else np.zeros((0, 2))
    return FramePack(
        np.array([v.camera.K for v in views], np.float64).reshape(count, 3, 3),
        np.array([v.camera.R for v in views], np.float64).reshape(count, 3, 3),
        np.array([v.camera.t for v in views], np.float64).reshape(count, 3),
        np.array([v.camera.D for v in views], np.float64).reshape(count, 5),
        np.array([v.outline is not None for v in views], np.bool_), outside, np.array(outside_at, np.int64),
        np.array([v.outline.outside.shape if v.outline is not None else (0, 0) for v in views], np.int64).reshape(count, 2),
        np.array([v.outline.origin if v.outline is not None else (0, 0) for v in views], np.float64).reshape(count, 2),
        slot, boundary, at, shape, origin, width, np.ascontiguousarray(points[:, 0], np.float64),
        np.ascontiguousarray(points[:, 1], np.float64), np.column_stack([np.r_[0, ends[:-1]], ends]).astype(np.int64))


@njit(cache=True, nogil=True, error_model='numpy')
def _project(frame, view, joints):
    """body.camera.Camera.project of joints (J, 3) in view `view`: pixels (J, 2), depths (J,)."""
    return _project_camera(frame.K[view], frame.R[view], frame.t[view], frame.D[view], joints)


@njit(cache=True, nogil=True, error_model='numpy')
def _project_camera(K, R, t, D, joints):
    """body.camera.Camera.project of joints (J, 3) by the camera K, R (3, 3), t (3,), D (5,): pixels (J, 2),
    depths (J,)."""
    count = joints.shape[0]
    pixels, depth = np.empty((count, 2)), np.empty(count)
    distorted = D[0] != 0 or D[1] != 0 or D[2] != 0 or D[3] != 0 or D[4] != 0
    for j in range(count):
        X, Y, Z = joints[j, 0], joints[j, 1], joints[j, 2]
        cx = R[0, 0] * X + R[0, 1] * Y + R[0, 2] * Z + t[0]
        cy = R[1, 0] * X + R[1, 1] * Y + R[1, 2] * Z + t[1]
        cz = R[2, 0] * X + R[2, 1] * Y + R[2, 2] * Z + t[2]
        depth[j] = cz
        x, y = cx / cz, cy / cz
        if distorted:
            r2 = x * x + y * y
            radial = 1 + r2 * (D[0] + r2 * (D[1] + r2 * D[4]))
            x, y = (x * radial + 2 * D[2] * x * y + D[3] * (r2 + 2 * x * x),
                    y * radial + D[2] * (r2 + 2 * y * y) + 2 * D[3] * x * y)
        pixels[j, 0] = x * K[0, 0] + y * K[0, 1] + K[0, 2]
        pixels[j, 1] = x * K[1, 0] + y * K[1, 1] + K[1, 2]
    return pixels, depth


@njit(cache=True, nogil=True, error_model='numpy')
def _on_grid(offset):
    """An image pixel's position [px] from a map's box origin, in the map's cells on the MAP_COARSENING grid
    (pixel centres; objective.bilinear's `grid`)."""
    return (offset + 0.5) / MAP_COARSENING - 0.5


@njit(cache=True, nogil=True, error_model='numpy')
def _bilinear(buffer, at, height, width, x, y):
    """objective.bilinear of one (height, width) map on the MAP_COARSENING grid, flattened in `buffer` from
    index `at`, at a point (x, y) [px] in image pixels from the map's box origin: bilinear inside, the
    nearest edge value plus the distance outside."""
    gx, gy = _on_grid(x), _on_grid(y)
    cx, cy = min(max(gx, 0.0), width - 1.0), min(max(gy, 0.0), height - 1.0)
    qx, qy = int(np.rint(cx * BILINEAR_STEPS)), int(np.rint(cy * BILINEAR_STEPS))
    x0, y0 = qx // BILINEAR_STEPS, qy // BILINEAR_STEPS
    x1, y1 = min(x0 + 1, width - 1), min(y0 + 1, height - 1)
    fx, fy = (qx % BILINEAR_STEPS) / BILINEAR_STEPS, (qy % BILINEAR_STEPS) / BILINEAR_STEPS
    return (_corners(buffer, at, y0 * width + x0, y0 * width + x1, y1 * width + x0, y1 * width + x1, fx, fy)
            + MAP_COARSENING * np.hypot(gx - cx, gy - cy))


@njit(cache=True, nogil=True, error_model='numpy')
def _corners(buffer, at, i00, i01, i10, i11, fx, fy):
    """The bilinear interpolation at fractions fx, fy [0, 1) between a map's four values at indices
    at + i00 (top left), i01 (top right), i10, i11 (bottom left, right) of `buffer`."""
    v00 = np.float64(buffer[at + i00])
    v01 = np.float64(buffer[at + i01])
    v10 = np.float64(buffer[at + i10])
    v11 = np.float64(buffer[at + i11])
    top = v00 + fx * (v01 - v00)
    bottom = v10 + fx * (v11 - v10)
    return top + fy * (bottom - top)


@njit(cache=True, nogil=True, error_model='numpy')
def _segment_inside(a, b, origin_x, origin_y, height, width):
    """Whether both ends of the segment a–b (2,) [px] lie inside a (height, width) map on the
    MAP_COARSENING grid whose box starts at image pixel (origin_x, origin_y), by over INSIDE_MARGIN of a
    map cell: then every point between does too, however the arithmetic rounds."""
    for end in range(2):
        x, y = (a[0], a[1]) if end == 0 else (b[0], b[1])
        gx, gy = _on_grid(x - origin_x), _on_grid(y - origin_y)
        if not (INSIDE_MARGIN < gx < width - 1.0 - INSIDE_MARGIN and INSIDE_MARGIN < gy < height - 1.0 - INSIDE_MARGIN):
            return False
    return True


@njit(cache=True, nogil=True, error_model='numpy')
def _inside_lookups(buffer, at_a, at_b, height, width, a, b, origin_x, origin_y, fractions, d1, d2):
    """_bilinear of a part's two maps (their first indices at_a, at_b: one box, one shape) at the points
    a + f·(b − a) [px] (f in fractions (N,)) of a segment that _segment_inside found inside the map, into d1
    and d2 (N,): the same numbers as _bilinear's, computed for both maps at once and without its clamping
    (nothing to clamp; the distance beyond the map is 0), so that the loop compiles to vector instructions."""
    for s in range(len(fractions)):
        x = a[0] + fractions[s] * (b[0] - a[0]) - origin_x
        y = a[1] + fractions[s] * (b[1] - a[1]) - origin_y
        gx, gy = _on_grid(x), _on_grid(y)
        qx, qy = np.int64(np.rint(gx * BILINEAR_STEPS)), np.int64(np.rint(gy * BILINEAR_STEPS))
        x0, y0 = qx >> STEP_BITS, qy >> STEP_BITS   # qx, qy >= 0: // and % by BILINEAR_STEPS
        fx, fy = (qx & (BILINEAR_STEPS - 1)) / BILINEAR_STEPS, (qy & (BILINEAR_STEPS - 1)) / BILINEAR_STEPS
        x1, y1 = min(x0 + 1, width - 1), min(y0 + 1, height - 1)
        i00, i01, i10, i11 = y0 * width + x0, y0 * width + x1, y1 * width + x0, y1 * width + x1
        d1[s] = _corners(buffer, at_a, i00, i01, i10, i11, fx, fy) + 0.0   # _bilinear's sum, hypot(0, 0) = 0
        d2[s] = _corners(buffer, at_b, i00, i01, i10, i11, fx, fy) + 0.0


@njit(cache=True, nogil=True, error_model='numpy')
def _capsule_residuals(xs, ys, start, end, radius, terminal, out):
    """objective.capsule_residuals of the points (xs, ys) (M,) [px] and one capsule, into out (M,): each
    point's distance to the segment start–end (2,) [px] less the radius [px]; inf beyond the end of a
    terminal capsule. Branch-free, so that the loop compiles to vector instructions."""
    ax, ay = end[0] - start[0], end[1] - start[1]
    length2 = ax * ax + ay * ay + 1e-9
    beyond_end = np.inf if terminal else -np.inf   # max(residual, beyond_end): inf, or the residual
    for p in range(len(xs)):
        ox, oy = xs[p] - start[0], ys[p] - start[1]
        along = (ox * ax + oy * ay) / length2
        clamped = min(max(along, 0.0), 1.0)
        gx, gy = ox - clamped * ax, oy - clamped * ay
        residual = np.sqrt(gx * gx + gy * gy) - radius
        out[p] = max(residual, beyond_end) if along > 1.0 else residual


@njit(cache=True, nogil=True, error_model='numpy')
def stage_objective(values, stage, frame, bone_lengths, fractions, samples, used):
    """The stage's objective (StageSearch.search's cost: stage_cost plus the priors) at `values` (n,) of
    its parameters. stage: StagePack; frame: FramePack; bone_lengths (14,) [m]; fractions
    (SEGMENT_POINTS,) and samples (INSIDE_SAMPLES,): objective._fractions; used (V,) bool, set where a view
    contributed. Returns the cost (the reference's units: px and px² under the settings' weights)."""
    point_range, work = work_arrays(stage, frame, fractions)
    return evaluate(values, stage, frame, bone_lengths, fractions, samples, used, point_range, work)


@njit(cache=True, nogil=True, error_model='numpy')
def work_arrays(stage, frame, fractions):
    """What an evaluation of stage_objective needs beside its arguments, made once per search: each view's
    outline points' first and last + 1 index (V, 2) (StagePack.points are grouped by view) and a (6, M)
    float64 work array: the points' x and y (rows 1, 2, contiguous for vector instructions) and room for
    one view's nearest residuals (row 0), one segment's look-ups (rows 3, 4) and one capsule's residuals
    (row 5)."""
    views, count = frame.K.shape[0], len(stage.point_view)
    point_range = np.zeros((views, 2), np.int64)
    for p in range(count):
        v = stage.point_view[p]
        if p and v < stage.point_view[p - 1]:
            raise ValueError('StagePack.point_view must be grouped by view, in view order')
        if point_range[v, 1] == 0:
            point_range[v, 0] = p
        point_range[v, 1] = p + 1
    work = np.empty((6, max(count, len(fractions))))
    work[1, :count] = stage.points[:, 0]
    work[2, :count] = stage.points[:, 1]
    return point_range, work


@njit(cache=True, nogil=True, error_model='numpy')
def evaluate(values, stage, frame, bone_lengths, fractions, samples, used, point_range, work):
    """stage_objective with its work_arrays given (compiled_search.nelder_mead makes them once per search)."""
    w = stage.weights
    parameters = stage.base.copy()
    smoothness = limits = 0.0
    for i in range(len(stage.indices)):
        parameters[stage.indices[i]] = values[i]
        step = (values[i] - stage.start[i]) / stage.steps[i]
        smoothness += step * step
        beyond = max(stage.low[i] - values[i], 0.0) + max(values[i] - stage.high[i], 0.0)
        limits += beyond * beyond
    for i in range(len(stage.twist_bones)):
        limits += twist_excess(parameters, stage.twist_bones[i], stage.twist_reference[i], stage.twist_neutral[i],
                               stage.twist_low[i], stage.twist_high[i], stage.twist_hinge[i],
                               stage.lateral_low[i], stage.lateral_high[i])
    joints = forward_joints(parameters, bone_lengths)
    total = 0.0
    outline = 0.0
    views = frame.K.shape[0]
    capsule_count = len(stage.capsules)
    for v in range(views):
        used[v] = False
        pixels, depth = _project(frame, v, joints)
        # The outline term and the inside term (objective.outline_cost, inside_cost).
        usable = stage.assigned[v] and frame.has_outline[v]
        for k in range(capsule_count):
            bone = stage.capsules[k]
            if depth[CHAIN_START[bone]] <= 0 or depth[CHAIN_END[bone]] <= 0:
                usable = False
        if usable:
            used[v] = True
            starts, ends, radii = np.empty((capsule_count, 2)), np.empty((capsule_count, 2)), np.empty(capsule_count)
            height, width = frame.outside_shape[v, 0], frame.outside_shape[v, 1]
            inside = 0.0
            for k in range(capsule_count):
                a, b = CHAIN_START[stage.capsules[k]], CHAIN_END[stage.capsules[k]]
                starts[k, :] = pixels[a]
                ends[k, :] = pixels[b]
                radii[k] = stage.capsule_radius[k] * frame.K[v, 0, 0] / max(0.5 * (depth[a] + depth[b]), 0.1)
                for s in range(len(samples)):
                    px = np.rint(starts[k, 0] + samples[s] * (ends[k, 0] - starts[k, 0]) - frame.outside_origin[v, 0])
                    py = np.rint(starts[k, 1] + samples[s] * (ends[k, 1] - starts[k, 1]) - frame.outside_origin[v, 1])
                    column = int(min(max(px, 0.0), width - 1.0))
                    row = int(min(max(py, 0.0), height - 1.0))
                    d = np.float64(frame.outside[frame.outside_at[v] + row * width + column])
                    inside += d * d
            total += w[2] * inside
            # Capsule by capsule over the view's points (vector instructions).
            first, last = point_range[v, 0], point_range[v, 1]
            count = last - first
            nearest, residuals = work[0, :count], work[5, :count]
            nearest[:] = np.inf
            for k in range(capsule_count):
                _capsule_residuals(work[1, first:last], work[2, first:last], starts[k], ends[k], radii[k],
                                   stage.capsule_terminal[k], residuals)
                for p in range(count):
                    nearest[p] = min(nearest[p], residuals[p])
            for p in range(count):
                e = min(nearest[p], w[4]) / w[3]
                outline += w[3] * w[3] * np.log1p(e * e)
        # Eq. 4–5 with the enclosure term for the stage's labelled bones (objective.limb_cost).
        for i in range(len(stage.bones)):
            a, b = CHAIN_START[stage.bones[i]], CHAIN_END[stage.bones[i]]
            slot = stage.bone_slot[i]
            if depth[a] <= 0 or depth[b] <= 0 or not frame.slot[v, slot]:
                continue
            used[v] = True
            at_a, at_b = frame.boundary_at[v, slot, 0], frame.boundary_at[v, slot, 1]
            height, width = frame.boundary_shape[v, slot, 0], frame.boundary_shape[v, slot, 1]
            ox, oy = frame.boundary_origin[v, slot, 0], frame.boundary_origin[v, slot, 1]
            sum1 = sum2 = enclosure = 0.0
            within = _segment_inside(pixels[a], pixels[b], ox, oy, height, width)   # nearly always
            if within:
                _inside_lookups(frame.boundary, at_a, at_b, height, width, pixels[a], pixels[b], ox, oy, fractions,
                                work[3], work[4])
            for s in range(len(fractions)):
                if within:
                    d1, d2 = work[3, s], work[4, s]
                else:
                    x = pixels[a, 0] + fractions[s] * (pixels[b, 0] - pixels[a, 0]) - ox
                    y = pixels[a, 1] + fractions[s] * (pixels[b, 1] - pixels[a, 1]) - oy
                    d1 = _bilinear(frame.boundary, at_a, height, width, x, y)
                    d2 = _bilinear(frame.boundary, at_b, height, width, x, y)
                sum1 += d1
                sum2 += d2
                enclosure += max(d1 + d2 - frame.boundary_width[v, slot], 0.0)
            total += w[5] * (abs(sum1 - sum2) + w[0] * enclosure)
        # The keypoints' robust reprojection distance.
        for q in range(len(stage.keypoint_view)):
            if stage.keypoint_view[q] != v:
                continue
            used[v] = True
            j = stage.keypoint_joint[q]
            error = np.hypot(pixels[j, 0] - stage.keypoint_xy[q, 0], pixels[j, 1] - stage.keypoint_xy[q, 1])
            total += w[6] * w[7] * stage.keypoint_weight[q] * np.log1p(error / w[7])
    total += w[1] * OUTLINE_STEP * outline
    return total + w[8] * smoothness + w[9] * limits


def fractions_arrays():
    """(SEGMENT_POINTS,), (INSIDE_SAMPLES,) float64: objective._fractions, the S_j and inside samples' positions."""
    return np.ascontiguousarray(_fractions(SEGMENT_POINTS)[:, 0]), np.ascontiguousarray(_fractions(INSIDE_SAMPLES)[:, 0])


@njit(cache=True, nogil=True, error_model='numpy')
def nearest_capsules(points, starts, ends, radii, terminal):
    """For each point (M, 2) [px] its nearest of K projected capsules and the residual there, as the
    minimum over objective.capsule_residuals(points, starts, ends, radii, terminal) (its argument shapes
    (K, 2), (K,)): (indices (M,) int64, residuals (M,) [px]; inf where every capsule is terminal and
    ends before the point)."""
    count = points.shape[0]
    nearest, residual = np.zeros(count, np.int64), np.full(count, np.inf)
    _nearest_into(points[:, 0].copy(), points[:, 1].copy(), starts, ends, radii, terminal, nearest, residual,
                  np.empty(count))   # x and y contiguous
    return nearest, residual


@njit(cache=True, nogil=True, error_model='numpy')
def _nearest_into(xs, ys, starts, ends, radii, terminal, nearest, residual, distances):
    """nearest_capsules of the points (xs, ys) (M,) into nearest and residual (M,) (set beforehand to 0 and
    inf), with `distances` (M,) for one capsule's residuals."""
    for k in range(starts.shape[0]):
        _capsule_residuals(xs, ys, starts[k], ends[k], radii[k], terminal[k], distances)
        for p in range(len(xs)):
            if distances[p] < residual[p]:
                nearest[p], residual[p] = k, distances[p]


@njit(cache=True, nogil=True, error_model='numpy')
def outline_nearest(parameters, bone_lengths, capsule_radius, capsule_terminal, gate, K, R, t, D, outline_x,
                    outline_y, outline_range):
    """For each outline point of a frame's views (FramePack's outline_x, outline_y, outline_range and
    cameras K, R, t, D) its nearest of the pose's 14 projected capsules (stage_search.projected_capsules of
    every bone: capsule_radius (14,) [m] at the bone's mean depth, capsule_terminal (14,) bool) and whether
    it lies within `gate` [px] of it, as nearest_capsules gives them view by view: (indices into BONES (P,)
    int64, within (P,) bool). The pose: parameters (29,), bone_lengths (14,) [m]."""
    joints = forward_joints(parameters, bone_lengths)
    count = len(outline_x)
    nearest, residual = np.zeros(count, np.int64), np.full(count, np.inf)
    for v in range(K.shape[0]):
        first, last = outline_range[v, 0], outline_range[v, 1]
        if last <= first:
            continue
        pixels, depth = _project_camera(K[v], R[v], t[v], D[v], joints)
        mean_depth = np.maximum(0.5 * (depth[CHAIN_START] + depth[CHAIN_END]), 0.1)
        _nearest_into(outline_x[first:last], outline_y[first:last], pixels[CHAIN_START], pixels[CHAIN_END],
                      capsule_radius * K[v, 0, 0] / mean_depth, capsule_terminal, nearest[first:last],
                      residual[first:last], np.empty(last - first))
    return nearest, np.abs(residual) < gate
