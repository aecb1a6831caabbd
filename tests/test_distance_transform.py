"""The fitter's exact Euclidean distance transform (fitting/objective.py, exact_distances) against brute force,
and beside OpenCV's DIST_MASK_PRECISE, on seeded random maps.

Speed (not asserted; `./mvpose bench` gives the figures in the graph): on the demo walk's maps (three
views' boundary and outline maps, 1.25 M cells per frame set) about 11 ms per frame set against
cv2.distanceTransform's 17 on one core (development machine, session 64).
"""
import cv2
import numpy as np
import pytest

from mvpose_nodes.fitting.objective import exact_distances

pytestmark = pytest.mark.pure


def brute_force(seeds):
    """(H, W) float32: each cell's distance to the nearest seed (seeds (H, W), nonzero at a seed), the
    square root of the exact integer squared distance, correctly rounded."""
    seed_rows, seed_columns = np.nonzero(seeds)
    rows, columns = np.indices(seeds.shape)
    squared = ((rows[..., None] - seed_rows) ** 2 + (columns[..., None] - seed_columns) ** 2).min(axis=-1)
    return np.sqrt(squared.astype(np.float64)).astype(np.float32)


def seeded_maps(count=300, seed=0):
    """Random (H, W) uint8 seed maps, 1–60 cells a side: sparse and dense seeds, a silhouette's filled
    ellipse and a contour's one-pixel lines among them; each with at least one seed."""
    rng = np.random.default_rng(seed)
    maps = []
    while len(maps) < count:
        rows, columns = rng.integers(1, 61, 2)
        kind = len(maps) % 4
        if kind < 2:   # scattered seeds, from 1 in 1000 cells to 7 in 10
            seeds = (rng.random((rows, columns)) < (0.001, 0.7)[kind]).astype(np.uint8)
        else:
            seeds = np.zeros((rows, columns), np.uint8)
            centre = (int(rng.integers(0, columns)), int(rng.integers(0, rows)))
            axes = (int(rng.integers(1, 30)), int(rng.integers(1, 30)))
            cv2.ellipse(seeds, centre, axes, float(rng.uniform(0, 180)), 0, 360, 1, -1 if kind == 2 else 1)
        if seeds.any():
            maps.append(seeds)
    return maps


def test_the_distances_are_the_exact_euclidean_ones_correctly_rounded():
    for seeds in seeded_maps():
        out = np.empty(seeds.shape, np.float32)
        exact_distances(seeds, out)
        np.testing.assert_array_equal(out, brute_force(seeds), err_msg=f'a map of {seeds.shape}')


def test_a_map_of_one_row_one_column_or_one_seed():
    for shape, seed in (((1, 40), (0, 17)), ((40, 1), (3, 0)), ((25, 30), (24, 29)), ((1, 1), (0, 0))):
        seeds = np.zeros(shape, np.uint8)
        seeds[seed] = 1
        out = np.empty(shape, np.float32)
        exact_distances(seeds, out)
        np.testing.assert_array_equal(out, brute_force(seeds))


def test_within_a_unit_in_the_last_place_of_opencvs_precise_transform():
    """What the fitter's maps were made with before (cv2.distanceTransform, DIST_L2, DIST_MASK_PRECISE),
    whose square roots may be a unit in the last place off."""
    for seeds in seeded_maps(100, seed=1):
        out = np.empty(seeds.shape, np.float32)
        exact_distances(seeds, out)
        opencv = cv2.distanceTransform(1 - seeds, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        np.testing.assert_allclose(out, opencv, rtol=2.5e-7, atol=0)


def test_the_scale_multiplies_every_distance_exactly():
    for seeds in seeded_maps(40, seed=2):
        once, twice = np.empty(seeds.shape, np.float32), np.empty(seeds.shape, np.float32)
        exact_distances(seeds, once)
        exact_distances(seeds, twice, 2)
        np.testing.assert_array_equal(twice, 2 * once)


def test_a_map_without_seeds_or_of_the_wrong_type_is_refused():
    with pytest.raises(ValueError, match='no seed'):
        exact_distances(np.zeros((5, 6), np.uint8), np.empty((5, 6), np.float32))
    with pytest.raises(ValueError, match='want uint8 seeds'):
        exact_distances(np.ones((5, 6), np.uint8), np.empty((5, 6), np.float64))
    with pytest.raises(ValueError, match='want uint8 seeds'):
        exact_distances(np.ones((5, 6), np.uint8), np.empty((6, 5), np.float32))
