"""Contour labelling by shortest paths on the contour graph (paper 000 Sec. 3.3), on synthetic silhouettes.

Speed (not asserted): label_contour on the 1920×1080 standing person below (3680 contour vertices)
takes about 2.8 ms, outer_contour 0.45 ms of it (measured on the development machine).
"""
import cv2
import numpy as np
import pytest

from mvpose_nodes.body.model import (LABEL_HEAD, LABEL_LEFT_HAND, LABEL_LEFT_LEG, LABEL_NONE, LABEL_RIGHT_HAND,
                                     LABEL_RIGHT_LEG, LABEL_TORSO)
from mvpose_nodes.vision.contour import (SIDE_A, SIDE_B, SIDE_NONE, contour_graph, label_contour, outer_contour,
                                  shortest_path)

pytestmark = pytest.mark.pure

ROWS, COLS = 1080, 1920
# Image-left leg (the person's right, facing the camera) and image-right leg: centre lines, 60 px thick.
LEG_IMAGE_LEFT = ((915, 590), (820, 1000))
LEG_IMAGE_RIGHT = ((1005, 590), (1100, 1000))
HAND_CENTRES = {'right': (760, 560), 'left': (1160, 560)}  # the arms' ends (the person's right is image-left)
KEYPOINTS = {'head': (960, 140), 'neck': (960, 290), 'root': (960, 520),
             'left_ankle': (1095, 990), 'right_ankle': (825, 990)}
DIAGONAL = np.sqrt(2)


def standing_person():
    """(ROWS, COLS) bool: a person facing the camera, legs apart, arms hanging away from the torso."""
    mask = np.zeros((ROWS, COLS), np.uint8)
    cv2.ellipse(mask, (960, 200), (45, 60), 0, 0, 360, 1, -1)   # head: top at row 140
    cv2.rectangle(mask, (935, 250), (985, 300), 1, -1)           # neck
    cv2.rectangle(mask, (870, 300), (1050, 600), 1, -1)          # torso: columns 870..1050
    for start, end in (LEG_IMAGE_LEFT, LEG_IMAGE_RIGHT):
        cv2.line(mask, start, end, 1, 60)
    for shoulder, hand in (((885, 320), HAND_CENTRES['right']), ((1035, 320), HAND_CENTRES['left'])):
        cv2.line(mask, shoulder, hand, 1, 35)
    return mask.astype(bool)


def diamond(radius=40, centre=(100, 100)):
    """|x - cx| + |y - cy| <= radius: its contour is a pure cycle of 4·radius diagonal (√2) steps."""
    rows, cols = np.mgrid[:200, :200]
    return np.abs(cols - centre[0]) + np.abs(rows - centre[1]) <= radius


def path_length(points, path):
    return np.hypot(*np.diff(points[path], axis=0).T).sum()


def leg_centre_x(leg, row):
    (x0, y0), (x1, y1) = leg
    return x0 + (row - y0) * (x1 - x0) / (y1 - y0)


@pytest.fixture(scope='module')
def person():
    return standing_person()


@pytest.fixture(scope='module')
def labelled(person):
    return label_contour(person, KEYPOINTS)


def test_outer_contour_is_the_closed_boundary_of_the_largest_blob():
    mask = np.zeros((ROWS, COLS), bool)
    cv2.ellipse(mask.view(np.uint8), (700, 500), (150, 350), 0, 0, 360, 1, -1)
    mask[10:30, 10:30] = True  # a smaller blob elsewhere
    points = outer_contour(mask)
    assert points.dtype == np.int32 and points.shape[1] == 2
    x, y = points.T
    assert mask[y, x].all() and x.min() == 550 and y.min() == 150  # on the ellipse, in image coordinates
    padded = np.pad(mask, 1)
    assert (~padded[y, x + 1] | ~padded[y + 2, x + 1] | ~padded[y + 1, x] | ~padded[y + 1, x + 2]).all()  # on its edge
    steps = np.abs(np.diff(np.vstack([points, points[:1]]), axis=0)).max(axis=1)
    assert (steps == 1).all()  # ordered and closed: every step, also last to first, to an 8-neighbour
    assert np.array_equal(outer_contour(mask.astype(np.uint8) * 255), points)
    assert outer_contour(np.zeros((ROWS, COLS), bool)).shape == (0, 2)


def test_contour_graph_joins_8_neighbouring_contour_pixels(person):
    points = outer_contour(person)
    graph = contour_graph(points)
    assert graph.shape == (len(points),) * 2 and (graph != graph.T).nnz == 0
    assert np.all(np.isclose(graph.data, 1) | np.isclose(graph.data, DIAGONAL))
    degree = np.diff(graph.indptr)
    assert np.mean(degree == 2) > 0.9 and degree.min() >= 2  # staircase corners also have a diagonal shortcut
    following = np.roll(np.arange(len(points)), -1)
    assert np.all(graph[np.arange(len(points)), following] > 0)  # consecutive contour pixels are joined
    # Edges come from pixel adjacency, not from the order of the points.
    order = np.random.default_rng(0).permutation(len(points))
    assert (contour_graph(points[order]) != graph[order][:, order]).nnz == 0


@pytest.mark.parametrize('target', [1, 37, 80, 81, 123, 159])
def test_shortest_path_is_the_shorter_arc(target):
    points = outer_contour(diamond())
    assert len(points) == 160
    path = shortest_path(contour_graph(points), 0, target)
    closed = np.vstack([points, points[:1]])
    forward_arc = path_length(closed, np.arange(target + 1))
    backward_arc = path_length(closed, np.arange(target, len(points) + 1))
    assert path[0] == 0 and path[-1] == target
    assert np.isclose(path_length(points, path), min(forward_arc, backward_arc))


def test_shortest_path_avoids_blocked_vertices():
    points = outer_contour(diamond())
    graph = contour_graph(points)
    assert shortest_path(graph, 0, 30) == list(range(31))
    around = shortest_path(graph, 0, 30, blocked=[15, 0, 30])  # source and target are never blocked
    assert 15 not in around and around[0] == 0 and around[-1] == 30
    assert np.isclose(path_length(points, around), 130 * DIAGONAL)
    assert shortest_path(graph, 0, 30, blocked=[15, 100]) == []
    assert shortest_path(graph, 7, 7) == [7]
    # The blocked vertices' edges are restored: the graph is the contour's again, and a path free again.
    assert (graph != contour_graph(points)).nnz == 0
    assert shortest_path(graph, 0, 30) == list(range(31))


def test_label_contour_landmarks(labelled):
    points, landmarks = labelled.points, labelled.landmarks
    assert set(landmarks) == {'head', 'neck_a', 'neck_b', 'waist_a', 'waist_b', 'left_foot', 'right_foot', 'crotch'}
    assert tuple(points[landmarks['head']]) == (960, 140)
    assert tuple(points[landmarks['neck_a']]) == (935, 290) and tuple(points[landmarks['neck_b']]) == (985, 290)
    assert tuple(points[landmarks['waist_a']]) == (870, 520) and tuple(points[landmarks['waist_b']]) == (1050, 520)
    for foot in ('left', 'right'):
        assert np.hypot(*(points[landmarks[f'{foot}_foot']] - KEYPOINTS[f'{foot}_ankle'])) < 40
    crotch_x, crotch_y = points[landmarks['crotch']]
    inner_left = leg_centre_x(LEG_IMAGE_LEFT, crotch_y) + 30
    inner_right = leg_centre_x(LEG_IMAGE_RIGHT, crotch_y) - 30
    assert 598 <= crotch_y <= 605 and inner_left < crotch_x < inner_right


def test_label_contour_parts_and_sides(labelled):
    x, y = labelled.points.T
    labels, sides = labelled.labels, labelled.sides
    head = y < 245
    assert np.all(labels[head] == LABEL_HEAD)
    assert np.all(sides[head & (x < 955)] == SIDE_A) and np.all(sides[head & (x > 965)] == SIDE_B)
    flank = (420 <= y) & (y <= 510)
    assert np.all(labels[flank & (x == 870)] == LABEL_TORSO) and np.all(sides[flank & (x == 870)] == SIDE_A)
    assert np.all(labels[flank & (x == 1050)] == LABEL_TORSO) and np.all(sides[flank & (x == 1050)] == SIDE_B)
    shins = (700 <= y) & (y <= 950)
    image_left_centre, image_right_centre = leg_centre_x(LEG_IMAGE_LEFT, y), leg_centre_x(LEG_IMAGE_RIGHT, y)
    for edge, label, side in ((x < image_left_centre, LABEL_RIGHT_LEG, SIDE_A),                  # outer
                              ((x > image_left_centre) & (x < 960), LABEL_RIGHT_LEG, SIDE_B),  # inner
                              ((x > 960) & (x < image_right_centre), LABEL_LEFT_LEG, SIDE_A),  # inner
                              (x > image_right_centre, LABEL_LEFT_LEG, SIDE_B)):               # outer
        assert np.count_nonzero(shins & edge) > 200
        assert np.all(labels[shins & edge] == label) and np.all(sides[shins & edge] == side)
    assert np.mean(labels != LABEL_NONE) > 0.99  # the arms go to torso or legs
    assert np.all((labels == LABEL_NONE) == (sides == SIDE_NONE))


def test_leg_labels_follow_the_ankle_keypoint_names(person, labelled):
    swapped = dict(KEYPOINTS, left_ankle=KEYPOINTS['right_ankle'], right_ankle=KEYPOINTS['left_ankle'])
    relabelled = label_contour(person, swapped)
    swap = {LABEL_LEFT_LEG: LABEL_RIGHT_LEG, LABEL_RIGHT_LEG: LABEL_LEFT_LEG}
    assert np.array_equal(relabelled.labels, [swap.get(label, label) for label in labelled.labels])
    assert np.array_equal(relabelled.sides, labelled.sides)


def test_hand_masks_override(person, labelled):
    rows, cols = np.mgrid[:ROWS, :COLS]
    hand_masks = {hand: person & (np.hypot(cols - cx, rows - cy) <= 22) for hand, (cx, cy) in HAND_CENTRES.items()}
    with_hands = label_contour(person, KEYPOINTS, hand_masks)
    points = with_hands.points
    for hand, label in (('left', LABEL_LEFT_HAND), ('right', LABEL_RIGHT_HAND)):
        near = np.hypot(*(points - HAND_CENTRES[hand]).T) <= 22
        assert near.sum() > 20 and np.all(with_hands.labels[near] == label)
        assert np.all(with_hands.sides[near] == SIDE_NONE)
    far = np.hypot(*(points - HAND_CENTRES['left']).T).clip(max=np.hypot(*(points - HAND_CENTRES['right']).T)) > 30
    assert np.array_equal(with_hands.labels[far], labelled.labels[far])
    assert np.array_equal(label_contour(person, KEYPOINTS, {'left': None}).labels, labelled.labels)


@pytest.mark.parametrize('missing, present_labels', [
    (('left_ankle',), {LABEL_HEAD, LABEL_TORSO}),
    (('head',), {LABEL_TORSO, LABEL_LEFT_LEG, LABEL_RIGHT_LEG}),
    (('neck',), {LABEL_LEFT_LEG, LABEL_RIGHT_LEG}),
    (('root',), {LABEL_HEAD, LABEL_LEFT_LEG, LABEL_RIGHT_LEG}),  # the inner legs only: no waist
    (tuple(KEYPOINTS), set()),
])
def test_missing_keypoints_label_what_they_can(person, missing, present_labels):
    as_none = {**KEYPOINTS, **dict.fromkeys(missing)}
    for keypoints in (as_none, {name: xy for name, xy in KEYPOINTS.items() if name not in missing}):
        result = label_contour(person, keypoints)
        assert set(np.unique(result.labels)) - {LABEL_NONE} == present_labels
        assert len(result.points) == len(result.labels) == len(result.sides) == 3680


def test_coinciding_landmarks_skip_the_degenerate_segment(person):
    result = label_contour(person, dict(KEYPOINTS, head=KEYPOINTS['neck']))
    assert result.landmarks['head'] in (result.landmarks['neck_a'], result.landmarks['neck_b'])
    assert {SIDE_A, SIDE_B} <= set(result.sides[result.labels == LABEL_TORSO])
    same_feet = label_contour(person, dict(KEYPOINTS, left_ankle=KEYPOINTS['right_ankle']))
    assert 'crotch' not in same_feet.landmarks
    assert not np.isin(same_feet.labels, [LABEL_LEFT_LEG, LABEL_RIGHT_LEG]).any()


def test_a_pixel_visited_twice_gets_one_label(person):
    with_hair = person.copy()
    with_hair[100:141, 960] = True  # a 1 px spur: the contour runs up and back down it
    result = label_contour(with_hair, dict(KEYPOINTS, head=(960, 100)))
    keys, counts = np.unique(result.points, axis=0, return_counts=True)
    assert (counts == 2).sum() >= 39
    for pixel in keys[counts == 2]:
        twice = np.all(result.points == pixel, axis=1)
        assert np.all(result.labels[twice] == LABEL_HEAD)


def test_empty_silhouette_gives_empty_labels():
    result = label_contour(np.zeros((ROWS, COLS), bool), KEYPOINTS)
    assert result.points.shape == (0, 2) and result.labels.shape == result.sides.shape == (0,)
    assert result.labels.dtype == result.sides.dtype == np.uint8 and result.landmarks == {}
