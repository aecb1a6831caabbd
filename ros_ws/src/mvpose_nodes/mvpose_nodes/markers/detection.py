"""Marker detection for paper 001's tracking: the red blobs of an image, the image the regions are
tracked in, the markers' names, regions and flags, and every number of the marker mode (MarkerSettings).

Images are RGB uint8 (H, W, 3); points (x, y) in pixels, x right, y down, origin at the centre of the
top-left pixel. Pure NumPy/OpenCV: no ROS. The method and its choices: markers/tracking.py.
"""
from dataclasses import dataclass

import cv2
import numpy as np

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
