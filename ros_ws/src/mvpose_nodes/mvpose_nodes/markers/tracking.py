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
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import linear_sum_assignment

from mvpose_nodes.body.model import JOINT_NAMES
from mvpose_nodes.vision.silhouette import BLUENESS_THRESHOLD, chroma_key_foreground

# The values of mvpose_msgs/msg/MarkerTracks FLAG_*.
FLAG_DETECTED, FLAG_PREDICTED, FLAG_LOST = 0, 1, 2

MARKER_NAMES = JOINT_NAMES
REGIONS = {'head': ('head',),
           'shoulders': ('neck', 'left_shoulder', 'right_shoulder'),
           'hips': ('pelvis', 'left_hip', 'right_hip')}
REGION_INDICES = {region: tuple(MARKER_NAMES.index(name) for name in names) for region, names in REGIONS.items()}
LIMB_INDICES = tuple(i for i in range(len(MARKER_NAMES))
                     if not any(i in indices for indices in REGION_INDICES.values()))
_BIG = 1e9


@dataclass(frozen=True)
class MarkerSettings:
    # Red detection in HSV (hue in degrees, saturation and value in 0..1): a pixel is marker red when
    # its hue is within `red_hue_tolerance` of 0°, S >= red_min_saturation and V >= red_min_value.
    # Orange (hue >= ~25°), pink/magenta (hue <= ~340°) and skin (S ~0.3–0.45) fall outside.
    red_hue_tolerance: float = 15.0
    red_min_saturation: float = 0.55
    red_min_value: float = 0.35
    min_blob_area: int = 4                  # [px] smaller red blobs are noise
    max_blob_area: int | None = None        # [px] larger blobs are not markers; None: max_blob_fraction of the image
    max_blob_fraction: float = 0.005
    # Region tracking
    ncc_step: int = 3                       # λ of the first descent step [px]
    scale_step: float = 0.02                # size candidates h·(1 ± scale_step), per axis
    template_alpha: float = 0.9             # T_t = α·T_{t−1} + (1 − α)·W_t
    template_update_min_ncc: float = 0.5    # no update below this match quality
    template_margin_fraction: float = 0.25  # context around the marker box, × its mean side ...
    template_margin_px: float = 6.0         # ... and at least this [px]
    min_region_fraction: float = 0.4        # marker-box sides at least this × the torso length ...
    min_region_px: float = 8.0              # ... and at least this [px] (the head's box is this square)
    search_width_factor: float = 1.0        # horizontal range: ± this × window width around the last centre
    # Marker assignment
    marker_window_factor: float = 1.1       # region's marker search window: 1.1·h_x × 1.1·h_y
    limb_gate_fraction: float = 0.4         # limb/baseline gate [× initial torso length]
    init_gate_fraction: float = 0.2         # initial positions snap to detections within this × torso length
    predict_region_motion: bool = False     # start each region's search at its previous centre + previous S
    check_region_motion: bool = True        # keep S only if its markers' detections agree best (_checked_displacement)
    max_predicted_frames: int = 25          # predicted longer than this → FLAG_LOST
    carry_hidden_limbs: bool = True         # a hidden limb marker moves with its region, not its own velocity
    redness_weight: float = 2.0             # the tracking image adds this × max(0, r − max(g, b)): markers stand out
    # Background
    chroma_key: bool = True                 # mask the blue screen to 0 in the templates' grey image
    chroma_threshold: float = BLUENESS_THRESHOLD


# ---------------------------------------------------------------------------------------------
# Detection

def red_mask(rgb, settings=MarkerSettings()):
    """(H, W) bool: marker-red pixels (MarkerSettings' HSV thresholds)."""
    hsv = cv2.cvtColor(rgb.astype(np.float32) / 255.0, cv2.COLOR_RGB2HSV)  # H in degrees [0, 360)
    hue, saturation, value = cv2.split(hsv)
    red_hue = (hue <= settings.red_hue_tolerance) | (hue >= 360.0 - settings.red_hue_tolerance)
    return red_hue & (saturation >= settings.red_min_saturation) & (value >= settings.red_min_value)


def detect_markers(rgb, settings=MarkerSettings()):
    """(N, 2) float64 [px]: centres (x, y) of the red blobs of `rgb`: the centroids of the
    8-connected components of red_mask with an area in [min_blob_area, max_blob_area]. Two
    overlapping markers form one blob and count as one detection."""
    mask = red_mask(rgb, settings).astype(np.uint8)
    count, _, stats, centroids = cv2.connectedComponentsWithStats(mask, connectivity=8)
    max_area = settings.max_blob_area
    if max_area is None:
        max_area = settings.max_blob_fraction * rgb.shape[0] * rgb.shape[1]
    area = stats[1:, cv2.CC_STAT_AREA]
    keep = (area >= settings.min_blob_area) & (area <= max_area)
    return np.asarray(centroids[1:][keep], dtype=np.float64).reshape(-1, 2)


def tracking_image(rgb, settings=MarkerSettings()):
    """The grey float32 image the regions are tracked in: blue screen set to 0 when chroma_key."""
    if rgb.ndim == 2:
        return rgb.astype(np.float32)
    grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY).astype(np.float32)
    if settings.redness_weight:
        channels = rgb.astype(np.float32)
        grey += settings.redness_weight * np.maximum(channels[..., 0] - np.maximum(channels[..., 1], channels[..., 2]), 0)
    if settings.chroma_key:
        grey[~chroma_key_foreground(rgb, settings.chroma_threshold)] = 0.0
    return grey


# ---------------------------------------------------------------------------------------------
# Region tracking

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


# ---------------------------------------------------------------------------------------------
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
    cost = np.where(distance <= gate, distance / np.maximum(gate, 1e-9), _BIG)
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


# ---------------------------------------------------------------------------------------------
# Trackers

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
