"""Colour-marker tracking held together by body regions (paper 001), for one camera's image sequence.

Red markers sit on the 15 joints of the stick model (body_model.JOINT_NAMES). Three body regions
are tracked by template matching: region 1 = head (1 marker), region 2 = neck and shoulders,
region 3 = pelvis and hips. Each region's marker box spans X_min..X_max, Y_min..Y_max of its markers
(size h = (h_x, h_y), centre = midpoint; sides below a minimum, e.g. the single head marker's, are
widened to it). Markers are then assigned to the detected red blobs region by region, using each
region's measured displacement S_i; the 8 limb markers follow by gated nearest-neighbour assignment
(Hungarian) to their constant-velocity predictions.

Choices the paper leaves open, fixed here (MarkerSettings holds the numbers):

- Templates are grey (cv2 RGB→GRAY, float32) of the marker box padded by a margin on every side
  (the context), with the blue screen masked to 0 by silhouette.chroma_key_foreground when
  `chroma_key` is set (the "simple background subtraction": only the person's pixels carry texture).
- Windows are compared at the template's resolution: the candidate window (centre c, size W) is
  resampled bilinearly onto the template's pixel grid, so "template resized likewise" for the
  ±2 % scale candidates is exact, not rounded to whole pixels.
- Search: λ-descent from the region's previous centre (with `predict_region_motion`: plus its last
  displacement S; off by default, it made the synthetic bags worse) (λ = 3; 5 candidates: centre and
  ±λ in x or y; move to the best NCC, ties keep the centre; no move → λ − 1; λ = 0 → found), then the 9 size
  candidates (h_x·{0.98, 1, 1.02}) × (h_y·{0.98, 1, 1.02}) at the found centre, ties keep the size.
  Range: the centre stays within ± one window width of the previous centre horizontally (a range of
  twice the width) and on its side of the shoulders region's centre vertically (head above,
  hips below); the shoulders region is tracked first.
- Checked motion (beyond the paper): the matched displacement S is kept only if the region's markers,
  moved by it, find at least as many detections within the region's gate as with no motion or with
  the last frame's S (`check_region_motion`); grey templates of plain clothes slide.
- Template update (α = 0.9): T_t = α·T_{t−1} + (1 − α)·W_t, W_t the matched window (at the chosen
  centre and size, resampled on the template grid); skipped when the match's NCC is below
  `template_update_min_ncc` (an occluded region does not overwrite its template).
- Regions 2/3 assignment: predictions q_i = p_{t−1,i} + S_region; candidates are the unused
  detections inside the region's marker search window (1.1·h_x × 1.1·h_y around its centre); markers
  and candidates are paired by the Hungarian method on distance, gated at (h_x + h_y)/4.
  3 found → taken. 2 found → the third by the similarity transform (rotation, uniform scale,
  translation) that carries the two found markers' reference positions onto their detections,
  applied to the third's reference position; the reference is the last frame where all three were
  detected (the initialisation frame first). 1 found → the other two are their predictions shifted by
  the found marker's residual (detection − prediction). 0 found → each its region-displacement
  prediction p_{t−1,i} + S_region (not its own velocity: the region's motion is measured in this image).
- Region 1: the unused detections in its search window: one → the head; several → the nearest to
  p_{t−1,head} + S_1; none → p_{t−1,head} + S_1 (predicted).
- Limbs and the baseline: p_{t−1} + (p_{t−1} − p_{t−2}), Hungarian on distance to the remaining
  detections, gated at `limb_gate_fraction` × the initial torso length |neck − pelvis|. The region
  tracker's hidden limb markers (`carry_hidden_limbs`) move with their region instead (hips for the
  legs, shoulders for the arms): over a long occlusion a velocity runs away.
- A marker predicted for more than `max_predicted_frames` frames in a row is FLAG_LOST; its last
  position is still reported (and held: its velocity is zeroed) so that it can be re-acquired.

Images are RGB uint8 (H, W, 3); points (x, y) in pixels, x right, y down, origin at the centre of the
top-left pixel. Pure NumPy/OpenCV/SciPy: no ROS.
"""
import numpy as np

from mvpose_nodes.markers.detection import (FLAG_DETECTED, FLAG_LOST, FLAG_PREDICTED, LIMB_INDICES, MARKER_NAMES,
                                            REGION_INDICES, MarkerSettings, detect_markers, tracking_image)
from mvpose_nodes.markers.regions import RegionTracker, assign_group, assign_head, gated_assignment


class _TrackerBase:
    def __init__(self, settings=MarkerSettings()):
        self.settings = settings
        self.positions = None    # (15, 2) at t − 1
        self.previous = None     # (15, 2) at t − 2
        self.flags = None
        self.predicted_run = None

    def initialise(self, rgb, positions, visible=None):
        """Start from the first frame and the 15 markers' positions in it (an operator's labelling
        or a projected pose). visible: optional (15,) bool, the labelling's word on which markers are
        seen (a hidden one must not take a visible neighbour's blob). Each visible position snaps to
        the nearest detection within init_gate_fraction × |neck − pelvis| (FLAG_DETECTED), else stays
        as given (FLAG_PREDICTED). Returns (positions (15, 2), flags (15,))."""
        positions = np.asarray(positions, np.float64).reshape(len(MARKER_NAMES), 2).copy()
        visible = np.ones(len(MARKER_NAMES), bool) if visible is None else np.asarray(visible, bool)
        names = MARKER_NAMES
        # The body's scale in this image: the neck–pelvis distance (unlike the shoulder width, it does
        # not collapse in a side view).
        self.torso_length = max(float(np.linalg.norm(positions[names.index('neck')]
                                                     - positions[names.index('pelvis')])), 1.0)
        detections = detect_markers(rgb, self.settings)
        match = np.full(len(names), -1)
        match[visible] = gated_assignment(positions[visible], detections, self.settings.init_gate_fraction * self.torso_length)
        flags = np.full(len(names), FLAG_PREDICTED, np.uint8)
        flags[match >= 0] = FLAG_DETECTED
        positions[match >= 0] = detections[match[match >= 0]]
        self.positions, self.previous, self.flags = positions, positions.copy(), flags
        self.predicted_run = np.where(flags == FLAG_DETECTED, 0, 1)
        self.detections = detections
        return positions.copy(), flags.copy()

    def correct(self, positions, flags):
        """Replace the last frame's estimate with a better one (marker_views: the cameras' tracks fused in
        3D), so that the next frame is predicted from it: positions (15, 2) [px], flags (15,) FLAG_*. A
        lost marker (FLAG_LOST) keeps this tracker's own position."""
        flags = np.asarray(flags, np.uint8)
        known = flags != FLAG_LOST
        self.positions[known] = np.asarray(positions, np.float64)[known]
        self.flags = flags.copy()
        self.predicted_run = np.where(flags == FLAG_DETECTED, 0, np.maximum(self.predicted_run, 1))

    @property
    def limb_gate(self):
        return self.settings.limb_gate_fraction * self.torso_length

    def _finish(self, positions, flags):
        """Shift the history, count prediction runs, mark FLAG_LOST (and hold those still)."""
        self.predicted_run = np.where(flags == FLAG_DETECTED, 0, self.predicted_run + 1)
        lost = self.predicted_run > self.settings.max_predicted_frames
        flags = flags.copy()
        flags[lost] = FLAG_LOST
        previous = self.positions.copy()
        previous[lost] = positions[lost]  # zero velocity: a lost marker is held where it was last estimated
        self.previous, self.positions, self.flags = previous, positions, flags
        return positions.copy(), flags.copy()

    def _constant_velocity(self, indices):
        indices = list(indices)
        return 2.0 * self.positions[indices] - self.previous[indices]


class NearestNeighbourTracker(_TrackerBase):
    """The baseline: every marker takes the nearest detection to its constant-velocity prediction
    p_{t−1} + (p_{t−1} − p_{t−2}) (Hungarian, gated at limb_gate_fraction × torso length),
    predicted when none. No regions."""

    def track(self, rgb):
        """(positions (15, 2) float64 [px], flags (15,) uint8) in this image."""
        if self.positions is None:
            raise RuntimeError('initialise() first')
        detections = detect_markers(rgb, self.settings)
        self.detections = detections
        predicted = self._constant_velocity(range(len(MARKER_NAMES)))
        match = gated_assignment(predicted, detections, self.limb_gate)
        positions = predicted.copy()
        positions[match >= 0] = detections[match[match >= 0]]
        flags = np.where(match >= 0, FLAG_DETECTED, FLAG_PREDICTED).astype(np.uint8)
        return self._finish(positions, flags)


class MarkerTracker(_TrackerBase):
    """Paper 001's tracker: regions by template matching, then markers assigned region by region,
    then the limbs. `regions` holds, after each call, per region name a dict with the tracked
    window ('window_centre', 'window_size'), the marker box ('centre', 'size' = h), its marker
    search box ('search_size' = 1.1·h), the displacement 'S' and the match 'ncc'."""

    def __init__(self, settings=MarkerSettings()):
        super().__init__(settings)
        self.trackers = {}
        self.regions = {}
        self.references = {}

    def initialise(self, rgb, positions, visible=None):
        positions, flags = super().initialise(rgb, positions, visible)
        s = self.settings
        image = tracking_image(rgb, s)
        minimum = max(s.min_region_px, s.min_region_fraction * self.torso_length)
        self.trackers, self.regions, self.box_sizes = {}, {}, {}
        for region, indices in REGION_INDICES.items():
            points = positions[list(indices)]
            low, high = points.min(axis=0), points.max(axis=0)
            centre = (low + high) / 2.0
            box = np.maximum(high - low, minimum)
            margin = max(s.template_margin_px, s.template_margin_fraction * float(box.mean()))
            tracker = RegionTracker(s.ncc_step, s.scale_step, s.template_alpha, s.template_update_min_ncc)
            tracker.start(image, centre, box + 2.0 * margin)
            self.trackers[region] = tracker
            self.box_sizes[region] = box / tracker.size  # marker box = this × window size (scales with it)
            self.references[region] = points.copy()
            self.regions[region] = self._region_record(region, np.zeros(2), 1.0)
        return positions, flags

    def correct(self, positions, flags):
        """As _TrackerBase.correct; each region's window is centred again on its corrected markers' box."""
        super().correct(positions, flags)
        for region, indices in REGION_INDICES.items():
            points = self.positions[list(indices)]
            self.trackers[region].centre = (points.min(axis=0) + points.max(axis=0)) / 2.0
            self.regions[region] = self._region_record(region, self.regions[region]['S'], self.regions[region]['ncc'])

    def _region_record(self, region, displacement, score):
        tracker = self.trackers[region]
        box = self.box_sizes[region] * tracker.size
        return {'window_centre': tracker.centre.copy(), 'window_size': tracker.size.copy(),
                'centre': tracker.centre.copy(), 'size': box,
                'search_size': self.settings.marker_window_factor * box,
                'S': np.asarray(displacement, np.float64), 'ncc': float(score)}

    def track(self, rgb):
        """(positions (15, 2) float64 [px], flags (15,) uint8) in this image."""
        if self.positions is None:
            raise RuntimeError('initialise() first')
        s = self.settings
        image = tracking_image(rgb, s)
        detections = detect_markers(rgb, s)
        self.detections = detections
        width = s.search_width_factor
        # Region 2 first; region 1 stays above its centre, region 3 below.
        order = (('shoulders', None), ('head', 'above'), ('hips', 'below'))
        for region, side in order:
            tracker = self.trackers[region]
            before = tracker.centre.copy()
            if s.predict_region_motion:
                tracker.centre = before + self.regions[region]['S']
            x_range = (before[0] - width * tracker.size[0], before[0] + width * tracker.size[0])
            y_range = None
            if side is not None:
                middle = self.regions['shoulders']['centre'][1]
                y_range = (None, middle - 1.0) if side == 'above' else (middle + 1.0, None)
            centre, _, score = tracker.track(image, x_range, y_range)
            displacement = centre - before
            if s.check_region_motion:
                checked = self._checked_displacement(region, displacement, detections)
                if checked is not displacement:
                    tracker.centre = before + checked
                    displacement = checked
            self.regions[region] = self._region_record(region, displacement, score)

        positions = np.zeros_like(self.positions)
        flags = np.full(len(MARKER_NAMES), FLAG_PREDICTED, np.uint8)
        used = np.zeros(len(detections), bool)

        record = self.regions['head']
        (head,) = REGION_INDICES['head']
        free = np.flatnonzero(~used)
        positions[head], flags[head], k = assign_head(self.positions[head], record['S'], detections[free],
                                                      record['centre'], record['search_size'])
        if k >= 0:
            used[free[k]] = True

        for region in ('shoulders', 'hips'):
            record = self.regions[region]
            indices = list(REGION_INDICES[region])
            free = np.flatnonzero(~used)
            group, group_flags, index = assign_group(self.positions[indices], record['S'], detections[free],
                                                     record['centre'], record['size'], self.references[region],
                                                     s.marker_window_factor)
            positions[indices], flags[indices] = group, group_flags
            used[free[index[index >= 0]]] = True
            if np.all(index >= 0):
                self.references[region] = group.copy()

        limbs = list(LIMB_INDICES)
        free = np.flatnonzero(~used)
        predicted = self._limb_predictions(limbs)
        match = gated_assignment(predicted, detections[free], self.limb_gate)
        positions[limbs] = predicted
        for row, col in enumerate(match):
            if col >= 0:
                positions[limbs[row]] = detections[free[col]]
                flags[limbs[row]] = FLAG_DETECTED
        height, width = rgb.shape[:2]
        positions = np.clip(positions, 0, (width - 1, height - 1))  # a prediction never leaves the image
        return self._finish(positions, flags)

    def _checked_displacement(self, region, displacement, detections):
        """The template match's displacement S, or no motion, or the last frame's S, whichever explains
        the region's markers best: the most of them (moved by it) with a detection within the region's
        gate (h_x + h_y)/4, then the smaller summed distance, then that order. A template that slid along
        plain clothes would otherwise carry the markers' search windows away from them."""
        if not len(detections):
            return displacement
        indices = list(REGION_INDICES[region])
        box = self.box_sizes[region] * self.trackers[region].size
        gate = max(float(box.sum()) / 4.0, self.settings.min_region_px)

        def support(shift):
            distance = np.linalg.norm(self.positions[indices] + shift - detections[:, None], axis=2).min(axis=0)
            near = distance < gate
            return int(near.sum()), -float(distance[near].sum())
        candidates = [displacement, np.zeros(2), self.regions[region]['S']]   # matched, still, as before
        best = max(range(len(candidates)), key=lambda k: (support(candidates[k]), -k))
        return displacement if best == 0 else np.asarray(candidates[best], np.float64).copy()

    def _limb_predictions(self, limbs):
        """Predicted positions (L, 2) [px] of limb markers: seen last frame, constant velocity; hidden,
        carried by their region (the hips for legs, the shoulders for arms) without their own velocity,
        which runs away over a long occlusion (beyond the paper, which predicts by velocity)."""
        velocity = self._constant_velocity(limbs)
        if not self.settings.carry_hidden_limbs:
            return velocity
        predicted = velocity.copy()
        for row, index in enumerate(limbs):
            if self.predicted_run[index]:
                region = 'hips' if MARKER_NAMES[index].endswith(('knee', 'ankle')) else 'shoulders'
                predicted[row] = self.positions[index] + self.regions[region]['S']
        return predicted
