"""The exact Euclidean distance transform of the fitter's distance maps (objective.boundary_distances,
objective.outline_of), compiled with numba.

The two passes of Felzenszwalb and Huttenlocher ("Distance transforms of sampled functions", Theory of
Computing 8, 2012), as OpenCV's distanceTransform does them with DIST_MASK_PRECISE: along each column the
distance to the nearest seed, then along each row the lower envelope of the parabolas (q − p)² + f(p), in
float32 arithmetic as OpenCV's. Each distance is the correctly rounded square root of its (integer)
squared distance; the opencv-python 5 wheel's is one unit in the last place off on about a fifth of the
pixels (its square root is approximate), which is all that tells the two apart. It is about 1.5 times as
fast on the fitter's maps (one thread, `tests/test_distance_transform.py` checks the values, not the
time), because the column pass runs row by row (in memory order), the envelope is built over the
columns that have a seed only, and each envelope segment's distances are written in one loop. Cached on
disk like compiled.py.
"""
import numpy as np
from numba import njit

from mvpose_nodes.fitting import numba_cache  # noqa: F401  (first: the cache folder of this version's sources)

FAR = np.float32(1e15)   # OpenCV's "infinity" of the envelope (an exactly representable float32)


def exact_distances(seeds, out, scale=1.0):
    """Into out (H, W) float32: `scale` × the Euclidean distance [cells] from each cell to the nearest
    seed, seeds (H, W) uint8 nonzero at a seed (at least one). The square roots are correctly rounded;
    a scale that is a power of two (objective.MAP_COARSENING) keeps them so."""
    if seeds.shape != out.shape or out.dtype != np.float32 or seeds.dtype != np.uint8:
        raise ValueError(f'exact_distances: seeds {seeds.dtype} {seeds.shape}, out {out.dtype} {out.shape}: '
                         'want uint8 seeds and a float32 out of one shape')
    if not seeds.any():
        raise ValueError(f'exact_distances: no seed in a map of {seeds.shape}')
    _transform(seeds, out, np.float32(scale))


@njit(cache=True, nogil=True, error_model='numpy')
def _transform(seeds, out, scale):
    """exact_distances without its checks."""
    rows, columns = seeds.shape
    # Along the columns, row by row: each cell's distance to the nearest seed at or below it (`below`,
    # rows or more: none), then to the nearest above or below (`along`, squared in f, per seeded column).
    below = np.empty((rows, columns), np.int32)
    along = np.full(columns, rows - 1, np.int32)
    for r in range(rows - 1, -1, -1):
        for c in range(columns):
            along[c] = 0 if seeds[r, c] else along[c] + 1
            below[r, c] = along[c]
    seeded = np.flatnonzero(along < rows)   # a column whose seeds are all beyond reach has none
    count = len(seeded)
    f = np.empty((rows, count), np.float32)
    along[:] = rows - 1
    for r in range(rows):
        for c in range(columns):
            along[c] = min(along[c] + 1, below[r, c])
        for a in range(count):
            d = along[seeded[a]]
            f[r, a] = np.float32(d * d)
    # Along the rows. A seed in the row itself is nearer than any seed beyond it, so the row's own seeds
    # split it into parts whose cells' nearest seeds lie within the part (its own seeds at its ends
    # included): the envelope is built per part, and none inside a run of seeds (a silhouette's inside).
    half_inverse = np.zeros(columns, np.float32)   # 0.5 / (q - p), rounded as OpenCV's table
    for c in range(1, columns):
        half_inverse[c] = np.float32(0.5 / c)
    z = np.empty(count + 1, np.float32)
    v = np.empty(count, np.int64)
    for r in range(rows):
        height, row = f[r], out[r]
        low, first = 0, 0   # the part's first seeded column (index into `seeded`) and first cell
        for a in range(count + 1):
            if a < count and height[a] != 0:
                continue
            if a < count and a > 0 and low == a - 1 and height[low] == 0 and seeded[a] == seeded[low] + 1:
                row[seeded[a]] = 0.0   # within a run of the row's seeds
            else:
                last = columns - 1 if a == count else seeded[a]
                _envelope(height, seeded, low, min(a, count - 1), first, last, row, scale, half_inverse, z, v)
            if a < count:
                low, first = a, seeded[a] + 1


@njit(cache=True, nogil=True, error_model='numpy')
def _envelope(height, seeded, low, high, first, last, row, scale, half_inverse, z, v):
    """Into row[first … last]: scale × the distance to the lowest of the parabolas (q − p)² + height[a] of the
    seeded columns p = seeded[a], a = low … high, by their lower envelope: segment k (parabola v[k]) is the
    lowest from z[k] to z[k + 1]."""
    v[0], z[0], z[1] = low, -FAR, FAR
    k = 0
    for a in range(low + 1, high + 1):
        q = seeded[a]
        while True:
            p = seeded[v[k]]
            s = (height[a] + np.float32(q * q) - height[v[k]] - np.float32(p * p)) * half_inverse[q - p]
            if s > z[k]:
                k += 1
                v[k], z[k], z[k + 1] = a, s, FAR
                break
            k -= 1
    for segment in range(k + 1):
        end = last if z[segment + 1] >= last else int(np.floor(z[segment + 1]))
        p, floor = np.int32(seeded[v[segment]]), height[v[segment]]
        for q in range(first, end + 1):
            offset = np.int32(q - p)
            row[q] = np.sqrt(np.float32(offset * offset) + floor) * scale
        first = max(first, end + 1)
