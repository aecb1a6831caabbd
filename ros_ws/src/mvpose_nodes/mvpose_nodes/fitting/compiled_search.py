"""The Nelder–Mead search compiled with numba (paper 000 Sec. 5.1, Eq. 7), over compiled.py's stage
objective: a stage's whole search runs without the interpreter between its evaluations. Cached on disk
and releasing the GIL as compiled.py's functions do.
"""
import numpy as np
from numba import njit

from mvpose_nodes.fitting import numba_cache  # noqa: F401  (first: the cache folder of this version's sources)
from mvpose_nodes.fitting.compiled import FramePack, StagePack, evaluate, work_arrays


# Nelder–Mead (Lagarias et al. 1998) with paper 000's coefficients (Eq. 7): reflection ρ = 1, expansion
# χ = 2, contraction γ = 0.5, shrink σ = 0.5; step for step SciPy's non-adaptive
# scipy.optimize.minimize(method='Nelder-Mead') with an initial simplex, xatol, fatol and maxfev (its
# _minimize_neldermead, SciPy 1.17), so that a search gives SciPy's result (tests/test_compiled.py),
# without the interpreter between the evaluations.
REFLECTION, EXPANSION, CONTRACTION, SHRINK = 1.0, 2.0, 0.5, 0.5


@njit(cache=True)
def _sort_simplex(simplex, costs):
    """Sort the vertices by cost, ascending; ties keep their order (insertion sort, as numpy's sort of
    fewer than 16 numbers)."""
    for i in range(1, len(costs)):
        j = i
        while j > 0 and costs[j] < costs[j - 1]:
            costs[j], costs[j - 1] = costs[j - 1], costs[j]
            row = simplex[j].copy()
            simplex[j] = simplex[j - 1]
            simplex[j - 1] = row
            j -= 1


@njit(cache=True)
def nelder_mead(simplex, xatol, fatol, maxfev, stage, frame, bone_lengths, fractions, samples, used):
    """Minimise stage_objective from the initial simplex (n + 1, n). Returns (x (n,), cost, evaluations).
    At most maxfev evaluations; as in SciPy, the evaluation that would exceed them ends the search
    where it stands."""
    sim = simplex.copy()
    n = sim.shape[1]
    point_range, work = work_arrays(stage, frame, fractions)
    costs = np.full(n + 1, np.inf)
    calls = 0
    for k in range(n + 1):
        if calls >= maxfev:
            break
        calls += 1
        costs[k] = evaluate(sim[k].copy(), stage, frame, bone_lengths, fractions, samples, used, point_range, work)
    _sort_simplex(sim, costs)
    while calls < maxfev:
        if np.max(np.abs(sim[1:] - sim[0])) <= xatol and np.max(np.abs(costs[0] - costs[1:])) <= fatol:
            break
        centroid = sim[0].copy()
        for row in range(1, n):
            centroid += sim[row]
        centroid /= n
        worst = sim[n].copy()
        reflected = (1 + REFLECTION) * centroid - REFLECTION * worst
        if calls >= maxfev:
            break
        calls += 1
        cost_reflected = evaluate(reflected, stage, frame, bone_lengths, fractions, samples, used, point_range, work)
        shrink = False
        if cost_reflected < costs[0]:
            expanded = (1 + REFLECTION * EXPANSION) * centroid - REFLECTION * EXPANSION * worst
            if calls >= maxfev:
                break
            calls += 1
            cost_expanded = evaluate(expanded, stage, frame, bone_lengths, fractions, samples, used, point_range, work)
            if cost_expanded < cost_reflected:
                sim[n], costs[n] = expanded, cost_expanded
            else:
                sim[n], costs[n] = reflected, cost_reflected
        elif cost_reflected < costs[n - 1]:
            sim[n], costs[n] = reflected, cost_reflected
        else:
            if cost_reflected < costs[n]:
                contracted = (1 + CONTRACTION * REFLECTION) * centroid - CONTRACTION * REFLECTION * worst
                if calls >= maxfev:
                    break
                calls += 1
                cost_contracted = evaluate(contracted, stage, frame, bone_lengths, fractions, samples, used, point_range, work)
                if cost_contracted <= cost_reflected:
                    sim[n], costs[n] = contracted, cost_contracted
                else:
                    shrink = True
            else:
                contracted = (1 - CONTRACTION) * centroid + CONTRACTION * worst
                if calls >= maxfev:
                    break
                calls += 1
                cost_contracted = evaluate(contracted, stage, frame, bone_lengths, fractions, samples, used, point_range, work)
                if cost_contracted < costs[n]:
                    sim[n], costs[n] = contracted, cost_contracted
                else:
                    shrink = True
            if shrink:
                for j in range(1, n + 1):
                    sim[j] = sim[0] + SHRINK * (sim[j] - sim[0])
                    if calls >= maxfev:
                        break
                    calls += 1
                    costs[j] = evaluate(sim[j].copy(), stage, frame, bone_lengths, fractions, samples, used, point_range, work)
        _sort_simplex(sim, costs)
    _sort_simplex(sim, costs)
    return sim[0].copy(), costs[0], calls


# The entry point from Python, with the packs' fields as separate arguments: numba types top-level arrays in C,
# but the arrays inside a tuple in Python, at about 10 µs each, which cost more than a stage objective.
@njit(cache=True, nogil=True, error_model='numpy')
def search(simplex, xatol, fatol, maxfev, bone_lengths, fractions, samples, used,
           indices, base, start, steps, low, high, capsules, capsule_radius, capsule_terminal, assigned,
           points, point_view, bones, bone_slot, keypoint_view, keypoint_joint, keypoint_xy, keypoint_weight,
           twist_bones, twist_reference, twist_neutral, twist_low, twist_high, twist_hinge, lateral_low, lateral_high,
           weights, K, R, t, D, has_outline, outside, outside_at, outside_shape, outside_origin, slot, boundary,
           boundary_at, boundary_shape, boundary_origin, boundary_width, outline_x, outline_y, outline_range):
    """nelder_mead with the StagePack and FramePack given field by field: search(..., *stage, *frame).
    With maxfev 1 it evaluates the simplex's first vertex and stops: one evaluation of the objective."""
    stage = StagePack(indices, base, start, steps, low, high, capsules, capsule_radius, capsule_terminal,
                      assigned, points, point_view, bones, bone_slot, keypoint_view, keypoint_joint, keypoint_xy,
                      keypoint_weight, twist_bones, twist_reference, twist_neutral, twist_low, twist_high, twist_hinge,
                      lateral_low, lateral_high, weights)
    frame = FramePack(K, R, t, D, has_outline, outside, outside_at, outside_shape, outside_origin, slot, boundary,
                      boundary_at, boundary_shape, boundary_origin, boundary_width, outline_x, outline_y, outline_range)
    return nelder_mead(simplex, xatol, fatol, maxfev, stage, frame, bone_lengths, fractions, samples, used)

