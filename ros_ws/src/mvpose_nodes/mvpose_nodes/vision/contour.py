"""Body-part labelling of a silhouette's outer contour (paper 000 Sec. 3.3).

The contour is a graph G = (V, E): the vertices are the contour pixels, the edges join contour
pixels that are 8-neighbours, weighted by their Euclidean distance (1 or √2 px). A path's weight
is w(p) = Σ w(v_i, v_i+1) (paper 000 Eq. 2); the Dijkstra shortest path between two keypoints'
contour vertices labels the pixels between them as one body part. Head, torso and legs each get
their two boundaries (SIDE_A, SIDE_B), which the fitting objective (paper 000 Eq. 4) compares with
the model's; hand pixels are labelled from skin. Pixel axes: x right (column), y down (row).
"""
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from mvpose_nodes.body.model import (LABEL_HEAD, LABEL_LEFT_HAND, LABEL_LEFT_LEG, LABEL_NONE, LABEL_RIGHT_HAND,
                                     LABEL_RIGHT_LEG, LABEL_TORSO)

# The values of mvpose_msgs/LabelledContour's SIDE_* constants: which of a part's two boundaries.
SIDE_NONE = 0
SIDE_A = 1
SIDE_B = 2

ROW_BAND_FRACTION = 0.02  # neck/root side landmarks are searched within ± this fraction of the contour height
HAND_DILATION_PX = 2      # skin masks stop just inside the silhouette edge: grow them onto the contour
# Half of the 8-neighbourhood (dx, dy): each unordered neighbour pair is found once, then mirrored.
HALF_NEIGHBOURHOOD = ((1, 0), (0, 1), (1, 1), (1, -1))


@dataclass
class ContourLabels:
    """The labelled outer contour: points (N, 2) int32 [px] (x, y) in contour order; labels (N,) uint8
    LABEL_*; sides (N,) uint8 SIDE_*; landmarks: name -> vertex index of the contour landmarks used."""
    points: np.ndarray
    labels: np.ndarray
    sides: np.ndarray
    landmarks: dict = field(default_factory=dict)


def outer_contour(silhouette):
    """The outer boundary of the largest foreground blob of a (H, W) bool/uint8 mask: (N, 2) int32 [px]
    (x, y), ordered (consecutive points 8-neighbours) and closed (the last adjoins the first); (0, 2) when
    the mask is empty. cv2.findContours (RETR_EXTERNAL, CHAIN_APPROX_NONE) on the foreground's bounding box."""
    mask = np.asarray(silhouette).astype(np.uint8)
    x0, y0, width, height = cv2.boundingRect(mask)
    if width == 0:
        return np.zeros((0, 2), np.int32)
    # A 1 px background frame, so that blobs touching the box edge are traced like any other.
    crop = cv2.copyMakeBorder(mask[y0:y0 + height, x0:x0 + width], 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0)
    contours, _ = cv2.findContours(crop, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    largest = max(contours, key=lambda contour: (cv2.contourArea(contour), len(contour)))
    return (largest.reshape(-1, 2) + (x0 - 1, y0 - 1)).astype(np.int32)


def _pixel_table(points):
    """Pixel keys of (N, 2) points: (stride, sorted unique keys (M,), first vertex of each unique pixel (M,),
    index into the unique keys of each point (N,)). Key = (x + 1)·stride + y + 1, unique also for neighbours."""
    points = np.asarray(points, np.int64).reshape(-1, 2)
    stride = int(points[:, 1].max()) + 3 if len(points) else 1
    keys = (points[:, 0] + 1) * stride + points[:, 1] + 1
    unique_keys, first_vertex, inverse = np.unique(keys, return_index=True, return_inverse=True)
    return stride, unique_keys, first_vertex, inverse


def contour_graph(points):
    """The contour graph of paper 000 Sec. 3.3: a symmetric (N, N) CSR matrix of float64 edge weights [px]
    between every two contour pixels that are 8-neighbours (1 side by side, √2 diagonally), found by pixel
    adjacency. A pixel the contour visits twice (a 1 px wide spur) is one vertex, its first visit; later
    visits stay isolated."""
    stride, unique_keys, first_vertex, _ = _pixel_table(points)
    count = len(np.asarray(points).reshape(-1, 2))
    if count == 0:
        return csr_matrix((0, 0))
    sources, targets, weights = [], [], []
    for dx, dy in HALF_NEIGHBOURHOOD:
        neighbour_keys = unique_keys + dx * stride + dy
        position = np.searchsorted(unique_keys, neighbour_keys).clip(max=len(unique_keys) - 1)
        found = unique_keys[position] == neighbour_keys
        sources.append(first_vertex[found])
        targets.append(first_vertex[position[found]])
        weights.append(np.full(np.count_nonzero(found), np.hypot(dx, dy)))
    sources, targets, weights = map(np.concatenate, (sources, targets, weights))
    return csr_matrix((np.concatenate([weights, weights]),
                       (np.concatenate([sources, targets]), np.concatenate([targets, sources]))), shape=(count, count))


def shortest_path(graph, source, target, blocked=()):
    """The minimum-weight path (paper 000 Eq. 2) from vertex `source` to vertex `target` of a contour graph:
    a list of vertex indices, source first; [] when unreachable. The path cannot pass through the vertices in
    `blocked` (other landmarks, so that it cannot go the wrong way round the body); source and target are
    never blocked. Dijkstra from the source (scipy.sparse.csgraph.dijkstra). The graph is changed while the
    call lasts and then restored (a copy per call took a fifth of the contour's labelling)."""
    # An infinite weight on every edge leaving a blocked vertex: reachable, but a dead end.
    edges = [slice(graph.indptr[vertex], graph.indptr[vertex + 1]) for vertex in set(blocked) - {source, target}]
    weights = [graph.data[edge].copy() for edge in edges]
    try:
        for edge in edges:
            graph.data[edge] = np.inf
        _, predecessors = dijkstra(graph, indices=source, return_predecessors=True)
    finally:
        for edge, weight in zip(edges, weights):
            graph.data[edge] = weight
    if source != target and predecessors[target] < 0:
        return []
    predecessors = predecessors.tolist()  # Python ints walk faster than NumPy scalars
    vertex, path = target, [target]
    while vertex != source:
        vertex = predecessors[vertex]
        path.append(vertex)
    return path[::-1]


def _nearest(points, keypoint, candidates):
    """The vertex among `candidates` (indices) nearest to keypoint (x, y) [px]; the first of equals."""
    return int(candidates[np.argmin(np.hypot(*(points[candidates] - keypoint).T))])


def _nearest_on_each_side(points, keypoint, band):
    """The contour vertices nearest to keypoint (x, y) [px] among those within ±band rows of it, on its
    image-left (x < keypoint x) and image-right side: (vertex or None, vertex or None). The band doubles
    until a side has candidates or spans the whole contour."""
    row_offset = np.abs(points[:, 1] - keypoint[1])
    found = []
    for on_side in (points[:, 0] < keypoint[0], points[:, 0] >= keypoint[0]):
        half_width = band
        candidates = np.flatnonzero(on_side & (row_offset <= half_width))
        while not len(candidates) and half_width < row_offset.max():
            half_width *= 2
            candidates = np.flatnonzero(on_side & (row_offset <= half_width))
        found.append(_nearest(points, keypoint, candidates) if len(candidates) else None)
    return found


def label_contour(silhouette, keypoints, hand_masks=None):
    """Label the outer contour of a (H, W) silhouette mask by body part and side (paper 000 Sec. 3.3).

    keypoints: name -> (x, y) [px] or None, names 'head' (top of head), 'neck' (base of neck), 'root'
    (silhouette centroid ≈ pelvis), 'left_ankle', 'right_ankle'. hand_masks: optional {'left', 'right'}
    -> (H, W) bool skin regions of the hands. Landmarks (vertex indices): 'head' nearest to the head
    keypoint; 'neck_a'/'neck_b' and 'waist_a'/'waist_b' nearest to the neck and root keypoints on their
    image-left/right at about their row; '<left|right>_foot' nearest to each ankle; 'crotch' the highest
    vertex of the inner-leg arc between the feet. Shortest paths between landmarks, each with the other
    landmarks blocked, label head (neck_a-head A, head-neck_b B), torso (neck_a-waist_a A, neck_b-waist_b B)
    and legs (image-left leg: waist_a-foot A outer, foot-crotch B inner; the other: crotch-foot A inner,
    foot-waist_b B outer); hand pixels then override. Missing keypoints leave their parts LABEL_NONE.
    """
    points = outer_contour(silhouette)
    labels = np.full(len(points), LABEL_NONE, np.uint8)
    sides = np.full(len(points), SIDE_NONE, np.uint8)
    result = ContourLabels(points, labels, sides)
    if not len(points):
        return result
    graph = contour_graph(points)
    landmarks = result.landmarks
    band = max(2.0, ROW_BAND_FRACTION * np.ptp(points[:, 1]))
    present = {name: np.asarray(xy, float) for name, xy in keypoints.items() if xy is not None}
    if 'head' in present:
        landmarks['head'] = _nearest(points, present['head'], np.arange(len(points)))
    for keypoint, landmark in (('neck', 'neck'), ('root', 'waist')):
        if keypoint in present:
            for side, vertex in zip('ab', _nearest_on_each_side(points, present[keypoint], band)):
                if vertex is not None:
                    landmarks[f'{landmark}_{side}'] = vertex
    feet = [f'{side}_foot' for side in ('left', 'right') if f'{side}_ankle' in present]
    for foot in feet:
        landmarks[foot] = _nearest(points, present[foot.replace('foot', 'ankle')], np.arange(len(points)))

    segments = [('neck_a', 'head', LABEL_HEAD, SIDE_A), ('head', 'neck_b', LABEL_HEAD, SIDE_B),
                ('neck_a', 'waist_a', LABEL_TORSO, SIDE_A), ('neck_b', 'waist_b', LABEL_TORSO, SIDE_B)]
    # With the head and neck blocked, the only way between the feet is the inner-leg arc.
    two_feet = len(feet) == 2 and landmarks[feet[0]] != landmarks[feet[1]]
    inner_arc = shortest_path(graph, landmarks[feet[0]], landmarks[feet[1]],
                              [landmarks[name] for name in ('head', 'neck_a', 'neck_b') if name in landmarks]
                              ) if two_feet else []
    if inner_arc:
        arc_rows = points[inner_arc, 1]
        highest = np.flatnonzero(arc_rows == arc_rows.min())
        landmarks['crotch'] = inner_arc[highest[len(highest) // 2]]  # the middle of a flat crotch
        image_left, image_right = sorted(feet, key=lambda foot: points[landmarks[foot], 0])
        left_label, right_label = (LABEL_LEFT_LEG if foot == 'left_foot' else LABEL_RIGHT_LEG
                                   for foot in (image_left, image_right))
        segments += [('waist_a', image_left, left_label, SIDE_A), (image_left, 'crotch', left_label, SIDE_B),
                     ('crotch', image_right, right_label, SIDE_A), (image_right, 'waist_b', right_label, SIDE_B)]
    for source, target, label, side in segments:
        # Coinciding landmarks make a degenerate segment: nothing between them to label.
        if source in landmarks and target in landmarks and landmarks[source] != landmarks[target]:
            path = shortest_path(graph, landmarks[source], landmarks[target], landmarks.values())
            labels[path], sides[path] = label, side

    # Later visits of a pixel (isolated in the graph) take the label of its first visit.
    _, _, first_vertex, inverse = _pixel_table(points)
    labels[:], sides[:] = labels[first_vertex[inverse]], sides[first_vertex[inverse]]

    # Dilation at a contour pixel sees only the mask within HAND_DILATION_PX of it: the contour's box grown so.
    x0, y0 = np.maximum(points.min(axis=0) - HAND_DILATION_PX, 0)
    x1, y1 = points.max(axis=0) + HAND_DILATION_PX + 1
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * HAND_DILATION_PX + 1,) * 2)
    for hand, label in (('left', LABEL_LEFT_HAND), ('right', LABEL_RIGHT_HAND)):
        if hand_masks and hand_masks.get(hand) is not None:
            skin = cv2.dilate(np.asarray(hand_masks[hand])[y0:y1, x0:x1].astype(np.uint8), kernel)
            on_hand = skin[points[:, 1] - y0, points[:, 0] - x0] > 0
            labels[on_hand], sides[on_hand] = label, SIDE_NONE
    return result
