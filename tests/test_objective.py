"""The per-limb objective (paper 000 Eq. 4–5) on a hand-made labelled contour, and DLT triangulation
(Hartley & Zisserman Sec. 12.2) in the studio rig.

Speed (not asserted): limb_cost over 3 cameras (N = 100 points each) takes about 0.19 ms; the four
distance maps of the synthetic contour below (two parts' boxes of 401×231 and 401×141 px, on a grid
twice coarser) about 1.1 ms; triangulate 0.2 ms for 3 views;
best_assignment 2.1 ms for 8 views (128 combinations, solved together) (development machine).
"""
import numpy as np
import pytest

from mvpose_nodes.body.model import LABEL_LEFT_ARM, LABEL_TORSO
from mvpose_nodes.body.camera import studio_rig
from mvpose_nodes.vision.contour import SIDE_A, SIDE_B, SIDE_NONE, ContourLabels
from mvpose_nodes.fitting.objective import (SEGMENT_POINTS, _camera_cost, boundary_distances, limb_cost,
                                            segment_points)
from mvpose_nodes.body.triangulation import best_assignment, triangulate

pytestmark = pytest.mark.pure


def limb_cost_brute_force(segments, contour_labels, label, n=SEGMENT_POINTS, enclosure_weight=0.0):
    """limb_cost computed directly from the boundary point lists (min over all boundary pixels), for tests.
    contour_labels: per camera the ContourLabels (instead of BoundaryDistances)."""
    cost, cameras_used = 0.0, []
    for camera, (segment, contour) in enumerate(zip(segments, contour_labels)):
        part = contour.labels == label
        bound_1 = contour.points[part & (contour.sides == SIDE_A)].astype(float)
        bound_2 = contour.points[part & (contour.sides == SIDE_B)].astype(float)
        if segment is None or not len(bound_1) or not len(bound_2):
            continue
        points = segment_points(*segment, n)
        d1, d2 = (np.linalg.norm(points[:, None] - bound[None], axis=2).min(axis=1) for bound in (bound_1, bound_2))
        width = max(np.linalg.norm(bound_1[:, None] - bound_2[None], axis=2).min(axis=axis).max() for axis in (0, 1))
        cost += _camera_cost(d1, d2, width, enclosure_weight)
        cameras_used.append(camera)
    return cost, cameras_used


IMAGE_SIZE = (640, 480)
ARM_SIDES_X = (100, 140)  # a vertical arm 40 px wide: SIDE_A at x = 100, SIDE_B at x = 140
ARM_ROWS = (100, 400)
MIDLINE_X = 120
N = SEGMENT_POINTS
MAP_ERROR_PX = 1.0   # the boundary maps are within a pixel of the exact distances (objective.MAP_COARSENING)


def vertical_boundary(x, label, side, rows=ARM_ROWS):
    ys = np.arange(rows[0], rows[1] + 1)
    return np.column_stack([np.full_like(ys, x), ys]), np.full(len(ys), label), np.full(len(ys), side)


def arm_contour(sides=(SIDE_A, SIDE_B)):
    """ContourLabels of the arm's two boundaries (with the given sides) beside a torso whose pixels must not
    count for the arm, and an unlabelled cap (not a closed contour: the objective needs none)."""
    pieces = [vertical_boundary(x, LABEL_LEFT_ARM, side) for x, side in zip(ARM_SIDES_X, sides)]
    pieces += [vertical_boundary(200, LABEL_TORSO, SIDE_A), vertical_boundary(330, LABEL_TORSO, SIDE_B),
               vertical_boundary(170, 0, SIDE_NONE, rows=(60, 80))]
    points, labels, part_sides = (np.concatenate(parts) for parts in zip(*pieces))
    return ContourLabels(points.astype(np.int32), labels.astype(np.uint8), part_sides.astype(np.uint8))


def vertical_segment(x, rows=(150, 350)):
    return (x, rows[0]), (x, rows[1])


def test_distance_maps_match_brute_force_on_random_segments():
    contour = arm_contour()
    maps = boundary_distances(contour, IMAGE_SIZE)
    assert set(maps.maps) == {(LABEL_LEFT_ARM, SIDE_A), (LABEL_LEFT_ARM, SIDE_B), (LABEL_TORSO, SIDE_A),
                              (LABEL_TORSO, SIDE_B)}
    assert maps.widths[LABEL_LEFT_ARM] == pytest.approx(40, abs=MAP_ERROR_PX)
    rng = np.random.default_rng(1)
    points = rng.uniform((60, 60), (180, 440), (2000, 2))  # within the arm's maps' box
    for side in (SIDE_A, SIDE_B):
        boundary = contour.points[(contour.labels == LABEL_LEFT_ARM) & (contour.sides == side)]
        exact = np.linalg.norm(points[:, None] - boundary[None], axis=2).min(axis=1)
        assert np.abs(maps.distances(LABEL_LEFT_ARM, side, points) - exact).max() <= MAP_ERROR_PX
    for _ in range(50):
        segment = rng.uniform((60, 60), (180, 440), (2, 2))
        for weight in (0.0, 1.0):
            cost, used = limb_cost([segment], [maps], LABEL_LEFT_ARM, enclosure_weight=weight)
            expected, _ = limb_cost_brute_force([segment], [contour], LABEL_LEFT_ARM, enclosure_weight=weight)
            assert used == [0]
            # Each S_j's two distances are within MAP_ERROR_PX each.
            assert cost == pytest.approx(expected, abs=2 * MAP_ERROR_PX * N)


def test_outside_the_maps_distance_grows_with_the_distance_to_the_box():
    maps = boundary_distances(arm_contour(), IMAGE_SIZE)
    x0 = maps.origins[LABEL_LEFT_ARM][0]
    # Straight left of the box the nearest SIDE_A pixel lies straight inward: the extrapolation is exact.
    points = np.array([[x0 - 30.0, 250.0], [x0 - 0.5, 250.0], [x0 + 10.0, 250.0]])
    assert maps.distances(LABEL_LEFT_ARM, SIDE_A, points) == pytest.approx(ARM_SIDES_X[0] - points[:, 0],
                                                                          abs=MAP_ERROR_PX)


def test_cost_is_zero_on_the_midline_and_grows_linearly_sideways():
    maps = [boundary_distances(arm_contour(), IMAGE_SIZE)]
    assert limb_cost([vertical_segment(MIDLINE_X)], maps, LABEL_LEFT_ARM) == (pytest.approx(0, abs=MAP_ERROR_PX * N), [0])
    for shift in (-15.0, -2.5, 2.0, 7.25, 19.0):
        cost, _ = limb_cost([vertical_segment(MIDLINE_X + shift)], maps, LABEL_LEFT_ARM)
        # Each S_j moves |shift| nearer one side and farther from the other.
        assert cost == pytest.approx(2 * N * abs(shift), abs=MAP_ERROR_PX * N)


def test_enclosure_term_removes_the_equidistant_far_segment():
    maps = [boundary_distances(arm_contour(), IMAGE_SIZE)]
    beyond_the_hand = vertical_segment(MIDLINE_X, rows=(420, 470))  # on the extended midline, off the arm
    assert limb_cost([beyond_the_hand], maps, LABEL_LEFT_ARM)[0] == pytest.approx(0, abs=MAP_ERROR_PX * N)
    assert limb_cost([beyond_the_hand], maps, LABEL_LEFT_ARM, enclosure_weight=1.0)[0] > 10 * N
    # On the arm d1 + d2 is the arm's width: the enclosure term adds nothing and moves no optimum.
    for shift in (0.0, 5.0, -12.0):
        on_arm = [vertical_segment(MIDLINE_X + shift)]
        assert (limb_cost(on_arm, maps, LABEL_LEFT_ARM, enclosure_weight=1.0)[0]
                == pytest.approx(limb_cost(on_arm, maps, LABEL_LEFT_ARM)[0], abs=MAP_ERROR_PX * N))


def test_cost_sums_over_the_cameras_that_see_both_sides():
    full, one_sided = arm_contour(), arm_contour(sides=(SIDE_A, SIDE_A))
    contours = [full, one_sided, full, full]
    maps = [boundary_distances(contour, IMAGE_SIZE) for contour in contours]
    segments = [vertical_segment(MIDLINE_X + 3), vertical_segment(MIDLINE_X + 3), None, vertical_segment(MIDLINE_X - 5)]
    cost, used = limb_cost(segments, maps, LABEL_LEFT_ARM)
    assert used == [0, 3]  # camera 1 lacks SIDE_B, camera 2 has no segment
    assert cost == pytest.approx(2 * N * (3 + 5), abs=2 * MAP_ERROR_PX * N)
    assert limb_cost_brute_force(segments, contours, LABEL_LEFT_ARM) == (pytest.approx(cost, abs=2 * MAP_ERROR_PX * N),
                                                                         used)


# Triangulation: cameras 3, 5 and 7 of the rig (the paper's three views), points about the capture volume.
RIG = studio_rig()
VIEWS = [RIG[2], RIG[4], RIG[6]]


def random_points(rng, count):
    return rng.uniform((-0.5, -0.5, 0.1), (0.5, 0.5, 1.8), (count, 3))


def observe(cameras, point):
    return np.array([camera.project(point[None])[0][0] for camera in cameras])


@pytest.mark.parametrize('cameras', [VIEWS, [VIEWS[0].with_distortion([-0.2, 0, 0, 0, 0]), *VIEWS[1:]], RIG[:2]])
def test_triangulation_recovers_exact_points(cameras):
    rng = np.random.default_rng(2)
    for point in random_points(rng, 20):
        estimate, rms = triangulate(cameras, observe(cameras, point))
        assert estimate == pytest.approx(point, abs=1e-6)
        assert rms < 1e-4


def test_triangulation_with_one_pixel_noise_is_within_millimetres():
    rng = np.random.default_rng(3)
    errors, residuals = [], []
    for point in random_points(rng, 200):
        estimate, rms = triangulate(VIEWS, observe(VIEWS, point) + rng.normal(0, 1, (3, 2)))
        errors.append(np.linalg.norm(estimate - point))
        residuals.append(rms)
    assert np.sqrt(np.mean(np.square(errors))) < 0.004  # [m]: 1 px is about 3 mm at 4 m
    assert 0.3 < np.mean(residuals) < 1.2  # [px]


def test_triangulation_weights_and_missing_views():
    point = np.array([0.1, -0.2, 1.0])
    pixels = observe(VIEWS, point)
    corrupted = pixels + [[40.0, -30.0], [0, 0], [0, 0]]
    assert triangulate(VIEWS, corrupted, weights=[0, 1, 1])[0] == pytest.approx(point, abs=1e-6)
    uniform_error = np.linalg.norm(triangulate(VIEWS, corrupted)[0] - point)
    downweighted_error = np.linalg.norm(triangulate(VIEWS, corrupted, weights=[0.05, 1, 1])[0] - point)
    assert downweighted_error < 0.2 * uniform_error
    unseen = pixels.copy()
    unseen[1] = np.nan
    assert triangulate(VIEWS, unseen)[0] == pytest.approx(point, abs=1e-6)
    assert triangulate(VIEWS[:1], pixels[:1]) is None
    assert triangulate(VIEWS, unseen, weights=[1, 1, 0]) is None


def test_robust_points_leave_out_the_one_disagreeing_view_of_each_point():
    """Triangulated together, each point with one of four views 40 px off is found from the other three,
    the clean points from all four, a point seen twice as it is, a point seen once not at all; each as
    when it is triangulated alone."""
    from mvpose_nodes.body.triangulation import Rig
    from mvpose_nodes.fitting.initialisation import robust_points, robust_triangulate
    rng = np.random.default_rng(6)
    cameras = [RIG[0], RIG[2], RIG[4], RIG[6]]
    truth = random_points(rng, 12)
    pixels = np.array([observe(cameras, point) for point in truth])   # (12, 4, 2)
    weights = np.ones((12, 4))
    off = rng.integers(0, 4, 6)
    pixels[np.arange(6), off] += (40.0, -30.0)   # the first six points: one view wrong each
    pixels[10, 2:] = np.nan                      # seen in two views
    pixels[11, 1:] = np.nan                      # seen in one
    points, found = robust_points(Rig.of(cameras), pixels, weights, outlier_rms=2.0)
    assert found.tolist() == [True] * 11 + [False]
    np.testing.assert_allclose(points[:11], truth[:11], atol=1e-6)
    for point, observed, weight in zip(points[:11], pixels, weights):
        np.testing.assert_array_equal(robust_triangulate(cameras, observed, weight, 2.0), point)
    assert robust_triangulate(cameras, pixels[11], weights[11], 2.0) is None


def test_best_assignment_undoes_per_view_left_right_swaps():
    rng = np.random.default_rng(4)
    for _ in range(5):
        hip_centre = random_points(rng, 1)[0]
        left, right = hip_centre + [0, 0.1, 0], hip_centre - [0, 0.1, 0]
        swaps = rng.random(len(RIG)) < 0.5
        swaps[0] = False  # the first view fixes which point is called left
        left_pixels, right_pixels = observe(RIG, left), observe(RIG, right)
        observed_left = np.where(swaps[:, None], right_pixels, left_pixels) + rng.normal(0, 0.5, (len(RIG), 2))
        observed_right = np.where(swaps[:, None], left_pixels, right_pixels) + rng.normal(0, 0.5, (len(RIG), 2))
        left_estimate, right_estimate, found = best_assignment(RIG, observed_left, observed_right)
        assert found.tolist() == swaps.tolist()
        assert left_estimate == pytest.approx(left, abs=0.005)
        assert right_estimate == pytest.approx(right, abs=0.005)


def test_best_assignments_of_several_pairs_are_each_pairs_own():
    """Pairs solved together (one triangulation call for all their labellings, as triangulated_joints does)
    give each pair what best_assignment gives it alone, to the bit; a pair seen in one view only gives None."""
    from mvpose_nodes.body.triangulation import Rig, best_assignments
    rng = np.random.default_rng(5)
    cameras = [RIG[1], RIG[3], RIG[6]]
    rig = Rig.of(cameras)
    pixels = np.empty((4, 3, 2, 2))
    for pair, centre in enumerate(random_points(rng, 4)):
        ends = [observe(cameras, centre + offset) for offset in ([0.12, 0, 0], [-0.12, 0, 0])]
        swaps = rng.random(3) < 0.5
        pixels[pair, :, 0] = np.where(swaps[:, None], ends[1], ends[0]) + rng.normal(0, 2.0, (3, 2))
        pixels[pair, :, 1] = np.where(swaps[:, None], ends[0], ends[1]) + rng.normal(0, 2.0, (3, 2))
    pixels[3, 1:] = np.nan   # the last pair seen by the first camera only
    weights = rng.uniform(0.3, 1.0, (4, 3, 2))
    normalized = np.stack([rig.normalized(pixels[pair]) for pair in range(4)])
    together = best_assignments(rig, pixels, weights, normalized)
    for pair in range(4):
        alone = best_assignment(cameras, pixels[pair, :, 0], pixels[pair, :, 1], weights[pair], rig, normalized[pair])
        if pair == 3:
            assert alone is None and together[pair] is None
            continue
        for mine, theirs in zip(together[pair], alone):
            assert np.array_equal(mine, theirs)


# The outline objective (objective.outline_cost): capsules explaining a silhouette's outline.

CAPSULE = ((150.0, 120.0), (420.0, 300.0))  # a limb's axis [px] in a 640 × 480 image
CAPSULE_RADIUS_PX = 18


def capsule_outline():
    """The Outline of a silhouette that is one capsule (radius CAPSULE_RADIUS_PX around CAPSULE)."""
    import cv2
    from mvpose_nodes.vision.contour import outer_contour
    from mvpose_nodes.fitting.objective import outline_of
    mask = np.zeros(IMAGE_SIZE[::-1], np.uint8)
    cv2.line(mask, tuple(map(int, CAPSULE[0])), tuple(map(int, CAPSULE[1])), 1, 2 * CAPSULE_RADIUS_PX + 1)
    return outline_of(outer_contour(mask))


def outline_terms(outline, start, end, radius, terminal=False):
    from mvpose_nodes.fitting.objective import inside_cost, outline_cost
    starts, ends = np.array([start], float), np.array([end], float)
    return (outline_cost(outline.points, starts, ends, np.array([radius], float), np.array([terminal]), 10.0, 20.0),
            inside_cost(starts, ends, outline))


def test_capsule_residuals_match_a_brute_force_distance():
    from mvpose_nodes.fitting.objective import capsule_residuals
    rng = np.random.default_rng(5)
    starts, ends = rng.uniform(0, 400, (3, 2)), rng.uniform(0, 400, (3, 2))
    radii = rng.uniform(5, 20, 3)
    points = rng.uniform(-50, 450, (200, 2))
    dense = [np.linspace(a, b, 20001) for a, b in zip(starts, ends)]   # segments sampled every < 0.03 px
    brute = np.array([[np.linalg.norm(segment - q, axis=1).min() for segment in dense] for q in points]) - radii
    np.testing.assert_allclose(capsule_residuals(points, starts, ends, radii, np.zeros(3, bool)), brute, atol=0.05)
    # Per-point capsules (each camera's own) give the same as shared ones.
    shared = np.broadcast_to(starts, (200, 3, 2)), np.broadcast_to(ends, (200, 3, 2)), np.broadcast_to(radii, (200, 3))
    np.testing.assert_allclose(capsule_residuals(points, *shared, np.zeros(3, bool)), brute, atol=0.05)
    # A terminal capsule does not explain what lies beyond its end.
    beyond = ends[0] + 10 * (ends[0] - starts[0]) / np.linalg.norm(ends[0] - starts[0])
    assert np.isinf(capsule_residuals(beyond[None], starts[:1], ends[:1], radii[:1], np.array([True]))[0, 0])


def test_outline_cost_is_least_on_the_axis_whatever_the_radius():
    """The outline term puts the segment midway between the sides even with a wrong radius (here 12 px
    for an 18 px limb), as Eq. 4 does; shifting it sideways or turning it costs more, and a segment
    leaving the silhouette pays the inside term."""
    outline = capsule_outline()
    start, end = np.array(CAPSULE[0]), np.array(CAPSULE[1])
    across = np.array([-(end - start)[1], (end - start)[0]]) / np.linalg.norm(end - start)
    on_axis, inside = outline_terms(outline, start, end, radius=12)
    assert inside == 0.0
    for shift in (3, 6, -6):
        assert outline_terms(outline, start + shift * across, end + shift * across, radius=12)[0] > on_axis, shift
    turned = outline_terms(outline, start + 8 * across, end - 8 * across, radius=12)[0]
    assert turned > on_axis
    assert outline_terms(outline, start + 40 * across, end + 40 * across, radius=12)[1] > 0, 'outside the silhouette'
