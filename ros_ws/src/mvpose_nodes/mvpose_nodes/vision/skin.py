"""Skin detection by a colour-histogram log-likelihood ratio (paper 000 Sec. 3.2, after
Conaire, O'Connor et al. 2007, "Detector adaptation by maximising agreement between
independent data sources").

Labelled training pixels fill two RGB histograms of BINS³ bins (bin = value >> SHIFT per
channel): H for skin, h for non-skin. A pixel of colour (r, g, b) scores
L = log(H(r,g,b) / h(r,g,b)) with H, h normalised to probabilities (paper 000 Eq. 1);
L > threshold is skin, which morphology and a minimum region area then clean up.
"""
import dataclasses
import os
import zipfile

import cv2
import numpy as np

from mvpose_nodes.vision.silhouette import component_box, components


class SkinModelError(ValueError):
    """A skin colour model file that is missing or malformed; the message names the file."""


BINS = 32  # histogram levels per colour channel
SHIFT = 3  # 8-bit channel value >> SHIFT = bin index (256 / BINS = 2**SHIFT)
FORMAT_VERSION = 1  # of the .npz written by SkinModel.save
DEFAULT_ALPHA = 0.05  # weight of the uniform prior: 5 % of each class's probability spread over every colour
_SHAPE = (BINS, BINS, BINS)


def _bin_index(rgb):
    """Flat histogram bin r·BINS² + g·BINS + b of each pixel of an RGB uint8 (H, W, 3) image,
    as uint16 (H, W) (bit shifts: BINS³ = 2**15 fits in uint16, which keeps np.take fast)."""
    if rgb.dtype != np.uint8 or rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f'expected an RGB uint8 (H, W, 3) image, got {rgb.dtype} {rgb.shape}')
    levels = rgb >> SHIFT
    index = levels[..., 0].astype(np.uint16) << (2 * (8 - SHIFT))
    index |= levels[..., 1].astype(np.uint16) << (8 - SHIFT)
    index |= levels[..., 2]
    return index


def _check_mask(mask, shape, name):
    if mask.dtype != bool or mask.shape != shape:
        raise ValueError(f'{name} must be a bool {shape} mask, got {mask.dtype} {mask.shape}')


@dataclasses.dataclass(eq=False)
class SkinModel:
    """Skin and non-skin colour histograms and their smoothed log-likelihood ratio.

    skin_counts, background_counts: (BINS, BINS, BINS) float64 pixel counts per RGB bin
    (H and h of paper 000 Sec. 3.2). alpha: weight of the uniform prior (below).

    Empty bins: a plain ratio of normalised histograms is 0/0, ±inf or wildly noisy where
    few pixels were seen. Each class's colour distribution is instead the posterior mean under
    a Dirichlet prior whose pseudo-count per bin is alpha·N/BINS³ (N = the class's training
    pixels), i.e. the empirical histogram mixed with a uniform distribution over the colour cube:
        P(bin | class) = (count_bin + alpha·N/BINS³) / (N·(1 + alpha)) = (count_bin/N + alpha/BINS³) / (1 + alpha)
        L = log P(bin | skin) − log P(bin | non-skin)
    The prior scales with N so that the two classes are treated alike however unequal their
    training sets: a colour seen in neither class gets L = 0 exactly (no evidence either way, so a
    threshold > 0 keeps unseen colours out of the skin), while a plain add-one prior would give it
    the log ratio of the class sizes and call unseen colours skin whenever skin pixels are fewer.
    L is finite everywhere; a class with no pixels at all is uniform.

    Counts change only through `add` and `merge` (which drop the cached table).
    """
    skin_counts: np.ndarray
    background_counts: np.ndarray
    alpha: float = DEFAULT_ALPHA
    _table: np.ndarray = dataclasses.field(default=None, init=False, repr=False)

    def __post_init__(self):
        self.skin_counts = np.asarray(self.skin_counts, dtype=np.float64)
        self.background_counts = np.asarray(self.background_counts, dtype=np.float64)
        if self.skin_counts.shape != _SHAPE or self.background_counts.shape != _SHAPE:
            raise ValueError(f'counts must be {_SHAPE}, got {self.skin_counts.shape}, {self.background_counts.shape}')
        if not self.alpha > 0:
            raise ValueError(f'alpha must be > 0, got {self.alpha}')

    @classmethod
    def empty(cls, alpha=DEFAULT_ALPHA):
        """A model with no training pixels (L = 0 everywhere until `add`)."""
        return cls(np.zeros(_SHAPE), np.zeros(_SHAPE), alpha)

    @property
    def log_likelihood(self):
        """(BINS, BINS, BINS) float32 table of L per RGB bin (class docstring), cached."""
        if self._table is None:
            def smoothed(counts):
                total = counts.sum()
                empirical = counts / total if total else np.full(_SHAPE, 1.0 / BINS ** 3)
                return np.log((empirical + self.alpha / BINS ** 3) / (1 + self.alpha))
            self._table = (smoothed(self.skin_counts) - smoothed(self.background_counts)).astype(np.float32)
        return self._table

    def likelihood(self, rgb):
        """L per pixel, (H, W) float32, of an RGB uint8 (H, W, 3) image, by table look-up
        (about 5.5 ms for 1920×1080 on one core)."""
        return np.take(self.log_likelihood.ravel(), _bin_index(rgb))

    def add(self, rgb, skin_mask, valid_mask=None):
        """Count the pixels of one RGB uint8 (H, W, 3) image: skin where the bool (H, W)
        skin_mask is set, non-skin elsewhere, only where the bool (H, W) valid_mask is set
        (None = every pixel), e.g. the person and a band of background around it. Returns self."""
        index = _bin_index(rgb)
        _check_mask(skin_mask, index.shape, 'skin_mask')
        valid = np.ones(index.shape, bool) if valid_mask is None else valid_mask
        _check_mask(valid, index.shape, 'valid_mask')
        for counts, selected in ((self.skin_counts, valid & skin_mask), (self.background_counts, valid & ~skin_mask)):
            counts += np.bincount(index[selected], minlength=BINS ** 3).reshape(_SHAPE)
        self._table = None
        return self

    def merge(self, other):
        """Add the counts of another SkinModel (e.g. one trained in another process). Returns self."""
        self.skin_counts += other.skin_counts
        self.background_counts += other.background_counts
        self._table = None
        return self

    def save(self, path):
        """Write a compressed .npz at exactly `path`: both counts (uint32 when integral, else
        float64), alpha and the format version."""
        def stored(counts):
            integral = np.all(counts == np.round(counts)) and counts.max() <= np.iinfo(np.uint32).max
            return counts.astype(np.uint32) if integral else counts
        with open(path, 'wb') as file:  # a file object keeps numpy from appending '.npz'
            np.savez_compressed(file, skin_counts=stored(self.skin_counts),
                                background_counts=stored(self.background_counts),
                                alpha=np.float64(self.alpha), version=np.int64(FORMAT_VERSION))

    @classmethod
    def load(cls, path):
        """Read a model written by `save`; SkinModelError naming the file if it is missing or malformed."""
        if not os.path.isfile(path):
            raise SkinModelError(f'skin model {path}: no such file')
        try:
            stored = np.load(path, allow_pickle=False)
            if not isinstance(stored, np.lib.npyio.NpzFile):  # a bare .npy array
                raise ValueError
            with stored:
                arrays = {key: stored[key] for key in stored.files}
        except (OSError, ValueError, EOFError, zipfile.BadZipFile):
            raise SkinModelError(f'skin model {path}: not an .npz file written by SkinModel.save') from None
        missing = {'skin_counts', 'background_counts', 'alpha', 'version'} - arrays.keys()
        if missing:
            raise SkinModelError(f'skin model {path}: missing {", ".join(sorted(missing))}')
        if arrays['version'].shape != () or arrays['version'] != FORMAT_VERSION:
            raise SkinModelError(f'skin model {path}: format version {arrays["version"]}, expected {FORMAT_VERSION}')
        for key in ('skin_counts', 'background_counts'):
            counts = arrays[key]
            if counts.shape != _SHAPE or counts.dtype.kind not in 'uif' or not np.all(np.isfinite(counts) & (counts >= 0)):
                raise SkinModelError(f'skin model {path}: {key} must be {_SHAPE} finite non-negative numbers, '
                                f'got {counts.dtype} {counts.shape}')
        alpha = arrays['alpha']
        if alpha.shape != () or alpha.dtype.kind not in 'uif' or not alpha > 0:
            raise SkinModelError(f'skin model {path}: alpha must be a positive number, got {alpha}')
        return cls(arrays['skin_counts'], arrays['background_counts'], float(alpha))


def _disk(radius):
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))


def detect_skin(model, rgb, threshold=0.0, region=None, min_area=30, opening=1, closing=2):
    """Skin mask, bool (H, W), of an RGB uint8 (H, W, 3) image (paper 000 Sec. 3.2).

    Pixels with L > threshold (SkinModel.likelihood, natural log), only inside the bool (H, W)
    `region` (e.g. the silhouette; None = everywhere); then a morphological opening (elliptical
    kernel, radius `opening` px) removes speckle and a closing (radius `closing` px) fills small
    holes, both kept inside `region`; last, 8-connected regions under `min_area` px are dropped.
    With a region only its bounding box (plus the morphology's reach) is processed.
    """
    height, width = rgb.shape[:2]
    window = (slice(0, height), slice(0, width))
    if region is not None:
        _check_mask(region, (height, width), 'region')
        x, y, w, h = cv2.boundingRect(region.view(np.uint8))
        if w == 0:
            return np.zeros((height, width), bool)
        # Margin = how far opening + closing reach, so the crop's border changes nothing.
        margin = 2 * (opening + closing)
        window = (slice(max(y - margin, 0), min(y + h + margin, height)),
                  slice(max(x - margin, 0), min(x + w + margin, width)))
    skin = (model.likelihood(rgb[window]) > threshold).view(np.uint8)
    inside = None if region is None else region[window]
    if inside is not None:
        skin &= inside
    for operation, radius in ((cv2.MORPH_OPEN, opening), (cv2.MORPH_CLOSE, closing)):
        if radius > 0:
            skin = cv2.morphologyEx(skin, operation, _disk(radius))
    if inside is not None:
        skin &= inside  # closing may bridge into concavities of the region
    skin = skin.view(bool)
    if min_area > 1:
        labels, areas = components(skin)
        large = areas >= min_area
        large[0] = False  # label 0 is the background
        if not large[1:].all():   # else no pass over the window: nothing to drop
            skin = large[labels]
    mask = np.zeros((height, width), bool)
    mask[window] = skin
    return mask


@dataclasses.dataclass(eq=False)
class SkinRegion:
    """One 8-connected region of a skin mask, in pixels: label in the component image, area,
    bbox (x, y, w, h), centroid float64 (2,) (x, y), boundary int32 (N, 2) points (x, y) of its
    outer contour (cv2.findContours, CHAIN_APPROX_NONE)."""
    label: int
    area: int
    bbox: tuple
    centroid: np.ndarray
    boundary: np.ndarray


def skin_regions(mask, min_area=30):
    """The 8-connected regions of a bool (H, W) skin mask with at least min_area px, largest first."""
    labels, areas = components(mask)
    regions = []
    for label in np.flatnonzero(areas >= min_area):
        if label == 0:
            continue
        x, y, w, h = component_box(labels, label)
        # One pixel of padding so the contour of a region touching the crop edge is traced in full.
        crop = np.pad(labels[y:y + h, x:x + w] == label, 1).view(np.uint8)
        rows, columns = np.nonzero(crop)
        centroid = np.array([columns.mean() + x - 1, rows.mean() + y - 1])
        contours, _ = cv2.findContours(crop, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        outer = max(contours, key=len).reshape(-1, 2) + (x - 1, y - 1)
        regions.append(SkinRegion(int(label), int(areas[label]), (x, y, w, h), centroid, outer.astype(np.int32)))
    return sorted(regions, key=lambda region: -region.area)


def surround_contrast(rgb, skin, region, silhouette, band):
    """How much a skin region's colour differs from the person around it: the CIE a*b* distance between the
    mean colour of its pixels and that of the non-skin `silhouette` pixels within `band` px of it, or None
    when there are none. rgb: the RGB uint8 (H, W, 3) image; skin, silhouette: bool (H, W) masks of it;
    region: a SkinRegion of `skin`. Colours in OpenCV's 8-bit Lab, whose a* and b* are CIE units + 128.

    Why: clothes whose colour is near skin's cross the skin threshold in patches, where their shading
    happens to match; such a patch has the colour of the cloth around it (a* b* within 1.5 in the median on
    the suite's tuning renders), while a hand or forearm differs from its sleeve or the shirt behind it (15)."""
    height, width = skin.shape
    x, y, w, h = region.bbox
    window = (slice(max(y - band, 0), min(y + h + band, height)),
              slice(max(x - band, 0), min(x + w + band, width)))
    inside = np.zeros(skin[window].shape, np.uint8)
    cv2.drawContours(inside, [region.boundary.reshape(-1, 1, 2)], -1, 1, cv2.FILLED,
                     offset=(-window[1].start, -window[0].start))
    inside = inside.view(bool) & skin[window]
    near = cv2.dilate(inside.view(np.uint8), np.ones((2 * band + 1,) * 2, np.uint8)).view(bool)
    around = near & ~skin[window] & silhouette[window]
    if not around.any() or not inside.any():
        return None
    crop = rgb[window]

    def mean_chroma(mask):
        # The pixels as one row: cvtColor's cost per row dwarfs a pixel's (a column of them took 7 times as long).
        return cv2.cvtColor(crop[mask].reshape(1, -1, 3), cv2.COLOR_RGB2LAB).reshape(-1, 3)[:, 1:].mean(axis=0)
    return float(np.linalg.norm(mean_chroma(inside) - mean_chroma(around)))


def skin_on_cloth(rgb, skin, regions, max_area, redness, opening):
    """The skin mask with the skin-coloured cloth taken out of it (beyond paper 000 Sec. 3.2). Each of
    `regions` (SkinRegions of `skin`) larger than `max_area` px is too large for a hand or a forearm: it is
    clothing whose colour the skin model takes for skin (a beige shirt, khaki trousers), with perhaps the
    hands or forearms that touch it. Of its pixels only those whose CIE a* exceeds the region's median a*
    by more than `redness` stay skin, opened with a disc of radius `opening` px (the cloth's stray pixels go).
    rgb: the RGB uint8 (H, W, 3) image; skin: its bool (H, W) skin mask. Returns (the bool (H, W) mask, a
    copy if anything changed; whether anything did).

    Why a*, one-sided: the cloth is most of such a region, so its median is the cloth's colour, and skin is
    redder than the clothes the skin model mistakes for it (beige shirts on the suite's renders: a* 129–132
    against 134–138 for the hands on them, in OpenCV's 8-bit Lab, a* + 128), while b* overlaps and L* follows
    the shading. Cloth in shadow has less chroma, so it is not redder than the lit cloth."""
    large = [region for region in regions if region.area > max_area]
    if not large:
        return skin, False
    labels, _ = components(skin)
    skin = skin.copy()
    kernel = _disk(opening)
    for region in large:
        x, y, w, h = region.bbox
        window = (slice(y, y + h), slice(x, x + w))
        inside = labels[window] == region.label
        # The pixels as one row: cvtColor's cost per row dwarfs a pixel's (as in surround_contrast).
        reds = cv2.cvtColor(rgb[window][inside].reshape(1, -1, 3), cv2.COLOR_RGB2LAB)[0, :, 1].astype(np.int16)
        redder = np.zeros((h, w), np.uint8)
        redder[inside] = reds > np.median(reds) + redness
        skin[window] &= ~inside
        skin[window] |= cv2.morphologyEx(redder, cv2.MORPH_OPEN, kernel).view(bool)
    return skin, True


def warm_up():
    """Convert one pixel to Lab, so that OpenCV builds its 8-bit RGB→Lab tables (surround_contrast's
    conversion; 60–70 ms on the first call, a sixth of a 1080p image's features) while a node starts,
    not in its first image. The camera_features node calls this."""
    cv2.cvtColor(np.zeros((1, 1, 3), np.uint8), cv2.COLOR_RGB2LAB)


def mask_counts(predicted, truth):
    """(true positives, predicted, true) pixel counts of two bool masks of the same shape."""
    if predicted.shape != truth.shape:
        raise ValueError(f'mask shapes differ: {predicted.shape} vs {truth.shape}')
    return np.count_nonzero(predicted & truth), np.count_nonzero(predicted), np.count_nonzero(truth)


def scores_of_counts(true_positives, predicted_count, truth_count):
    """(precision, recall, F1) from pixel counts (summed over many images, for evaluation)."""
    precision = true_positives / predicted_count if predicted_count else 0.0
    recall = true_positives / truth_count if truth_count else 0.0
    f1 = 2 * precision * recall / (precision + recall) if precision + recall else 0.0
    return float(precision), float(recall), float(f1)
