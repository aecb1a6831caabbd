"""Silhouettes by background subtraction, and the keypoints read off them (paper 000 Sec. 3.1).

Two background models: a chroma key for blue-screen studios such as i3DPost's ("a simple
threshold separates the person"), and a learned per-pixel Gaussian model for ordinary scenes
(from person-free frames, or kept up to date as a running average where no person is). Either
mask is cleaned the same way: opening, closing, the largest blob kept, its holes filled.
Keypoints: the centroid of the silhouette (root estimate, P1), and the ankles and knees as
centroids of the silhouette restricted to rectangles around each foot and knee.

Images are RGB uint8 (H, W, 3); masks bool (H, W); points (x, y) in pixels, x right, y down.
"""
import bisect
from dataclasses import dataclass

import cv2
import numpy as np

BLUENESS_THRESHOLD = 25   # [DN] b − max(r, g) above which a pixel is blue screen
MIN_PERSON_AREA = 2000    # [px] at 1080p: smaller blobs are not a person (scaled with the image area)
MAX_HOLE_FRACTION = 0.002  # holes up to this share of the person's area are keying misses, and filled
OPENING_PX = 2            # [px] clean_mask's opening radius: keying noise
CLOSING_PX = 4            # [px] clean_mask's closing radius: small gaps, small enough not to join the legs
# Anthropometric bands, as fractions of the silhouette height above its lowest pixel (person standing).
LEG_CUT = 0.36            # legs are the silhouette below this height (below the hands, above the knees)
ANKLE_HEIGHT = 0.03       # the ankle joint above the lowest pixel of its foot, as a share of the stature
                          # (4–5 % above the sole, less the sole's rise towards the camera in the image)
SHIN_BAND = (0.06, 0.18)  # above a foot's lowest pixel: mostly the shin, whose axis leads down to the ankle
KNEE_BAND = (0.285, 0.345)  # the knee joint lies at about 30 % of the stature
HEAD_SCAN_SCALE = 4       # head_column follows the body's middle up on a grid this many times coarser
HEAD_WIDTH_BAND = (0.08, 0.22)  # the head's width: the runs this share of the centroid-to-top column below the top
SHOULDER_WIDENING = 1.8   # the shoulders' row is the first this many times as wide as the head
TRUNK_WIDENING = 1.15     # head_column: a run wider than this times the median so far has an arm held out
SHOULDER_DEPTH = (0.09, 0.22)  # ... and lies this share of the stature below the head's top (the template: 0.14)
HEAD_BUMP = 0.08          # head_column: a run that ends this share of the height above a split is a leaning back's
HEAD_MIN_WIDTH = 0.07     # ... if the other branch's median width is a head's (raised arms': 0.04-0.045 of it)
COUNTED_LABELS = 16       # components: up to this many labels, each one's pixels are counted in a pass of its own


def components(mask, connectivity=8):
    """Connected components of a bool or uint8 (H, W) mask: labels int32 (H, W) (0: the background) and
    the area of each label (n,) int64 [px]. cv2.connectedComponents, then each label's pixels counted by
    itself (np.count_nonzero of labels == k, one vectorised pass each, 0.08 ms on an 856×540 box) while
    there are at most COUNTED_LABELS of them, as nearly always (a person, a few skin regions or holes): a
    bincount costs as much as 16 such passes (1.2 ms: it casts the labels to int64 and increments one
    counter after another), and was the largest cost of the features (3–4 ms of 14 per 1080p image over the
    pipeline's six calls; docs/method.md, session 54). OpenCV's connectedComponentsWithStats takes longer
    still (1.0 against 0.2 ms for the labelling alone). Callers take the box of the one component they keep
    (component_box)."""
    count, labels = cv2.connectedComponents(mask.view(np.uint8), connectivity=connectivity)
    if count > COUNTED_LABELS:
        return labels, np.bincount(labels.ravel(), minlength=count)
    areas = np.empty(count, np.int64)
    areas[1:] = [np.count_nonzero(labels == label) for label in range(1, count)]
    areas[0] = labels.size - areas[1:].sum()
    return labels, areas


def component_box(labels, label):
    """(x, y, w, h) [px] of the pixels of `label` in labels (H, W): columns x to x + w − 1, rows y to y + h − 1."""
    pixels = labels == label
    rows = np.flatnonzero(pixels.any(axis=1))
    columns = np.flatnonzero(pixels.any(axis=0))
    return int(columns[0]), int(rows[0]), int(columns[-1] - columns[0] + 1), int(rows[-1] - rows[0] + 1)


def chroma_key_foreground(rgb, threshold=BLUENESS_THRESHOLD):
    """Pixels that are not blue screen: b − max(r, g) <= threshold. (H, W) bool."""
    red, green, blue = cv2.split(rgb)
    blueness = cv2.subtract(blue, cv2.max(red, green))  # saturates at 0 for non-blue pixels
    return blueness <= threshold


class BackgroundModel:
    """Per-pixel Gaussian background (mean and variance per channel) for ordinary scenes.

    A pixel is foreground when any channel differs from the mean by more than `k` standard
    deviations (with a floor on sigma, so that a static, noise-free background still tolerates
    sensor noise), unless it is a cast shadow: the background's colour scaled by a brightness
    factor in SHADOW_BRIGHTNESS with a colour distortion under SHADOW_CHROMA of its brightness
    (Horprasert, Harwood & Davis 1999). `update` keeps the model current where no person is
    (running average with `learning_rate`), which follows slow lighting changes."""

    SHADOW_BRIGHTNESS = (0.3, 0.95)
    SHADOW_CHROMA = 0.06

    def __init__(self, mean, variance, k=4.0, min_sigma=6.0, learning_rate=0.02):
        self.mean = mean.astype(np.float32)
        self.variance = variance.astype(np.float32)
        self.k, self.min_sigma, self.learning_rate = k, min_sigma, learning_rate

    @classmethod
    def from_frames(cls, frames, **options):
        """The model of person-free frames: a sequence of RGB uint8 (H, W, 3) images."""
        stack = np.stack([f.astype(np.float32) for f in frames])
        return cls(stack.mean(axis=0), stack.var(axis=0), **options)

    def foreground(self, rgb, window=(slice(None), slice(None))):
        """Foreground of `rgb`, the part `window` (row and column slices, possibly strided) of the image."""
        mean = self.mean[window]
        pixels = rgb.astype(np.float32)
        sigma = np.maximum(np.sqrt(self.variance[window]), self.min_sigma)
        changed = np.any(np.abs(pixels - mean) > self.k * sigma, axis=2)
        brightness = np.sum(pixels * mean, axis=2) / np.maximum(np.sum(mean * mean, axis=2), 1.0)
        distortion = np.linalg.norm(pixels - brightness[..., None] * mean, axis=2)
        low, high = self.SHADOW_BRIGHTNESS
        shadow = (brightness > low) & (brightness < high) & (
            distortion < self.SHADOW_CHROMA * brightness * np.linalg.norm(mean, axis=2) + self.k * self.min_sigma)
        return changed & ~shadow

    def update(self, rgb, foreground):
        """Blend the current frame into the model where it shows background."""
        background = ~foreground[..., None]
        difference = rgb.astype(np.float32) - self.mean
        rate = self.learning_rate * background
        self.mean += rate * difference
        self.variance += rate * (difference ** 2 - self.variance)


class BackgroundLearner:
    """The person-free frames that build a BackgroundModel, collected one image at a time (the
    camera_features node's 'background' silhouette method): `add(rgb)` keeps the RGB uint8 (H, W, 3)
    frame and returns None until `frames_needed` are in, then the model (and forgets the frames)."""

    def __init__(self, frames_needed):
        self.frames_needed = frames_needed
        self.frames = []

    def add(self, rgb):
        self.frames.append(rgb)
        if len(self.frames) < self.frames_needed:
            return None
        model = BackgroundModel.from_frames(self.frames)
        self.frames = []
        return model


def clean_mask(foreground, min_area=MIN_PERSON_AREA, opening=OPENING_PX, closing=CLOSING_PX,
               max_hole_fraction=MAX_HOLE_FRACTION):
    """The person's blob: opening (radius `opening` px), closing (radius `closing`), the largest
    8-connected component if it has at least `min_area` px, its small holes filled (up to
    `max_hole_fraction` of its area: keying misses, not the real gaps between legs or arm and body,
    which the blob also encloses where feet or hands touch). (H, W) bool; empty if none."""
    mask = foreground.astype(np.uint8)
    if opening:
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, _disk(opening))
    if closing:
        mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, _disk(closing))
    labels, areas = components(mask)
    if len(areas) < 2:
        return np.zeros(foreground.shape, bool)
    largest = 1 + int(np.argmax(areas[1:]))
    if areas[largest] < min_area:
        return np.zeros(foreground.shape, bool)
    x, y, w, h = component_box(labels, largest)
    blob = (labels[y:y + h, x:x + w] == largest).astype(np.uint8)
    # Holes: background components of the box that do not touch its border.
    padded = cv2.copyMakeBorder(1 - blob, 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=1)
    holes, hole_areas = components(padded, connectivity=4)
    outside = holes[0, 0]
    small = [i for i in range(1, len(hole_areas)) if i != outside
             and hole_areas[i] <= max_hole_fraction * areas[largest]]
    filled = blob.astype(bool)
    if small:   # most silhouettes have none: no pass over the box
        filled |= np.isin(holes[1:-1, 1:-1], small)
    person = np.zeros(foreground.shape, bool)
    person[y:y + h, x:x + w] = filled
    return person


def _disk(radius):
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))


@dataclass
class SilhouetteKeypoints:
    """Keypoints of one silhouette, each (x, y) [px] or None, with a confidence in [0, 1]. The two
    legs are not yet the person's left or right: `legs` is ordered by image x (image-left first)."""
    root: tuple
    height: float                # [px] the stature: from the head's top (`top`) down to the lowest pixel
    top: tuple                   # the top of the head (x, y): the top of the body's middle (head_column)
    legs: list                   # per leg found: {'ankle': (x, y), 'knee': (x, y) or None, 'confidence': c}
    shoulders: tuple = None      # the middle (x, y) of the first row where the body's middle widens to the
                                 # shoulders (head_column), or None


def silhouette_keypoints(mask):
    """Root (centroid of all foreground pixels), the head's top and the shoulders' row (head_column), and per
    leg the ankle and knee (paper 000 Sec. 3.1)."""
    per_row, per_column = np.count_nonzero(mask, axis=1), np.count_nonzero(mask, axis=0)
    count = int(per_row.sum())
    if count == 0:
        return None
    bottom_row = int(np.flatnonzero(per_row)[-1])
    # The pixels' mean row and column: exact integer sums, divided once (as np.mean of their coordinates gives).
    root = (int(per_column @ np.arange(mask.shape[1])) / count, int(per_row @ np.arange(mask.shape[0])) / count)
    top, shoulders = head_column(mask, root, bottom_row)
    height = float(bottom_row - top[1] + 1)
    legs = _legs(mask, bottom_row, height)
    return SilhouetteKeypoints(root, height, top, legs, shoulders)


def head_column(mask, root, bottom=None):
    """The top of the head and the shoulders' row of a silhouette (bool (H, W)) whose centroid is `root` (x, y):
    from the centroid up, row by row, the run of foreground that continues the run below it (of those that
    overlap it, the one whose middle is nearest to the trunk's: followed by at most a coarse cell a row towards
    the middle of each run at most TRUNK_WIDENING times the median width so far, not one with an arm held out
    or touching the head) leads up the trunk and neck to the
    top of the head, past raised arms, which leave that run to the sides; the silhouette's highest pixel is
    a raised hand instead. Where that run ends less than HEAD_BUMP of the silhouette's height above the last
    row where another run was left aside, and the other goes on higher and as wide as a head (HEAD_MIN_WIDTH),
    the run followed was the back of a person leaning forward (sitting down, seen from the side) and the other
    the head: the column goes on up the other. Scanned on a HEAD_SCAN_SCALE times coarser grid, then the head's
    highest pixel found in the image over the last run. Shoulders: going back down from the top, the first row
    at least SHOULDER_WIDENING times the head's width (the median width of the runs HEAD_WIDTH_BAND of the
    column's length below the top), None if no row is or the first is not SHOULDER_DEPTH of the stature (from
    the top down to `bottom`, the lowest row, or the image's) below the top (a view from the side; arms held
    out lower down). Returns ((x, y), (x, y) or None) [px]."""
    coarse = mask[::HEAD_SCAN_SCALE, ::HEAD_SCAN_SCALE]
    x, row = int(root[0] // HEAD_SCAN_SCALE), min(int(root[1] // HEAD_SCAN_SCALE), coarse.shape[0] - 1)
    row_runs = foreground_runs(coarse[:row + 1])
    runs, splits = trunk_column(row_runs, row, (x, x + 1), [])
    if runs and splits:
        split, others = splits[-1]
        end = runs[-1][0]
        height = (mask.shape[0] if bottom is None else bottom) / HEAD_SCAN_SCALE - end   # [coarse rows]
        if split - end < HEAD_BUMP * height:
            below = [run for run in runs if run[0] > split]
            _, *followed = runs[len(below)]
            other = min(others, key=lambda run: abs(run[0] + run[1] - followed[0] - followed[1]))
            branch, _ = trunk_column(row_runs, split, other, below)
            widths = [right - left for _, left, right in branch[len(below):]]
            if branch[-1][0] < end and np.median(widths) >= HEAD_MIN_WIDTH * height:
                runs = branch
    if not runs:
        rows, columns = np.nonzero(mask)
        top_row = rows.min()
        return (float(columns[rows == top_row].mean()), float(top_row)), None
    top_row, left, right = runs[-1]
    # The head's highest pixel in the image, within the last coarse run (and the coarse cells above it).
    band = mask[max(top_row * HEAD_SCAN_SCALE - HEAD_SCAN_SCALE, 0):(top_row + 1) * HEAD_SCAN_SCALE,
                left * HEAD_SCAN_SCALE:right * HEAD_SCAN_SCALE]
    rows, columns = np.nonzero(band)
    first = rows.min()
    top = (float(columns[rows == first].mean() + left * HEAD_SCAN_SCALE),
           float(first + max(top_row * HEAD_SCAN_SCALE - HEAD_SCAN_SCALE, 0)))
    column = np.array(runs[::-1], float)   # from the top down
    widths = column[:, 2] - column[:, 1]
    length = len(column)
    head = widths[int(HEAD_WIDTH_BAND[0] * length):max(int(HEAD_WIDTH_BAND[1] * length), int(HEAD_WIDTH_BAND[0] * length) + 1)]
    wide = np.flatnonzero(widths >= SHOULDER_WIDENING * np.median(head))
    wide = wide[wide > int(HEAD_WIDTH_BAND[1] * length)]
    if not len(wide):
        return top, None
    row, left, right = column[wide[0]]
    stature = mask.shape[0] - top[1] if bottom is None else bottom - top[1]
    if not SHOULDER_DEPTH[0] * stature <= row * HEAD_SCAN_SCALE - top[1] <= SHOULDER_DEPTH[1] * stature:
        return top, None   # widening elsewhere: arms held out lower down, or a view from the side
    return top, (float(0.5 * (left + right) * HEAD_SCAN_SCALE), float(row * HEAD_SCAN_SCALE))


def trunk_column(row_runs, row, start, below):
    """head_column's walk up the coarse grid, whose runs per row are `row_runs` (foreground_runs), from `row` and
    the columns `start` (first, last + 1) there, after the runs `below` [(row, first, last + 1), ...] (from the
    centroid up). Returns the runs from the centroid up to where the
    walk ends, and the rows where it left other overlapping runs aside: [(row, [(first, last + 1), ...]), ...],
    from the lowest up."""
    runs, widths, splits = list(below), sorted(right - left for _, left, right in below), []
    left, right = start
    middle = 0.5 * (left + right)   # of the trunk: the last run not much wider than those so far (no arm held out)
    for row in range(row, -1, -1):
        overlapping = [(first, end) for first, end in row_runs[row] if first < right and end > left]
        if not overlapping:
            break
        if max(end - first for first, end in overlapping) > 1:   # a sliver of one coarse cell beside a wider
            overlapping = [(first, end) for first, end in overlapping if end - first > 1]   # run: keying noise
        chosen = min(overlapping, key=lambda run: abs(0.5 * (run[0] + run[1]) - middle))
        if len(overlapping) > 1:
            splits.append((row, [run for run in overlapping if run != chosen]))
        left, right = chosen
        runs.append((row, left, right))
        bisect.insort(widths, right - left)
        count = len(widths)   # their median, as np.median gives it (without its overhead in this loop)
        median = widths[count // 2] if count % 2 else 0.5 * (widths[count // 2 - 1] + widths[count // 2])
        if right - left <= TRUNK_WIDENING * median:   # a cell a row at most: a lean of 45° (an arm
            middle += min(max(0.5 * (left + right) - middle, -1.0), 1.0)   # touching the head jumps further)
    return runs, splits


def foreground_runs(mask):
    """Per row of a bool (H, W) mask, its runs of foreground, left to right: [[(first column, last column
    + 1), ...], ...] in Python ints (found for all rows at once: head_column's row-by-row walk then costs
    no NumPy call per row)."""
    padded = np.zeros((mask.shape[0], mask.shape[1] + 2), bool)
    padded[:, 1:-1] = mask
    rows, columns = np.nonzero(padded[:, 1:] != padded[:, :-1])   # row-major: a row's edges in pairs
    runs = [[] for _ in range(mask.shape[0])]
    for row, start, end in zip(rows[0::2].tolist(), columns[0::2].tolist(), columns[1::2].tolist()):
        runs[row].append((start, end))
    return runs


def _band_centroid(leg, first_row, bottom_row, height, band):
    """Centroid (x, y) of a leg's pixels between band[0] and band[1] × height above bottom_row; `leg`: the
    silhouette's rows from first_row on (bool (R, W)), none above them."""
    low = max(int(round(bottom_row - band[1] * height)), 0)
    high = int(round(bottom_row - band[0] * height)) + 1
    rows, columns = np.nonzero(leg[max(low - first_row, 0):max(high - first_row, 0)])
    if rows.size == 0:
        return None
    # Rows counted from `low` (not from the leg's first row) before their mean: the same floats as ever.
    return float(columns.mean()), float((rows + max(first_row - low, 0)).mean() + low)


def _legs(mask, bottom_row, height):
    """The legs: connected parts of the silhouette below LEG_CUT; when both feet merge into one
    part (legs crossing or together), that part is split at its median column. Worked on in the rows
    below the cut only."""
    cut = int(round(bottom_row - LEG_CUT * height))
    below = mask[cut:bottom_row + 1]
    labels, areas = components(below.astype(np.uint8))
    parts = sorted(range(1, len(areas)), key=lambda i: -areas[i])[:2]
    parts = [p for p in parts if areas[p] > 0.1 * areas[parts[0]]]
    legs = []
    if len(parts) == 2:
        for part in parts:
            leg = labels == part
            legs.append(_leg(leg, cut, cut + np.flatnonzero(leg.any(axis=1))[-1], bottom_row, height, confidence=0.9))
    elif len(parts) == 1:
        part_mask = labels == parts[0]
        split = int(np.median(np.nonzero(part_mask)[1]))
        for columns, confidence in (((0, split), 0.5), ((split, mask.shape[1]), 0.5)):
            leg = np.zeros_like(part_mask)
            leg[:, columns[0]:columns[1]] = part_mask[:, columns[0]:columns[1]]
            leg_rows = np.flatnonzero(leg.any(axis=1))
            if leg_rows.size:
                legs.append(_leg(leg, cut, cut + leg_rows[-1], bottom_row, height, confidence))
    legs = [leg for leg in legs if leg['ankle'] is not None]
    return sorted(legs, key=lambda leg: leg['ankle'][0])


def _leg(leg, first_row, leg_bottom, bottom_row, height, confidence):
    """Ankle: the shin's axis (principal axis of the leg's pixels in SHIN_BAND above its lowest pixel)
    followed down to where it leaves the leg (the sole, or the heel of a foot that points down at
    toe-off), then ANKLE_HEIGHT of the stature back up it. A centroid of the foot would be pulled
    towards the toes. Knee: above the floor contact (the lowest pixel of the whole silhouette),
    where both knees stay while walking. `leg`: bool (R, W), the leg's pixels in the silhouette mask's
    rows from first_row on; leg_bottom, bottom_row: rows [px] of the whole mask."""
    low = max(int(round(leg_bottom - SHIN_BAND[1] * height)), first_row)
    high = int(round(leg_bottom - SHIN_BAND[0] * height)) + 1
    rows, columns = np.nonzero(leg[low - first_row:max(high - first_row, 0)])
    ankle = None
    if rows.size >= 10:
        points = np.column_stack([columns, rows + low]).astype(float)
        center = points.mean(axis=0)
        _, _, axes = np.linalg.svd(points - center, full_matrices=False)
        down = axes[0] if axes[0][1] > 0 else -axes[0]
        # Walked in Python floats (the same float64 arithmetic, without NumPy's overhead per step).
        (x, y), (dx, dy) = center.tolist(), down.tolist()
        rows_held, width = leg.shape
        for _ in range(int(height)):
            column, row = int(round(x + dx)), int(round(y + dy)) - first_row
            if not (0 <= row < rows_held and 0 <= column < width and leg[row, column]):
                break
            x, y = x + dx, y + dy
        reach = ANKLE_HEIGHT * height
        ankle = (x - reach * dx, y - reach * dy)
    return {'ankle': ankle, 'knee': _band_centroid(leg, first_row, bottom_row, height, KNEE_BAND),
            'confidence': confidence}
