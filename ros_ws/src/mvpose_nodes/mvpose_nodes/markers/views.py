"""Marker mode across cameras (beyond paper 001, which tracks in one 2D view): the cameras' 2D marker
tracks of one frame fused into 3D markers, and each camera's tracks corrected from them.

Per frame (`MarkerViews.fuse`):

1. Each marker's 3D point from the cameras whose tracker detected it. Every pair of those views is
   triangulated (DLT, triangulation.triangulate); a view agrees with a point when its viewing ray passes
   within `agreement_m` of it (a distance in metres at the marker, the same for near and far cameras).
   The pair with the most agreeing views wins, ties going to the point nearer the marker's predicted
   position; the point is then triangulated again from all the views that agree. A view that disagrees
   has given the marker another marker's blob (an identity swap in that view). Refused: a point farther
   from the prediction than `jump_gate_m` (limbs; `two_view_jump_gate_m` when only two views agree) or
   `region_jump_gate_m` (the smoothly moving torso and head), more the longer the marker has gone
   without two views (two views that made the same mistake, or a wrong blob along their epipolar line);
   a limb marker off its distance from its parent marker (`bone_tolerance_m`, doubled); a region marker
   that breaks its region's shape at the start (`shape_tolerance_m`).
2. A marker without two agreeing views is predicted: a region marker (markers.REGIONS) moves with the
   mean 3D displacement of its region's triangulated markers (the head with the shoulders'), the 3D form
   of paper 001's region displacement, or at constant velocity (damped) when none is; a limb marker is
   carried by its parent, at its distance from it (velocities run away over long occlusions). One
   detecting view then pulls the prediction onto its ray: the ray's point nearest to it when within
   `single_view_gate_m`, or, for a limb marker lost a frame or more, the point where the ray meets its
   parent's shell.
3. In each camera, the 15 points are projected and the image's red blobs (all of them, assigned by its
   tracker or not) are paired with the projections by the Hungarian method, each gated at `blob_gate_m`
   (`predicted_blob_gate_m` for a predicted marker) at the marker's depth: a blob's identity is now the
   one that agrees with the other views. A paired marker is DETECTED at its blob; an unpaired one is
   PREDICTED at its projection (the prediction the paper makes in 2D, here from the other views).
   Blobs that no marker claimed get lost markers back (`_reacquire`): those meeting in two or more
   views, and, for a lost limb marker, a single view's blob whose ray meets its parent's shell.
4. Steps 1 and 3 run twice: the second time from the blobs as re-assigned in step 3.

The result goes back to each camera's tracker (markers._TrackerBase.correct), so the next frame's
search starts from positions the views agree on. Points in metres (world frame, camera.py), pixels as
in markers.py. Pure NumPy/OpenCV/SciPy: no ROS.
"""
import itertools
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from mvpose_nodes.markers.detection import FLAG_DETECTED, FLAG_LOST, FLAG_PREDICTED, MARKER_NAMES, REGION_INDICES
from mvpose_nodes.markers.regions import UNASSIGNABLE, gated_assignment
from mvpose_nodes.markers.tracking import MarkerTracker
from mvpose_nodes.body.triangulation import dlt_point, triangulate

# The region whose motion carries each region marker when it cannot be triangulated: its own region,
# except the head (one marker), which moves with the shoulders.
CARRIER_REGION = {index: ('shoulders' if region == 'head' else region)
                  for region, indices in REGION_INDICES.items() for index in indices}
REGION_MARKERS = tuple(sorted(CARRIER_REGION))
# Each limb marker's parent along the body (body_model's tree); parents come first.
LIMB_PARENT = {MARKER_NAMES.index(child): MARKER_NAMES.index(parent) for child, parent in (
    ('left_elbow', 'left_shoulder'), ('right_elbow', 'right_shoulder'), ('left_knee', 'left_hip'),
    ('right_knee', 'right_hip'), ('left_wrist', 'left_elbow'), ('right_wrist', 'right_elbow'),
    ('left_ankle', 'left_knee'), ('right_ankle', 'right_knee'))}
LIMB_MARKERS = tuple(LIMB_PARENT)


@dataclass(frozen=True)
class ViewSettings:
    agreement_m: float = 0.03        # a view agrees with a 3D point when its ray passes this close [m]
    jump_gate_m: float = 0.3         # a limb marker's point this far from the prediction is refused [m] (plus
                                     # reacquire_growth_m per frame the marker has gone without two views)
    two_view_jump_gate_m: float = 0.05  # ... a limb marker's seen by two views only [m] (a wrong blob
                                        # along their epipolar line makes a consistent pair)
    region_jump_gate_m: float = 0.1  # ... a region marker's (the torso moves smoothly) [m]
    single_view_gate_m: float = 0.15  # one view's ray moves the prediction onto it when this close [m]
    blob_gate_m: float = 0.04        # a blob is paired with a triangulated marker's projection within this,
                                     # at the marker's depth [m] ...
    predicted_blob_gate_m: float = 0.09  # ... with a predicted marker's (one or no view) within this [m]
    shape_tolerance_m: float = 0.04  # two region markers stay this close to their distance at the start [m]
    bone_tolerance_m: float = 0.05   # a limb marker stays this close to its first distance from its parent [m]
    reacquire_gate_m: float = 0.5    # a marker takes unclaimed blobs' 3D point at most this far from its estimate [m]
    reacquire_growth_m: float = 0.03  # ... the gate widening by this per frame without two views [m]
    velocity_damping: float = 0.5    # a marker's velocity shrinks by this each frame it is not triangulated
    max_predicted_frames: int = 25   # a marker without any detecting view for longer is FLAG_LOST


class MarkerViews:
    """The 3D markers of C calibrated cameras, frame after frame.

    `points` (15, 3) float64 [m] after each call; `support` (15,) int: the views the point was
    triangulated from (0 or 1: predicted)."""

    def __init__(self, cameras, settings=ViewSettings()):
        self.cameras = list(cameras)
        self.settings = settings
        self.points = self.velocity = self.lengths = None
        self.support = np.zeros(len(MARKER_NAMES), int)
        self.predicted_run = np.zeros(len(MARKER_NAMES), int)
        self.unsupported_run = np.zeros(len(MARKER_NAMES), int)

    def start(self, positions, flags):
        """The first frame: positions (C, 15, 2) [px] and flags (C, 15) of the initial labelling; each
        marker triangulated from every view that places it (FLAG_LOST excepted), hidden ones included.
        Returns points (15, 3) [m]; NaN rows for markers placed in fewer than 2 views."""
        positions, flags = np.asarray(positions, float), np.asarray(flags)
        points = np.full((len(MARKER_NAMES), 3), np.nan)
        for marker in range(len(MARKER_NAMES)):
            found = triangulate(self.cameras, positions[:, marker], (flags[:, marker] != FLAG_LOST).astype(float))
            if found is not None:
                points[marker] = found[0]
        self.points, self.velocity = points, np.zeros_like(points)
        self.distances = np.linalg.norm(points[:, None] - points[None], axis=2)   # NaN where not placed
        self.lengths = np.full(len(MARKER_NAMES), np.nan)
        for child, parent in LIMB_PARENT.items():
            self.lengths[child] = np.linalg.norm(points[child] - points[parent])
        self.support = (flags == FLAG_DETECTED).sum(axis=0)
        self.predicted_run[:] = 0
        self.unsupported_run[:] = 0
        return points.copy()

    def fuse(self, positions, flags, blobs=None):
        """One frame. positions (C, 15, 2) [px] and flags (C, 15) FLAG_*: each camera's tracks; blobs: per
        camera the (N_c, 2) [px] red blobs of its image (None: the tracks' detected positions). Returns
        (points (15, 3) [m], positions (C, 15, 2) [px], flags (C, 15) uint8): the 3D markers and every
        camera's tracks corrected by them."""
        if self.points is None:
            raise RuntimeError('start() first')
        positions, flags = np.asarray(positions, float), np.asarray(flags)
        if blobs is None:
            blobs = [positions[c][flags[c] == FLAG_DETECTED] for c in range(len(self.cameras))]
        predicted = self.points + self.velocity
        observed, detected = positions, flags == FLAG_DETECTED
        for again in (True, False):
            points, support = self._points(observed, detected, predicted)
            observed, detected, unclaimed = self._assign_blobs(points, support, blobs)
            if again:
                self._reacquire(points, support, observed, detected, unclaimed)
        self.predicted_run = np.where(support > 0, 0, self.predicted_run + 1)
        self.unsupported_run = np.where(support >= 2, 0, self.unsupported_run + 1)
        corrected = np.where(detected, FLAG_DETECTED, FLAG_PREDICTED).astype(np.uint8)
        corrected[:, (self.predicted_run > self.settings.max_predicted_frames) | ~np.all(np.isfinite(points), axis=1)] = FLAG_LOST
        damping = np.where(support >= 2, 1.0, self.settings.velocity_damping)[:, None]
        self.velocity = damping * (points - self.points)
        self.points, self.support = points, support
        return points.copy(), observed, corrected

    def _points(self, positions, detected, predicted):
        """Steps 1 and 2: (points (15, 3), support (15,) int) from the detected positions (C, 15, 2)."""
        count = len(MARKER_NAMES)
        points = np.full((count, 3), np.nan)
        support = np.zeros(count, int)
        rays = [self._rays(c, positions[c]) for c in range(len(self.cameras))]
        for marker in REGION_MARKERS:
            points[marker], support[marker] = self._triangulated_best(marker, detected, rays, predicted)
        for marker in self._out_of_shape(points, support, predicted):
            points[marker], support[marker] = np.nan, 0
        for marker in REGION_MARKERS:
            if not support[marker]:
                base = self._region_prediction(marker, points, support, predicted)
                points[marker], support[marker] = self._on_a_ray(marker, base, detected, rays)
        for marker in LIMB_MARKERS:   # parents first
            parent = LIMB_PARENT[marker]
            points[marker], support[marker] = self._triangulated_best(marker, detected, rays, predicted, points[parent])
            if not support[marker]:
                # Hidden: carried by its parent marker (as the 2D tracker carries a hidden limb with its
                # region; a velocity runs away over a long occlusion), kept at its distance from it.
                base = self._on_shell(marker, self.points[marker] + points[parent] - self.points[parent],
                                      points[parent])
                points[marker], support[marker] = self._on_a_ray(marker, base, detected, rays, points[parent])
        return points, support

    def _triangulated_best(self, marker, detected, rays, predicted, parent=None):
        """Step 1 for one marker: (point (3,), agreeing views) or (NaN, 0). A limb marker's point must lie
        within its distance from its parent's `parent` point (± 2 × bone_tolerance_m)."""
        s = self.settings
        views = np.flatnonzero(detected[:, marker])
        origins = np.array([rays[c][0] for c in views]).reshape(-1, 3)
        directions = np.array([rays[c][1][marker] for c in views]).reshape(-1, 3)
        best = None
        for pair in itertools.combinations(views, 2):
            found = self._triangulated(marker, rays, pair)
            if not self._near_shell(marker, found, parent, 2.0 * s.bone_tolerance_m):
                continue
            gap = np.linalg.norm(found - predicted[marker]) if np.all(np.isfinite(predicted[marker])) else 0.0
            agree = views[np.linalg.norm(np.cross(found - origins, directions), axis=1) <= s.agreement_m].tolist()
            jump = s.region_jump_gate_m if marker not in LIMB_PARENT else \
                s.jump_gate_m if len(agree) >= 3 else s.two_view_jump_gate_m
            if gap > jump + s.reacquire_growth_m * self.unsupported_run[marker] or len(agree) < 2:
                continue
            key = (len(agree), -gap)
            if best is None or key > best[0]:
                best = (key, agree)
        if best is None:
            return np.full(3, np.nan), 0
        return self._triangulated(marker, rays, best[1]), len(best[1])

    def _out_of_shape(self, points, support, predicted):
        """Triangulated region markers that break their region's shape: a distance to another triangulated
        marker of the region more than shape_tolerance_m off its distance at the start. Of a broken pair
        the marker in more broken pairs goes, on a tie the one farther from its prediction (a marker
        given a neighbour's blob in two views triangulates at that neighbour)."""
        rejected = []
        for region, indices in REGION_INDICES.items():
            seen = [i for i in indices if support[i] >= 2]
            broken = [(a, b) for a, b in itertools.combinations(seen, 2)
                      if abs(np.linalg.norm(points[a] - points[b]) - self.distances[a, b]) > self.settings.shape_tolerance_m]
            while broken:
                count = {i: sum(i in pair for pair in broken) for i in seen}
                gap = {i: np.linalg.norm(points[i] - predicted[i]) if np.all(np.isfinite(predicted[i])) else 0.0
                       for i in seen}
                worst = max(seen, key=lambda i: (count[i], gap[i]))
                rejected.append(worst)
                seen.remove(worst)
                broken = [pair for pair in broken if worst not in pair]
        return rejected

    def _region_prediction(self, marker, points, support, predicted):
        """A region marker without two agreeing views: moved with its region's triangulated markers, or at
        constant velocity."""
        moved = [i for i in REGION_INDICES[CARRIER_REGION[marker]] if support[i] >= 2]
        if moved:
            return self.points[marker] + np.mean(points[moved] - self.points[moved], axis=0)
        return predicted[marker]

    def _on_a_ray(self, marker, base, detected, rays, parent=None):
        """(point, 1) on the detecting view's ray nearest to `base` (for a limb marker: within its
        distance of `parent`) when within single_view_gate_m of it; else (base, 0)."""
        s = self.settings
        # A lost limb marker can be anywhere its parent reaches: its ray must meet the shell instead.
        lost_limb = parent is not None and self.unsupported_run[marker] > 0 and np.isfinite(self.lengths[marker])
        best = None
        for c in np.flatnonzero(detected[:, marker]):
            origin, direction = rays[c][0], rays[c][1][marker]
            point = self._ray_point(marker, origin, direction, base, parent)
            gap = np.linalg.norm(point - base)
            near = (self._near_shell(marker, point, parent, s.bone_tolerance_m + 1e-9) if lost_limb
                    else gap <= s.single_view_gate_m)
            if near and (best is None or gap < best[0]):
                best = (gap, point)
        return (base, 0) if best is None else (best[1], 1)

    def _ray_point(self, marker, origin, direction, base, parent):
        """The point of the ray nearest to `base`; for a limb marker, of the ray's points at its distance
        (± bone_tolerance_m) from `parent`, the nearest to `base` (the ray's point nearest to `parent`
        when the ray passes wide of that shell)."""
        along = float(np.dot(base - origin, direction))
        point = origin + direction * along
        if parent is None or self._near_shell(marker, point, parent, self.settings.bone_tolerance_m):
            return point
        length = self.lengths[marker]
        tolerance = self.settings.bone_tolerance_m
        radius = length - tolerance if np.linalg.norm(point - parent) < length else length + tolerance
        middle = float(np.dot(parent - origin, direction))
        closest = np.linalg.norm(origin + direction * middle - parent)
        if closest > radius:
            return origin + direction * middle
        half = np.sqrt(radius ** 2 - closest ** 2)
        roots = np.array([middle - half, middle + half])
        return origin + direction * roots[np.argmin(np.abs(roots - along))]

    def _near_shell(self, marker, point, parent, tolerance):
        if parent is None or not np.isfinite(self.lengths[marker]):
            return True
        return abs(np.linalg.norm(point - parent) - self.lengths[marker]) <= tolerance

    def _on_shell(self, marker, point, parent):
        """`point` moved along the line from `parent` to within its distance (± bone_tolerance_m) from it."""
        if not np.isfinite(self.lengths[marker]):
            return point
        offset = point - parent
        distance = np.linalg.norm(offset)
        tolerance = self.settings.bone_tolerance_m
        wanted = np.clip(distance, self.lengths[marker] - tolerance, self.lengths[marker] + tolerance)
        return parent + offset * (wanted / max(distance, 1e-9))

    def _assign_blobs(self, points, support, blobs):
        """Step 3: per camera, the blobs paired with the projected points. Returns (positions (C, 15, 2):
        the paired blob or the projection, detected (C, 15) bool, unclaimed: per camera the indices of the
        blobs paired with no marker)."""
        count = len(self.cameras)
        positions = np.zeros((count, len(points), 2))
        detected = np.zeros((count, len(points)), bool)
        unclaimed = []
        for c, camera in enumerate(self.cameras):
            projected, depth = camera.project(points)
            positions[c] = projected
            gate = np.where(support >= 2, self.settings.blob_gate_m, self.settings.predicted_blob_gate_m) \
                * camera.K[0, 0] / np.maximum(depth, 1e-6)
            camera_blobs = np.asarray(blobs[c], float).reshape(-1, 2)
            match = gated_assignment(projected, camera_blobs, gate)
            positions[c][match >= 0] = camera_blobs[match[match >= 0]]
            detected[c] = match >= 0
            unclaimed.append(camera_blobs[np.setdiff1d(np.arange(len(camera_blobs)), match[match >= 0])])
        return positions, detected, unclaimed

    def _reacquire(self, points, support, observed, detected, unclaimed):
        """Step 3b: markers without two agreeing views take the 3D points that blobs no marker claimed
        make in two or more views (a marker whose prediction drifted while it was hidden finds its blobs
        again when it reappears). A candidate goes to the marker nearest to it (a limb marker: at its
        distance from its parent) by the Hungarian method, within a gate that widens with the frames the
        marker has gone without two views, blob_gate_m + reacquire_growth_m per frame, up to
        reacquire_gate_m; its blobs become that
        marker's detections in observed (C, 15, 2) and detected (C, 15), changed in place."""
        s = self.settings
        markers = np.flatnonzero(support < 2)
        candidates = self._unclaimed_points(unclaimed)
        if not len(markers):
            return
        cost = np.full((len(markers), len(candidates)), UNASSIGNABLE)
        for row, marker in enumerate(markers):
            parent = points[LIMB_PARENT[marker]] if marker in LIMB_PARENT else None
            gate = min(s.reacquire_gate_m, s.blob_gate_m + s.reacquire_growth_m * self.unsupported_run[marker])
            if parent is not None and self.unsupported_run[marker]:
                gate = np.inf   # a lost limb marker can be anywhere its parent reaches: the shell decides
            for column, (point, _) in enumerate(candidates):
                gap = np.linalg.norm(point - points[marker])
                if gap <= gate and self._near_shell(marker, point, parent, 2.0 * s.bone_tolerance_m):
                    cost[row, column] = gap
        used, taken = set(), set()
        for row, column in (sorted(zip(*linear_sum_assignment(cost)), key=lambda pair: cost[pair]) if candidates else ()):
            views = candidates[column][1]
            if cost[row, column] >= UNASSIGNABLE or any((c, i) in used for c, i in views.items()):
                continue
            used.update(views.items())
            taken.add(markers[row])
            for c, i in views.items():
                observed[c, markers[row]] = unclaimed[c][i]
                detected[c, markers[row]] = True
        self._reacquire_in_one_view(points, support, observed, detected, unclaimed, used, taken)

    def _reacquire_in_one_view(self, points, support, observed, detected, unclaimed, used, taken):
        """Step 3c: a limb marker lost (no view for a frame or more) and not found in step 3b takes an
        unclaimed blob of a single view whose ray meets its parent's shell (its distance from its parent
        ± bone_tolerance_m), the nearest to its estimate, by the Hungarian method: the first view that
        sees it again brings it back (an occluder still hiding it from the others)."""
        lost = [m for m in LIMB_PARENT if support[m] == 0 and self.unsupported_run[m] and m not in taken
                and np.isfinite(self.lengths[m])]
        blobs = [(c, i) for c in range(len(self.cameras)) for i in range(len(unclaimed[c])) if (c, i) not in used]
        if not lost or not blobs:
            return
        rays = {c: self._rays(c, unclaimed[c]) for c in {c for c, _ in blobs}}
        cost = np.full((len(lost), len(blobs)), UNASSIGNABLE)
        for row, marker in enumerate(lost):
            parent = points[LIMB_PARENT[marker]]
            for column, (c, i) in enumerate(blobs):
                point = self._ray_point(marker, rays[c][0], rays[c][1][i], points[marker], parent)
                if self._near_shell(marker, point, parent, self.settings.bone_tolerance_m + 1e-9):
                    cost[row, column] = np.linalg.norm(point - points[marker])
        for row, column in zip(*linear_sum_assignment(cost)):
            if cost[row, column] < UNASSIGNABLE:
                c, i = blobs[column]
                observed[c, lost[row]] = unclaimed[c][i]
                detected[c, lost[row]] = True

    def _unclaimed_points(self, unclaimed):
        """[(point (3,) [m], {camera: blob index})]: the unclaimed blobs of two cameras whose rays meet
        (within agreement_m), with the nearest agreeing unclaimed blob of each other camera."""
        s = self.settings
        rays = [self._rays(c, blobs) if len(blobs) else None for c, blobs in enumerate(unclaimed)]
        found = {}
        for a, b in itertools.combinations(range(len(self.cameras)), 2):
            if rays[a] is None or rays[b] is None:
                continue
            for i, j in itertools.product(range(len(unclaimed[a])), range(len(unclaimed[b]))):
                pixels = np.full((len(self.cameras), 2), np.nan)
                pixels[a], pixels[b] = unclaimed[a][i], unclaimed[b][j]
                point = triangulate(self.cameras, pixels)[0]
                if max(_ray_distance(rays[c][0], rays[c][1][k], point) for c, k in ((a, i), (b, j))) > s.agreement_m:
                    continue
                views = {a: i, b: j}
                for c in range(len(self.cameras)):
                    if c in views or rays[c] is None:
                        continue
                    distances = [_ray_distance(rays[c][0], direction, point) for direction in rays[c][1]]
                    if min(distances) <= s.agreement_m:
                        views[c] = int(np.argmin(distances))
                key = frozenset(views.items())
                if key not in found:
                    pixels = np.full((len(self.cameras), 2), np.nan)
                    for c, k in views.items():
                        pixels[c] = unclaimed[c][k]
                    found[key] = (triangulate(self.cameras, pixels)[0], views)
        return list(found.values())

    def _rays(self, c, pixels):
        """Camera c's optical centre (3,), unit rays (N, 3) through pixels (N, 2), and the pixels' ideal
        normalised coordinates (N, 2)."""
        camera = self.cameras[c]
        normalized = camera.undistort_pixels(pixels)
        return camera.center, camera.rays(normalized), normalized

    def _triangulated(self, marker, rays, views):
        """A marker's DLT point (3,) [m] from `views` (2 or more) of `rays` (as _rays gives them)."""
        views = list(views)
        return dlt_point([self.cameras[c] for c in views], np.array([rays[c][2][marker] for c in views]),
                         np.ones(len(views)))


class ViewTrackers:
    """Marker mode's graph without ROS: a markers.MarkerTracker per camera (the marker_tracker nodes) and
    their tracks fused by MarkerViews (marker_skeleton), the fusion handed back to each tracker before
    the next frame, as the nodes do. The blobs go to the fusion as float32, as MarkerTracks carries
    them, so that this computes exactly what the graph does."""

    def __init__(self, cameras, settings=ViewSettings()):
        self.trackers = [MarkerTracker() for _ in cameras]
        self.views = MarkerViews(cameras, settings)

    def track(self, images, labelling=None):
        """One frame: images, C RGB uint8 (H, W, 3) in the cameras' order. The first frame is the labelled
        calibration frame: labelling, per camera (positions (15, 2) [px], visible (15,) bool); its tracks
        are the labelling snapped to the detections (markers._TrackerBase.initialise). Returns as
        MarkerViews.fuse: (points (15, 3) [m], positions (C, 15, 2) [px], flags (C, 15))."""
        if self.views.points is None:
            if labelling is None:
                raise ValueError('the first frame needs its labelling')
            tracks = [tracker.initialise(image, *label) for tracker, image, label in
                      zip(self.trackers, images, labelling)]
            self.views.start([t[0] for t in tracks], [t[1] for t in tracks])
        else:
            tracks = [tracker.track(image) for tracker, image in zip(self.trackers, images)]
        blobs = [tracker.detections.astype(np.float32) for tracker in self.trackers]
        points, positions, flags = self.views.fuse([t[0] for t in tracks], [t[1] for t in tracks], blobs)
        for tracker, camera_positions, camera_flags in zip(self.trackers, positions, flags):
            tracker.correct(camera_positions, camera_flags)
        return points, positions, flags


def _ray_distance(origin, direction, point):
    """Distance [m] of `point` (3,) from the ray origin + s·direction (unit direction)."""
    return float(np.linalg.norm(np.cross(point - origin, direction)))
