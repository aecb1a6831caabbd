"""Paper 001's colour-marker tracking constrained by body regions (mvpose_nodes.markers.tracking), on seeded
synthetic images drawn here: a blue studio background, a textured grey body (head ellipse, torso
rectangle, arm and leg strokes) pasted at integer offsets, red anti-aliased discs for the markers
and orange/pink/skin-coloured discs that are not markers."""
import cv2
import numpy as np
import pytest

from mvpose_nodes.markers.detection import (FLAG_DETECTED, FLAG_LOST, FLAG_PREDICTED, MARKER_NAMES, REGIONS,
                                            MarkerSettings, detect_markers)
from mvpose_nodes.markers.regions import RegionTracker, assign_group, assign_head, similarity_complete
from mvpose_nodes.markers.tracking import MarkerTracker, NearestNeighbourTracker

pytestmark = pytest.mark.pure

BLUE = (30, 40, 200)
RED = (220, 20, 25)
SHAPE = (260, 320)
# Marker positions relative to the pelvis [px] (shoulder width 60).
LOCAL = {'pelvis': (0, 0), 'left_hip': (16, 0), 'right_hip': (-16, 0), 'left_knee': (16, 45),
         'right_knee': (-16, 45), 'left_ankle': (16, 90), 'right_ankle': (-16, 90), 'neck': (0, -75),
         'head': (0, -112), 'left_shoulder': (30, -70), 'right_shoulder': (-30, -70), 'left_elbow': (40, -35),
         'right_elbow': (-40, -35), 'left_wrist': (44, 0), 'right_wrist': (-44, 0)}
CANVAS, ORIGIN = (320, 240), (120, 200)   # body layer (h, w); the pelvis in it (x, y)


def texture(rng, shape, blur=3.0):
    noise = cv2.GaussianBlur(rng.uniform(0, 1, shape).astype(np.float32), (0, 0), blur)
    return (noise - noise.min()) / (noise.max() - noise.min())


def body_layer(seed):
    """(RGB uint8, mask bool) of a textured grey body in a CANVAS-sized layer, pelvis at ORIGIN."""
    rng = np.random.default_rng(seed)
    mask = np.zeros(CANVAS, np.uint8)
    ox, oy = ORIGIN
    cv2.ellipse(mask, (ox, oy - 95), (17, 22), 0, 0, 360, 255, -1)
    cv2.rectangle(mask, (ox - 34, oy - 80), (ox + 34, oy + 8), 255, -1)
    for side in (-1, 1):
        cv2.line(mask, (ox + 30 * side, oy - 70), (ox + 40 * side, oy - 35), 255, 9)
        cv2.line(mask, (ox + 16 * side, oy), (ox + 16 * side, oy + 90), 255, 11)
    grey = 60 + 160 * texture(rng, CANVAS)
    rgb = np.stack([grey + 10, grey, grey - 10], axis=2).clip(0, 255).astype(np.uint8)
    return rgb, mask > 0


def draw_disc(image, centre, radius, colour):
    scale = 16  # 4 fractional bits: sub-pixel centres
    cv2.circle(image, (int(round(centre[0] * scale)), int(round(centre[1] * scale))), int(round(radius * scale)),
               colour, -1, cv2.LINE_AA, 4)


def render(layer, offset, markers, radius=4.0):
    """The body pasted with its pelvis at the integer `offset`, red discs at `markers` (name → (x, y),
    None = hidden)."""
    rgb, mask = layer
    image = np.empty(SHAPE + (3,), np.uint8)
    image[:] = BLUE
    rows, cols = np.nonzero(mask)
    y, x = rows + int(offset[1]) - ORIGIN[1], cols + int(offset[0]) - ORIGIN[0]
    ok = (y >= 0) & (y < SHAPE[0]) & (x >= 0) & (x < SHAPE[1])
    image[y[ok], x[ok]] = rgb[rows[ok], cols[ok]]
    for point in markers.values():
        if point is not None:
            draw_disc(image, point, radius, RED)
    return image


def pose(offset, **overrides):
    points = {name: (offset[0] + LOCAL[name][0], offset[1] + LOCAL[name][1]) for name in MARKER_NAMES}
    points.update(overrides)
    return points


def as_array(points):
    return np.array([points[name] for name in MARKER_NAMES], np.float64)


def textured_grey(seed, shape=(200, 240), blur=4.0):
    """A grey float32 image of smooth blobs on black (what tracking_image gives for a keyed person)."""
    rng = np.random.default_rng(seed)
    image = np.zeros(shape, np.float32)
    for _ in range(25):
        centre = (int(rng.uniform(20, shape[1] - 20)), int(rng.uniform(20, shape[0] - 20)))
        axes = (int(rng.uniform(6, 20)), int(rng.uniform(6, 20)))
        cv2.ellipse(image, centre, axes, float(rng.uniform(0, 180)), 0, 360, float(rng.uniform(60, 230)), -1)
    return cv2.GaussianBlur(image, (0, 0), blur)


def shifted(image, dx, dy):
    return cv2.warpAffine(image, np.float32([[1, 0, dx], [0, 1, dy]]), image.shape[::-1],
                          borderMode=cv2.BORDER_CONSTANT)


# ---------------------------------------------------------------------------------------------
# (a) region search

def test_region_search_finds_a_known_shift_by_lambda_descent():
    image = textured_grey(3)
    tracker = RegionTracker(step=3)
    tracker.start(image, (120.0, 100.0), (61, 47))
    centre, size, score = tracker.track(shifted(image, 7, -4))
    np.testing.assert_array_equal(centre, [127.0, 96.0])
    np.testing.assert_array_equal(size, [61, 47])
    assert score > 0.9999
    # The descent as the paper says: starts at the previous centre with λ = 3; every move is λ along
    # one axis to a strictly better window; λ only shrinks (after a step without a move) down to 1.
    path = tracker.path
    assert path[0][:3] == (120.0, 100.0, 3)
    steps = [entry[2] for entry in path]
    assert steps == sorted(steps, reverse=True) and steps[1] == 3 and steps[-1] == 1
    for before, after in zip(path, path[1:]):
        move = np.subtract(after[:2], before[:2])
        assert sorted(np.abs(move)) == [0, after[2]]
        assert after[3] > before[3]
    # Each round compares 4 neighbours; λ shrinks 3 times; then 8 other sizes.
    moves = len(path) - 1
    assert tracker.evaluations == 1 + 4 * (moves + 3) + 8


def test_region_search_respects_the_vertical_order_bound():
    image = textured_grey(4)
    tracker = RegionTracker(step=3)
    tracker.start(image, (120.0, 100.0), (61, 47))
    centre, _, _ = tracker.track(shifted(image, 0, 9), y_range=(None, 104.0))   # must stay above y = 104
    assert centre[1] <= 104.0
    assert all(entry[1] <= 104.0 for entry in tracker.path)
    fresh = RegionTracker(step=3)
    fresh.start(image, (120.0, 100.0), (61, 47))
    centre, _, _ = fresh.track(shifted(image, 0, 9), y_range=(None, None))
    np.testing.assert_array_equal(centre, [120.0, 109.0])


# (b) scale choice

@pytest.mark.parametrize('growth, expected', [((1.02, 1.02), (1.02, 1.02)), ((1.0, 1.0), (1.0, 1.0)),
                                              ((1.02, 1.0), (1.02, 1.0)), ((0.98, 0.98), (0.98, 0.98))])
def test_scale_choice(growth, expected):
    image = textured_grey(5, blur=2.5)
    centre = np.array([120.0, 100.0])
    tracker = RegionTracker(step=3, scale_step=0.02)
    tracker.start(image, centre, (101, 81))
    matrix = np.float64([[growth[0], 0, centre[0] * (1 - growth[0])], [0, growth[1], centre[1] * (1 - growth[1])]])
    grown = cv2.warpAffine(image, matrix, image.shape[::-1], flags=cv2.INTER_LINEAR)
    found, size, _ = tracker.track(grown)
    np.testing.assert_array_equal(found, centre)
    np.testing.assert_allclose(size / [101, 81], expected, atol=1e-12)


# (c) template update T_t = α·T_{t−1} + (1 − α)·W_t

def test_template_update_follows_the_alpha_rule():
    image = textured_grey(6)
    tracker = RegionTracker(step=3, alpha=0.9, update_min_ncc=0.5)
    tracker.start(image, (120.0, 100.0), (41, 31))
    t0 = tracker.template.copy()
    # Brightness and contrast change (NCC 1, the window stays): W1 = 0.5·T0 + 40, W2 = 0.25·T0 + 60.
    tracker.track(0.5 * image + 40)
    np.testing.assert_allclose(tracker.template, 0.9 * t0 + 0.1 * (0.5 * t0 + 40), atol=1e-3)
    np.testing.assert_allclose(tracker.template, 0.95 * t0 + 4, atol=1e-3)
    tracker.track(0.25 * image + 60)
    # Recursive: 0.9·(0.95·T0 + 4) + 0.1·(0.25·T0 + 60) = 0.88·T0 + 9.6 (blending T0 would give 0.925·T0 + 6).
    np.testing.assert_allclose(tracker.template, 0.88 * t0 + 9.6, atol=1e-3)
    # A poor match (unrelated image) leaves the template alone.
    before = tracker.template.copy()
    _, _, score = tracker.track(textured_grey(99))
    assert score < 0.5
    np.testing.assert_array_equal(tracker.template, before)


# (d) assignment rules

PREVIOUS = np.array([[100.0, 50.0], [130.0, 55.0], [70.0, 55.0]])   # neck, left, right shoulder at t − 1
BOX = np.array([60.0, 20.0])                                        # h: gate (60 + 20)/4 = 20 px
S = np.array([5.0, 2.0])


def group(detections, reference=PREVIOUS):
    return assign_group(PREVIOUS, S, np.array(detections, np.float64).reshape(-1, 2), (105.0, 54.0), BOX, reference)


def test_group_three_found():
    truth = PREVIOUS + S + [[1, -1], [-2, 0], [0, 2]]
    positions, flags, index = group([truth[2], [300, 300], truth[0], truth[1]])
    np.testing.assert_array_equal(positions, truth)
    np.testing.assert_array_equal(flags, [FLAG_DETECTED] * 3)
    np.testing.assert_array_equal(index, [2, 3, 0])


def test_group_two_found_completes_the_third_by_similarity():
    # The shoulder line turned by 10° and stretched by 5 % about the neck: right shoulder hidden.
    angle, scale = np.radians(10.0), 1.05
    rotation = scale * np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    truth = (PREVIOUS - PREVIOUS[0]) @ rotation.T + PREVIOUS[0] + S
    positions, flags, index = group([truth[0], truth[1]])
    np.testing.assert_array_equal(flags, [FLAG_DETECTED, FLAG_DETECTED, FLAG_PREDICTED])
    np.testing.assert_array_equal(index[:2], [0, 1])
    assert index[2] == -1
    assert np.linalg.norm(positions[2] - truth[2]) < 1.0
    # Against the plain region-displacement prediction, which is off by several pixels here.
    assert np.linalg.norm(PREVIOUS[2] + S - truth[2]) > 4.0


def test_group_one_found_shifts_the_predictions_by_its_residual():
    residual = np.array([3.0, -2.0])
    found = PREVIOUS[1] + S + residual
    positions, flags, index = group([found, [400, 10]])
    np.testing.assert_array_equal(flags, [FLAG_PREDICTED, FLAG_DETECTED, FLAG_PREDICTED])
    np.testing.assert_array_equal(positions, PREVIOUS + S + residual)


def test_group_none_found_uses_the_region_displacement():
    # Detections only outside the search window (105 ± 33, 54 ± 11), one of them 2 px from a prediction.
    positions, flags, index = group([[200.0, 54.0], [105.0, 54.0 + 11.5], [140.0, 57.0]])
    np.testing.assert_array_equal(flags, [FLAG_PREDICTED] * 3)
    np.testing.assert_array_equal(index, [-1] * 3)
    np.testing.assert_array_equal(positions, PREVIOUS + S)


def test_group_detection_outside_the_window_is_not_taken_even_when_near():
    # Left shoulder's detection 1 px beyond the window's right edge (105 + 33 = 138): not a candidate.
    positions, flags, _ = group([PREVIOUS[0] + S, [138.5, 57.0]])
    assert flags[1] == FLAG_PREDICTED


def test_similarity_complete_is_exact_for_a_similarity():
    reference = np.array([[0.0, 0.0], [10.0, 0.0], [4.0, 7.0]])
    moved = reference * 2.0 @ np.array([[0.0, -1.0], [1.0, 0.0]]).T + [5.0, 5.0]
    np.testing.assert_allclose(similarity_complete(*reference, moved[0], moved[1]), moved[2], atol=1e-12)


def test_head_cases():
    previous, displacement = np.array([100.0, 20.0]), np.array([2.0, 1.0])
    centre, size = (102.0, 21.0), (33.0, 33.0)
    # One detection inside: the head, even away from the prediction.
    position, flag, k = assign_head(previous, displacement, [[300.0, 300.0], [110.0, 30.0]], centre, size)
    assert flag == FLAG_DETECTED and k == 1
    np.testing.assert_array_equal(position, [110.0, 30.0])
    # Several inside: the nearest to p + S = (102, 21).
    position, flag, k = assign_head(previous, displacement, [[90.0, 10.0], [104.0, 22.0], [112.0, 30.0]],
                                    centre, size)
    assert flag == FLAG_DETECTED and k == 1
    # None inside: the prediction.
    position, flag, k = assign_head(previous, displacement, [[130.0, 21.0]], centre, size)
    assert flag == FLAG_PREDICTED and k == -1
    np.testing.assert_array_equal(position, [102.0, 21.0])


# ---------------------------------------------------------------------------------------------
# Whole trackers on rendered sequences

def test_tracker_follows_a_moving_body_and_exposes_regions():
    layer = body_layer(2)
    offsets = [(160 + 3 * t, 140 - (t % 3)) for t in range(8)]
    tracker = MarkerTracker()
    positions, flags = tracker.initialise(render(layer, offsets[0], pose(offsets[0])), as_array(pose(offsets[0])))
    assert np.all(flags == FLAG_DETECTED)
    assert set(tracker.regions) == set(REGIONS)
    for t in range(1, len(offsets)):
        positions, flags = tracker.track(render(layer, offsets[t], pose(offsets[t])))
        assert positions.shape == (15, 2) and positions.dtype == np.float64 and flags.dtype == np.uint8
        assert np.all(flags == FLAG_DETECTED)
        np.testing.assert_allclose(positions, as_array(pose(offsets[t])), atol=0.5)
        for name, record in tracker.regions.items():
            np.testing.assert_array_equal(record['S'], np.subtract(offsets[t], offsets[t - 1]), err_msg=name)
            assert record['ncc'] > 0.95


def test_group_completion_in_a_sequence():
    """The right shoulder's marker hidden: completed from the neck and left shoulder."""
    layer = body_layer(7)
    tracker = MarkerTracker()
    tracker.initialise(render(layer, (160, 140), pose((160, 140))), as_array(pose((160, 140))))
    index = MARKER_NAMES.index('right_shoulder')
    for t in range(1, 5):
        offset = (160 + 4 * t, 140)
        truth = pose(offset)
        positions, flags = tracker.track(render(layer, offset, dict(truth, right_shoulder=None)))
        assert flags[index] == FLAG_PREDICTED
        assert np.linalg.norm(positions[index] - truth['right_shoulder']) < 1.0


# (e) occlusion: the left wrist hidden while passing the left hip, the body stopping meanwhile

def occlusion_sequence():
    """Body moves +4 px/frame in x, then stands still from frame 5. The left wrist (on the hip's row)
    moves −5 px/frame in frames 0–2, is hidden in frames 3–5, and comes back 12 px right of the left
    hip at frame 6 (the arm swung back behind the body), moving +3 px/frame. A constant-velocity
    prediction then puts the wrist on the hip's marker and the hip 4 px too far right."""
    layer = body_layer(1)
    wrist_x = {0: 164, 1: 159, 2: 154, 6: 148, 7: 151, 8: 154, 9: 157, 10: 160}
    frames, truths, visible = [], [], []
    for t in range(11):
        offset = (100 + 4 * min(t, 5), 140)
        truth = pose(offset, left_wrist=(float(wrist_x.get(t, np.nan)), 140.0))
        shown = dict(truth)
        if t not in wrist_x:
            shown['left_wrist'] = None
        frames.append(render(layer, offset, shown))
        truths.append(as_array(truth))
        visible.append(t in wrist_x)
    return frames, truths, visible


def run(tracker, frames, truths):
    tracker.initialise(frames[0], truths[0])
    return [tracker.track(frame) for frame in frames[1:]]


def test_occluded_wrist_is_predicted_then_reacquired_under_its_name():
    frames, truths, visible = occlusion_sequence()
    wrist, hip = MARKER_NAMES.index('left_wrist'), MARKER_NAMES.index('left_hip')
    for t, (positions, flags) in enumerate(run(MarkerTracker(), frames, truths), start=1):
        if visible[t]:
            assert flags[wrist] == FLAG_DETECTED, t
        else:
            assert flags[wrist] == FLAG_PREDICTED, t
            # The first hidden frame by its velocity (154 − 5), then carried by the shoulders (+4 px a frame).
            np.testing.assert_allclose(positions[wrist], [149.0 + 4.0 * (t - 3), 140.0], atol=0.5)
        others = np.delete(np.arange(15), wrist)
        assert np.all(flags[others] == FLAG_DETECTED), t
        np.testing.assert_allclose(positions[others], truths[t][others], atol=0.5)
        if visible[t]:
            np.testing.assert_allclose(positions[wrist], truths[t][wrist], atol=0.5)
    # The baseline swaps wrist and hip when the wrist comes back, and never recovers.
    results = run(NearestNeighbourTracker(), frames, truths)
    for t in range(6, 11):
        positions, _ = results[t - 1]
        np.testing.assert_allclose(positions[wrist], truths[t][hip], atol=0.5)
        np.testing.assert_allclose(positions[hip], truths[t][wrist], atol=0.5)


def test_long_prediction_becomes_lost():
    layer = body_layer(2)
    tracker = MarkerTracker(MarkerSettings(max_predicted_frames=3))
    tracker.initialise(render(layer, (160, 140), pose((160, 140))), as_array(pose((160, 140))))
    ankle = MARKER_NAMES.index('left_ankle')
    flags_seen = []
    for _ in range(5):
        _, flags = tracker.track(render(layer, (160, 140), dict(pose((160, 140)), left_ankle=None)))
        flags_seen.append(int(flags[ankle]))
    assert flags_seen == [FLAG_PREDICTED] * 3 + [FLAG_LOST] * 2
    positions, flags = tracker.track(render(layer, (160, 140), pose((160, 140))))
    assert flags[ankle] == FLAG_DETECTED


# (f) detection

def test_detect_markers_finds_red_centres_and_ignores_other_colours():
    """Thresholds (MarkerSettings defaults): hue within ±15° of red, saturation >= 0.55, value >= 0.35.
    Decoys: orange (255, 140, 0) hue 33°; pink (255, 105, 180) hue 330°; hot pink (240, 40, 120) hue 336°;
    skin (225, 160, 130) saturation 0.42; dark red (70, 10, 10) value 0.27."""
    rng = np.random.default_rng(11)
    image = render(body_layer(3), (160, 140), {})
    centres = []
    for _ in range(12):
        while True:
            centre = rng.uniform([15, 15], [305, 245])
            if all(np.linalg.norm(centre - c) > 20 for c in centres):
                break
        centres.append(centre)
    reds, decoys = np.array(centres[:7]), centres[7:]
    for centre, radius in zip(reds, rng.uniform(3.0, 6.0, len(reds))):
        draw_disc(image, centre, radius, RED)
    for centre, colour in zip(decoys, [(255, 140, 0), (255, 105, 180), (240, 40, 120), (225, 160, 130), (70, 10, 10)]):
        draw_disc(image, centre, 5.0, colour)
    found = detect_markers(image)
    assert len(found) == len(reds)
    distance = np.linalg.norm(found[:, None] - reds[None], axis=2)
    assert np.all(distance.min(axis=0) < 0.5)


def test_detect_markers_merges_overlapping_markers_and_drops_specks():
    image = np.empty((200, 200, 3), np.uint8)   # max blob area 0.5 % of the image: 200 px
    image[:] = BLUE
    draw_disc(image, (30.0, 50.0), 5.0, RED)
    draw_disc(image, (36.0, 50.0), 5.0, RED)   # overlaps the first: one blob
    image[10, 10] = RED                         # one pixel: below min_blob_area
    found = detect_markers(image)
    assert len(found) == 1
    np.testing.assert_allclose(found[0], [33.0, 50.0], atol=0.5)


def test_region_motion_is_checked_against_its_markers():
    """The matched displacement S is kept when the region's markers moved by it; a match that slid
    (along plain clothes) gives way to no motion, or to the last frame's S, whichever the markers'
    detections support best."""
    from types import SimpleNamespace
    tracker = MarkerTracker()
    rng = np.random.default_rng(4)
    tracker.positions = rng.uniform(100, 300, (15, 2))
    from mvpose_nodes.markers.detection import REGION_INDICES
    hips = list(REGION_INDICES['hips'])
    tracker.box_sizes = {'hips': np.array([1.0, 1.0])}
    tracker.trackers = {'hips': SimpleNamespace(size=np.array([60.0, 40.0]))}   # gate (60 + 40) / 4 = 25 px
    tracker.regions = {'hips': {'S': np.array([12.0, 0.0])}}
    markers = tracker.positions[hips]
    np.testing.assert_array_equal(tracker._checked_displacement('hips', np.array([5.0, -3.0]), markers + [5, -3]),
                                  [5.0, -3.0])                                    # moved as matched
    np.testing.assert_array_equal(tracker._checked_displacement('hips', np.array([40.0, 0.0]), markers + 0.5),
                                  [0.0, 0.0])                                     # the match slid; they stayed
    np.testing.assert_array_equal(tracker._checked_displacement('hips', np.array([-40.0, 0.0]), markers + [12, 1]),
                                  [12.0, 0.0])                                    # they went on as before
