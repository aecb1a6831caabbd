"""One camera's evidence for one frame (View), made from its features, and which views a frame set is fitted to.

A view the image's edge cuts the person off in (beyond the paper, whose cameras see the whole person):
its silhouette's keypoints are left out (the cut silhouette's shape no longer says where the knees and
ankles are), and when much of its outline lies along the edge (over `cut_share` of its contour pixels,
FitterSettings) and at least MIN_WHOLE_VIEWS other views are cut less, it is left out of the frame set:
a runner leaving the middle of an 8-camera ring, cut off in five views and seen whole in three, was fitted
320–400 mm off from the cut views' outlines (docs/method.md, sessions 48 and 50).
No ROS.
"""
from dataclasses import dataclass

import numpy as np

from mvpose_nodes.fitting.compiled import MAP_LABELS
from mvpose_nodes.fitting.initialisation import hair_gap
from mvpose_nodes.fitting.objective import EDGE_PX, MapArena, boundary_distances, map_floats, outline_of

# Keypoints read off the silhouette's shape (vision/silhouette.py): wrong once the image cuts the person off,
# so left out then; but the root (the silhouette's centroid), shifted as it is, is kept at CUT_ROOT_CONFIDENCE
# of its confidence: without it, a person cut off in every view (close to the cameras) has no start at all.
SILHOUETTE_KEYPOINTS = ('left_knee', 'right_knee', 'left_ankle', 'right_ankle')
CUT_ROOT_CONFIDENCE = 0.2
# Views that must be left for a cut view to be left out: two do not hold a fit (a 3-camera run with a cut
# view left out: 75 → 389 mm; docs/method.md, session 48).
MIN_WHOLE_VIEWS = 3


@dataclass
class View:
    """One camera's evidence for one frame: its Camera, the boundary distance maps of its labelled
    contour (objective.BoundaryDistances, or None), its 2D keypoints {name: (x, y, confidence)}, how
    much of the face it sees (features.Features.frontness; None if unknown), its outline
    (objective.Outline, or None), its skin regions (N, 3): centre x, y [px] and area [px²] (or None), where
    the face's skin begins below the top of the head (initialisation.hair_gap; None if unknown), and the
    share of its contour's pixels on the image's edge (edge_share; 0: the person is seen whole)."""
    camera: object
    distances: object
    keypoints: dict
    frontness: float = None
    outline: object = None
    skin: np.ndarray = None
    hair_gap: float = None
    edge_share: float = 0.0


def view_from_features(camera, keypoints, contour, frontness=None, skin=None, face_top=None, arena=None):
    """A View of one camera from its features: keypoints {name: (x, y, confidence)} (the visible ones),
    its ContourLabels (or None), its frontness, its skin regions [(x, y, area)] (the skin ellipses'
    centres [px] and areas [px²]) and its face ellipse's topmost row [px] (vision.features.ellipse_top; None
    without one); its distance maps in `arena` (objective.MapArena, sized by frame_set_arena) if given."""
    distances = outline = None
    cut = 0.0
    if contour is not None and len(contour.points):
        distances = boundary_distances(contour, (camera.width, camera.height), MAP_LABELS, arena=arena)
        outline = outline_of(contour.points, (camera.width, camera.height), arena=arena)
        cut = edge_share(contour.points, camera)
        if cut > 0:   # the silhouette's shape no longer says where the knees and ankles are
            keypoints = {name: value for name, value in keypoints.items() if name not in SILHOUETTE_KEYPOINTS}
            if 'root' in keypoints:
                x, y, confidence = keypoints['root']
                keypoints['root'] = (x, y, confidence * CUT_ROOT_CONFIDENCE)
    skin = None if skin is None else np.asarray(skin, float).reshape(-1, 3)
    return View(camera, distances, keypoints, frontness, outline, skin, hair_gap(face_top, keypoints), cut)


def edge_share(contour_points, camera):
    """The share of a contour's pixels (N, 2) [px], N > 0, within EDGE_PX of the camera's image edge: 0 when
    the image shows the whole person, more the more of the person it cuts off."""
    x, y = np.asarray(contour_points).T
    return float(np.mean((x < EDGE_PX) | (x >= camera.width - EDGE_PX) | (y < EDGE_PX) | (y >= camera.height - EDGE_PX)))


def whole_views(views, cut_share):
    """The views (View) a frame set is fitted to: those with an edge_share of at most `cut_share` if there are
    MIN_WHOLE_VIEWS of them, else all."""
    whole = [view for view in views if view.edge_share <= cut_share]
    return whole if len(whole) >= MIN_WHOLE_VIEWS else views


def frame_set_arena(contours):
    """The objective.MapArena for the views of a frame set's ContourLabels (None for a camera without)."""
    return MapArena(sum(map_floats(c.points, 2 * len(MAP_LABELS)) for c in contours if c is not None))
