"""The compiled objective and forward kinematics (fitting/compiled.py) equal the numpy reference
(StageSearch.stage_cost plus the search's priors, kinematics.forward_kinematics) to 1e-9 on random poses,
with the evidence of real features: studio renders of the CMU walk through the feature pipeline (labelled
boundaries, outlines, keypoints), in a rig with and without lens distortion."""
import dataclasses
import math

import numpy as np
import pytest

from mvpose_nodes.body.camera import studio_rig
from mvpose_nodes.body.kinematics import bone_lengths, forward_kinematics, inverse_kinematics
from mvpose_nodes.body.model import STAGE_NAMES
from mvpose_nodes.fitting.compiled import pack_frame
from mvpose_nodes.fitting.compiled_kinematics import bone_length_array, forward_joints
from mvpose_nodes.fitting.views import frame_set_arena, view_from_features
from mvpose_nodes.fitting.settings import FitterSettings
from mvpose_nodes.fitting.stage_search import STAGE_PARAMETERS, StageSearch, stage_indices
from mvpose_nodes.ros.params import default_skin_model_path
from mvpose_nodes.studio import scene
from mvpose_nodes.vision.features import FeatureExtractor, FeatureSettings
from mvpose_nodes.vision.skin import SkinModel

pytestmark = pytest.mark.pure

POSES = 12          # random poses per stage
RELATIVE = 1e-9


@pytest.fixture(scope='module', params=[0.0, -0.05], ids=['pinhole', 'barrel'])
def walk_features(request, cmu_walk):
    """(truth joints (15, 3), [(camera, vision.features.Features)]) of one walking frame in cameras 2, 5 and
    7 at 960×540 through the feature pipeline; the rig with radial distortion k1 as the parameter."""
    motion = cmu_walk.placed(heading=math.radians(30))
    i = len(motion.joints) // 2
    pose = scene.BodyPose(motion.joints[i], motion.toes[i], motion.hand_tips[i], motion.head_forward[i])
    extractor = FeatureExtractor(FeatureSettings(), SkinModel.load(default_skin_model_path()))
    found = []
    for camera in studio_rig((960, 540), cameras=[2, 5, 7]):
        camera = camera.__class__(**{**camera.__dict__, 'D': np.array([request.param, 0.0, 0.0, 0.0, 0.0])})
        view = scene.prepare_camera(camera)
        rgb, _ = scene.Realism().finish(scene.render(view, pose, scene.Appearance()), view, camera.number, 0, 0)
        found.append((camera, extractor(rgb)))
    return motion.joints[i], found


@pytest.fixture(scope='module')
def walk_frame(walk_features):
    """(truth joints (15, 3), [fitter.View]) of walk_features' frame."""
    truth, found = walk_features
    views = [view_from_features(camera, f.visible_keypoints(), f.contour, f.frontness) for camera, f in found]
    assert all(view.distances is not None and view.distances.widths for view in views)
    return truth, views


def reference_objective(search, stage, parameters, start, views, assigned):
    """StageSearch.stage_cost plus the priors (smoothness, joint and twist limits), as the search's cost adds them."""
    settings = search.settings
    indices = stage_indices(stage)
    steps = np.array([settings.step_position if name.endswith(('_x', '_y', '_z')) else settings.step_angle
                      for name in STAGE_PARAMETERS[stage]])
    total, used = search.stage_cost(stage, parameters, views, assigned)
    total += settings.smoothness_weight * np.sum(((parameters[indices] - start[indices]) / steps) ** 2)
    total += search.limit_cost(stage, parameters)   # joint and twist limits
    return total, sorted(used)


def test_compiled_forward_kinematics_equals_the_reference():
    rng = np.random.default_rng(1)
    lengths = bone_lengths(1.5 + 0.45 * rng.random())
    for _ in range(50):
        parameters = rng.normal(scale=1.0, size=29)
        assert np.abs(forward_joints(parameters, bone_length_array(lengths))
                      - forward_kinematics(parameters, lengths)[0]).max() < 1e-9


@pytest.mark.parametrize('stage', STAGE_NAMES)
def test_compiled_stage_objective_equals_the_reference_on_random_poses(walk_frame, stage):
    truth, views = walk_frame
    search = StageSearch(FitterSettings(), bone_lengths(1.75))
    frame = pack_frame(views)
    rng = np.random.default_rng(STAGE_NAMES.index(stage))
    true_parameters = inverse_kinematics(truth)
    indices = stage_indices(stage)
    compared = 0
    for _ in range(POSES):
        start = true_parameters + rng.normal(scale=0.1, size=29)
        assigned = search.outline_assignment(stage, start, views, frame)
        pack = search.stage_pack(stage, start, views, assigned, priors=True)
        trial = start.copy()
        trial[indices] += rng.normal(scale=0.4, size=len(indices))   # also beyond the joint limits
        reference, used = reference_objective(search, stage, trial, start, views, assigned)
        flags = np.zeros(len(views), bool)
        from mvpose_nodes.fitting.compiled import stage_objective
        from mvpose_nodes.fitting.stage_search import FRACTIONS, SAMPLES
        compiled = stage_objective(trial[indices], pack, frame, search.bone_lengths, FRACTIONS, SAMPLES, flags)
        assert compiled == pytest.approx(reference, rel=RELATIVE), (stage, trial)
        assert np.flatnonzero(flags).tolist() == used
        without_priors, used_views = search.compiled_cost(stage, trial, views, assigned, frame)
        assert without_priors == pytest.approx(search.stage_cost(stage, trial, views, assigned)[0], rel=RELATIVE)
        with_limits, _ = search.compiled_cost(stage, trial, views, assigned, frame, limits=True)
        assert with_limits == pytest.approx(without_priors + search.limit_cost(stage, trial), rel=RELATIVE)
        compared += reference > 0
    assert compared == POSES, 'every pose has evidence in this stage'


@pytest.mark.parametrize('stage', ['torso', 'left_arm', 'right_leg'])
def test_compiled_nelder_mead_takes_scipys_steps(walk_frame, stage):
    """From the same simplex, the compiled search visits SciPy's points: the same result and evaluation
    count, also when the evaluation budget ends it."""
    from scipy.optimize import minimize
    from mvpose_nodes.fitting.compiled import stage_objective
    from mvpose_nodes.fitting.compiled_search import nelder_mead
    from mvpose_nodes.fitting.stage_search import FRACTIONS, SAMPLES
    truth, views = walk_frame
    search = StageSearch(FitterSettings(), bone_lengths(1.75))
    frame = pack_frame(views)
    rng = np.random.default_rng(7)
    indices = stage_indices(stage)
    for budget in (1000, 40):
        start = inverse_kinematics(truth) + rng.normal(scale=0.1, size=29)
        pack = search.stage_pack(stage, start, views, search.outline_assignment(stage, start, views, frame), priors=True)
        flags = np.zeros(len(views), bool)
        simplex = np.vstack([start[indices], start[indices] + np.diag(pack.steps)])
        reference = minimize(stage_objective, start[indices], (pack, frame, search.bone_lengths, FRACTIONS, SAMPLES, flags),
                             method='Nelder-Mead', options={'initial_simplex': simplex, 'xatol': 1e-2, 'fatol': np.inf,
                                                            'adaptive': False, 'maxfev': budget})
        x, cost, evaluations = nelder_mead(simplex, 1e-2, np.inf, budget, pack, frame, search.bone_lengths, FRACTIONS,
                                           SAMPLES, flags)
        assert evaluations == reference.nfev and (budget > 100 or evaluations == budget)
        assert np.array_equal(x, reference.x) and cost == reference.fun


def test_maps_made_in_one_arena_reach_the_search_without_a_copy_and_unchanged(walk_features, walk_frame):
    """A frame set's views made in one MapArena (as the skeleton_fitter node makes them): pack_frame passes
    the arena itself to the search, and every field of the FramePack reads the same values as with
    views that have maps of their own (which pack_frame copies together)."""
    truth, found = walk_features
    arena = frame_set_arena([f.contour for _, f in found])
    in_arena = [view_from_features(camera, f.visible_keypoints(), f.contour, f.frontness, arena=arena)
                for camera, f in found]
    packed, reference = pack_frame(in_arena), pack_frame(walk_frame[1])
    assert packed.boundary is arena.buffer and packed.outside is arena.buffer
    offsets = ('outside', 'outside_at', 'boundary', 'boundary_at')
    for name in reference._fields:
        if name not in offsets:
            assert np.array_equal(getattr(packed, name), getattr(reference, name)), name

    def same_map(buffer, start, other, other_start, shape):
        size = int(np.prod(shape))
        return np.array_equal(buffer[start:start + size], other[other_start:other_start + size])
    for v in range(len(found)):
        assert same_map(packed.outside, packed.outside_at[v], reference.outside, reference.outside_at[v],
                        reference.outside_shape[v])
        for k in np.flatnonzero(reference.slot[v]):
            for side in range(2):
                assert same_map(packed.boundary, packed.boundary_at[v, k, side], reference.boundary,
                                reference.boundary_at[v, k, side], reference.boundary_shape[v, k])


def test_nearest_capsules_equal_the_minimum_of_the_residuals():
    from mvpose_nodes.fitting.compiled import nearest_capsules
    from mvpose_nodes.fitting.objective import capsule_residuals
    rng = np.random.default_rng(3)
    points = rng.uniform(0, 500, size=(300, 2))
    starts, ends = rng.uniform(0, 500, size=(14, 2)), rng.uniform(0, 500, size=(14, 2))
    radii, terminal = rng.uniform(0, 30, size=14), rng.random(14) < 0.4
    residuals = capsule_residuals(points, starts, ends, radii, terminal)
    nearest, found = nearest_capsules(points, starts, ends, radii, terminal)
    assert np.array_equal(nearest, residuals.argmin(axis=1))
    assert np.allclose(found, residuals.min(axis=1), rtol=1e-12, atol=1e-9)


def test_the_outline_assignment_equals_the_reference_on_random_poses(walk_frame):
    """compiled.outline_nearest (the pose's capsules in every view at once) gives each outline point the
    nearest capsule and gate verdict that the numpy reference gives view by view: the pose's joints
    projected (body.camera.Camera.project), its capsules (projected_capsules) and nearest_capsules;
    also for a view without an outline."""
    from mvpose_nodes.fitting.compiled import nearest_capsules
    from mvpose_nodes.fitting.stage_search import CAPSULE_TERMINAL, projected_capsules
    truth, views = walk_frame
    views = views + [dataclasses.replace(views[0], outline=None)]
    search = StageSearch(FitterSettings(), bone_lengths(1.75))
    frame = pack_frame(views)
    rng = np.random.default_rng(11)
    gated = 0
    for _ in range(POSES):
        parameters = inverse_kinematics(truth) + rng.normal(scale=0.2, size=29)
        joints, _ = forward_kinematics(parameters, search.lengths)
        for view, (capsule, within) in zip(views, search.outline_nearest(parameters, frame)):
            if view.outline is None:
                assert capsule is None and within is None
                continue
            reference, residuals = nearest_capsules(view.outline.points, *projected_capsules(
                view, *view.camera.project(joints)), CAPSULE_TERMINAL)
            assert np.array_equal(capsule, reference)
            assert np.array_equal(within, np.abs(residuals) < search.settings.outline_gate)
            gated += np.count_nonzero(~within)
    assert gated, 'some points lie beyond the gate of every capsule'


def test_a_segment_inside_its_maps_is_read_as_point_by_point_to_the_bit():
    """The look-ups of a segment that lies inside a part's maps, both sides at once and without clamping
    (compiled._inside_lookups, which the objective uses when _segment_inside says so), equal _bilinear's at
    each of its points exactly; a segment that leaves the maps, by a corner or by a thousandth of a cell, is
    not taken for one inside."""
    from mvpose_nodes.fitting.compiled import _bilinear, _inside_lookups, _segment_inside
    from mvpose_nodes.fitting.objective import MAP_COARSENING
    from mvpose_nodes.fitting.stage_search import FRACTIONS
    rng = np.random.default_rng(11)
    height, width = 70, 45   # on the coarse grid: the box is 90 × 140 image px
    buffer = rng.uniform(0, 80, size=2 * height * width + 7).astype(np.float32)
    at_a, at_b = 3, 3 + height * width
    origin = (120.0, 40.0)
    inside = 0
    for _ in range(200):
        a, b = (np.array(origin) + rng.uniform(-10, (MAP_COARSENING * width + 10, MAP_COARSENING * height + 10), 2)
                for _ in range(2))
        if not _segment_inside(a, b, *origin, height, width):
            continue
        inside += 1
        d1, d2 = np.empty(len(FRACTIONS)), np.empty(len(FRACTIONS))
        _inside_lookups(buffer, at_a, at_b, height, width, a, b, *origin, FRACTIONS, d1, d2)
        for s, f in enumerate(FRACTIONS):
            x, y = a + f * (b - a) - origin
            assert d1[s] == _bilinear(buffer, at_a, height, width, x, y)
            assert d2[s] == _bilinear(buffer, at_b, height, width, x, y)
    assert inside > 100
    last_centre = MAP_COARSENING * (width - 1) + 0.5 * (MAP_COARSENING - 1)   # [px] the last cell's centre, from the box
    end = np.array(origin) + (last_centre, 30.0)
    assert _segment_inside(np.array(origin) + (20.0, 30.0), end - (0.01, 0.0), *origin, height, width)
    assert not _segment_inside(np.array(origin) + (20.0, 30.0), end + (0.001, 0.0), *origin, height, width)
    assert not _segment_inside(np.array(origin) + (20.0, 30.0), np.array(origin) + (-1.0, -1.0), *origin, height, width)


def test_outline_points_out_of_view_order_are_refused(walk_frame):
    """The objective reads each view's outline points as one run of StagePack.points (work_arrays): points
    not grouped by view in view order are an error, not a silently wrong cost."""
    from mvpose_nodes.fitting.compiled import stage_objective
    from mvpose_nodes.fitting.stage_search import FRACTIONS, SAMPLES
    truth, views = walk_frame
    search = StageSearch(FitterSettings(), bone_lengths(1.75))
    parameters = inverse_kinematics(truth)
    frame = pack_frame(views)
    pack = search.stage_pack('torso', parameters, views, search.outline_assignment('torso', parameters, views, frame),
                             priors=True)
    assert len(set(pack.point_view.tolist())) > 1
    indices = stage_indices('torso')
    flags = np.zeros(len(views), bool)
    stage_objective(parameters[indices], pack, frame, search.bone_lengths, FRACTIONS, SAMPLES, flags)
    shuffled = pack._replace(point_view=pack.point_view[::-1].copy(), points=pack.points[::-1].copy())
    with pytest.raises(ValueError, match='grouped by view'):
        stage_objective(parameters[indices], shuffled, frame, search.bone_lengths, FRACTIONS, SAMPLES, flags)
