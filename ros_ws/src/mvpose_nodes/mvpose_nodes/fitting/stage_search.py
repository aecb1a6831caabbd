"""One stage of the hierarchical search (paper 000 Sec. 5.1): its parameters, evidence, objective and
Nelder–Mead run.

Each of the six stages (torso, head and neck, left arm, right arm, left leg, right leg) searches its
own parameters with the rest fixed, minimising its own objective (weights: settings.FitterSettings):
  - Eq. 4–5 for every bone that has labelled boundaries (torso, head, thighs, shins): the projected
    bone midway between its part's two sides, summed over the cameras that see them; plus the
    "stay on the part" term of objective._camera_cost (enclosure_weight);
  - the outline term (objective.outline_cost, beyond the paper): the stage's bones as capsules
    explaining the part of each camera's outline that lies nearest to them, and staying inside the
    silhouette. It sees what the labelled parts cannot: the arms, and the torso's turn about the spine
    from the widths of shoulders and hips;
  - the reprojection distance of the joints that the features located in 2D (root, neck, head,
    elbows, wrists, knees, ankles), robust (keypoint_scale), weighted by confidence and made up for the
    views that left a keypoint out (keypoint_targets). The paper uses these keypoints for
    initialisation; the arms have no labelled contour, so for them the skin keypoints are evidence too,
    as in paper 000 Sec. 3.2;
  - priors: smoothness towards the stage's start (25 fps) and joint limits.
Nelder–Mead (Lagarias et al. 1998): SciPy's with its standard coefficients, which are the paper's
(Eq. 7: ρ = 1, χ = 2, γ = 0.5, σ = 0.5; non-adaptive), stopped by the simplex size (xatol) alone;
compiled, with the objective, in compiled.py (this module's stage_cost is the objective's reference).
"""
from dataclasses import dataclass

import numpy as np

from mvpose_nodes.body.geometry import cross
from mvpose_nodes.body.kinematics import BONE_INDEX, BONES, forward_kinematics
from mvpose_nodes.body.model import (JOINT_INDEX, LABEL_HEAD, LABEL_LEFT_LEG, LABEL_RIGHT_LEG, LABEL_TORSO,
                                     PARAMETER_INDEX)
from mvpose_nodes.fitting.compiled import LABEL_SLOT, StagePack, fractions_arrays, outline_nearest
from mvpose_nodes.fitting.compiled_search import search
from mvpose_nodes.fitting.compiled_kinematics import LATERAL_STIFFNESS, bone_length_array
from mvpose_nodes.fitting.objective import (CAPSULE_RADII, OUTLINE_STEP, TERMINAL_BONES, cauchy_loss, inside_cost,
                                            limb_cost, outline_cost)

JOINT_LIMITS = {'left_shin_rx': (-2.6, 0.05), 'right_shin_rx': (-2.6, 0.05),     # knees bend backwards,
                'left_forearm_rx': (-0.05, 2.6), 'right_forearm_rx': (-0.05, 2.6),  # elbows forwards [rad];
                # the clavicles move little, and no keypoint sees the shoulders: keep them near the rest
                **{f'{side}_clavicle_{axis}': (-0.5, 0.5) for side in ('left', 'right') for axis in ('ry', 'rz')}}
# The twist of the limbs whose child is a hinge, about their own axis (compiled_kinematics.limb_twist):
# (bone, hinge, reference direction and the hinge axis there, in the parent's frame (x right, y forward,
# z up), the twist's range [rad], and the range [rad] of the limb's lateral angle, the arcsine of its
# direction's x).
# Without it a thigh turned half round bends its knee forwards and the body facing backwards explains the
# silhouettes as well as the right one; anatomically the hip turns about ±45° (measured on the suite's
# tuning motions with the knee bent over 25°: within ±30°, a cartwheel 61°). The arms' reference is the
# T-pose, where the swing is defined for every direction the arm can take (an arm overhead included); the
# humerus turns about ±90° (tuning motions: -34° to 93° for the right arm). A thigh crosses the body's middle
# little (adduction): on the tuning motions at most 14° (a cartwheel 23°), where the knees and ankles of the
# other leg, the legs exchanged, put it at 10-35° (median 20-26°); so a leg's lateral angle towards the other
# side is limited to ADDUCTION (abduction: free). Nor does an upper arm reach far across the body: on the
# tuning motions at most -2° towards the other side (a cartwheel 32°), the elbows and wrists exchanged 45° or
# more (median 55-65°); so ACROSS (the shoulder's horizontal adduction reaches about 45°).
ADDUCTION = np.radians(15.0)
ACROSS = np.radians(35.0)
TWIST_LIMITS = {
    'left_leg': ('left_thigh', 'left_shin_rx', (0.0, 0.0, -1.0), (1.0, 0.0, 0.0), np.radians((-45.0, 45.0)),
                 (-np.pi / 2, ADDUCTION)),
    'right_leg': ('right_thigh', 'right_shin_rx', (0.0, 0.0, -1.0), (1.0, 0.0, 0.0), np.radians((-45.0, 45.0)),
                  (-ADDUCTION, np.pi / 2)),
    'left_arm': ('left_upper_arm', 'left_forearm_rx', (-1.0, 0.0, 0.0), (0.0, 0.0, -1.0), np.radians((-110.0, 60.0)),
                 (-np.pi / 2, ACROSS)),
    'right_arm': ('right_upper_arm', 'right_forearm_rx', (1.0, 0.0, 0.0), (0.0, 0.0, 1.0), np.radians((-60.0, 110.0)),
                  (-ACROSS, np.pi / 2)),
}
KEYPOINT_JOINT = {'root': 'pelvis'}   # 2D keypoint name -> the joint it locates

STAGE_PARAMETERS = {
    'torso': ('torso_x', 'torso_y', 'torso_z', 'torso_rx', 'torso_ry', 'torso_rz'),
    'head_neck': ('head_rx', 'head_ry', 'head_rz'),
    'left_arm': ('left_clavicle_ry', 'left_clavicle_rz', 'left_upper_arm_rx', 'left_upper_arm_ry',
                 'left_upper_arm_rz', 'left_forearm_rx'),
    'right_arm': ('right_clavicle_ry', 'right_clavicle_rz', 'right_upper_arm_rx', 'right_upper_arm_ry',
                  'right_upper_arm_rz', 'right_forearm_rx'),
    'left_leg': ('left_thigh_rx', 'left_thigh_ry', 'left_thigh_rz', 'left_shin_rx'),
    'right_leg': ('right_thigh_rx', 'right_thigh_ry', 'right_thigh_rz', 'right_shin_rx'),
}
STAGE_BONES = {  # bones with labelled boundaries: (bone, part label)
    'torso': (('torso', LABEL_TORSO),), 'head_neck': (('head', LABEL_HEAD),), 'left_arm': (), 'right_arm': (),
    'left_leg': (('left_thigh', LABEL_LEFT_LEG), ('left_shin', LABEL_LEFT_LEG)),
    'right_leg': (('right_thigh', LABEL_RIGHT_LEG), ('right_shin', LABEL_RIGHT_LEG)),
}
STAGE_KEYPOINTS = {
    # Only the torso's own keypoints: with the limbs' keypoints too, the torso would turn to explain
    # the limbs' motion since the last frame (their angles are still the last frame's), and drift.
    'torso': ('root', 'neck', 'head'),
    'head_neck': ('head',), 'left_arm': ('left_elbow', 'left_wrist'),
    'right_arm': ('right_elbow', 'right_wrist'), 'left_leg': ('left_knee', 'left_ankle'),
    'right_leg': ('right_knee', 'right_ankle'),
}
STAGE_CAPSULES = {  # bones whose capsules explain the outline in each stage (objective.outline_cost)
    'torso': ('torso', 'left_hip', 'right_hip', 'left_clavicle', 'right_clavicle'), 'head_neck': ('head',),
    'left_arm': ('left_clavicle', 'left_upper_arm', 'left_forearm'),
    'right_arm': ('right_clavicle', 'right_upper_arm', 'right_forearm'),
    'left_leg': ('left_thigh', 'left_shin'), 'right_leg': ('right_thigh', 'right_shin'),
}
CAPSULE_ENDS = np.array([(JOINT_INDEX[bone.parent_joint], JOINT_INDEX[bone.joint]) for bone in BONES])  # (14, 2)
CAPSULE_RADIUS = np.array([CAPSULE_RADII[bone.name.replace('left_', '').replace('right_', '')] for bone in BONES])
CAPSULE_TERMINAL = np.array([bone.name.endswith(TERMINAL_BONES) for bone in BONES])
FRACTIONS, SAMPLES = fractions_arrays()
WITHOUT_PRIORS = np.array([1.0] * 8 + [0.0, 0.0])   # StagePack.weights' factors: smoothness and limits off
WITHOUT_SMOOTHNESS = np.array([1.0] * 8 + [0.0, 1.0])   # the same factors: smoothness off, limits on
STAGE_CAPSULE_INDEX = {stage: np.array([BONE_INDEX[name] for name in names]) for stage, names in STAGE_CAPSULES.items()}
STAGE_CAPSULE_MASK = {stage: np.isin(np.arange(len(BONES)), index) for stage, index in STAGE_CAPSULE_INDEX.items()}


@dataclass
class StageResult:
    name: str
    cost: float
    evaluations: int
    cameras: list
    fitted: bool


def stage_indices(stage):
    """The indices (into the 29 parameters) that `stage` searches."""
    return [PARAMETER_INDEX[name] for name in STAGE_PARAMETERS[stage]]


def twist_arrays(stage):
    """The StagePack's twist fields of `stage` (TWIST_LIMITS; empty for the torso and the head): bones (T,),
    reference and neutral (T, 3), twist low and high (T,) [rad], hinge parameter indices (T,), lateral low
    and high (T,) [rad]."""
    limits = [TWIST_LIMITS[stage]] if stage in TWIST_LIMITS else []
    return (np.array([BONE_INDEX[bone] for bone, *_ in limits], np.int64),
            np.array([reference for _, _, reference, *_ in limits], float).reshape(-1, 3),
            np.array([neutral for _, _, _, neutral, *_ in limits], float).reshape(-1, 3),
            np.array([span[0] for *_, span, _ in limits], float), np.array([span[1] for *_, span, _ in limits], float),
            np.array([PARAMETER_INDEX[hinge] for _, hinge, *_ in limits], np.int64),
            np.array([lateral[0] for *_, lateral in limits], float),
            np.array([lateral[1] for *_, lateral in limits], float))


def twist_excess(stage, frames, parameters):
    """[rad²] The squared excess of the stage's limb's twist beyond its TWIST_LIMITS, times the sine of its
    child hinge's angle (at most 90°), squared, plus LATERAL_STIFFNESS × the squared excess of its lateral
    angle: bone frames {bone: 3×3} (kinematics.forward_kinematics) and parameters (29,). The twist: the
    signed angle about the limb's direction d, in its parent's frame, from the hinge axis it would have if
    swung to d from the reference direction by the shortest rotation (Rodrigues), its hinge axis there
    being the neutral one, to the hinge axis (the limb frame's x) it has; the lateral angle: arcsin(d_x).
    The reference of compiled_kinematics.limb_excess."""
    bone, hinge, reference, neutral, (low, high), (lateral_low, lateral_high) = TWIST_LIMITS[stage]
    parent = BONES[BONE_INDEX[bone]].parent
    local = frames[parent].T @ frames[bone] if parent else frames[bone]
    direction, axis = local @ np.array([0.0, 0.0, -1.0]), local[:, 0]
    reference, neutral = np.array(reference), np.array(neutral)
    lateral = np.arcsin(np.clip(direction[0], -1.0, 1.0))
    aside = LATERAL_STIFFNESS * (max(lateral_low - lateral, 0.0) + max(lateral - lateral_high, 0.0)) ** 2
    cosine = float(np.dot(reference, direction))
    if 1.0 + cosine < 1e-6:
        return float(aside)
    rotation_axis = cross(reference, direction)
    sine = np.linalg.norm(rotation_axis)
    angle = np.arctan2(sine, cosine)
    unit = rotation_axis / max(sine, 1e-300)
    swung = (neutral * np.cos(angle) + cross(unit, neutral) * np.sin(angle)
             + unit * np.dot(unit, neutral) * (1 - np.cos(angle)))
    twist = np.arctan2(np.dot(cross(swung, axis), direction), np.dot(swung, axis))
    beyond = max(low - twist, 0.0) + max(twist - high, 0.0)
    return float((beyond * np.sin(min(abs(parameters[PARAMETER_INDEX[hinge]]), np.pi / 2))) ** 2 + aside)


def projected_capsules(view, pixels, depth, bones=slice(None)):
    """The projected capsules of `bones` (indices into BONES; default all) in one view: starts, ends
    (B, 2) [px], radii (B,) [px] (CAPSULE_RADIUS at the bone's mean depth), from the projected joints
    pixels (15, 2), depth (15,)."""
    ends = CAPSULE_ENDS[bones]
    mean_depth = np.maximum(0.5 * (depth[ends[:, 0]] + depth[ends[:, 1]]), 0.1)
    return pixels[ends[:, 0]], pixels[ends[:, 1]], CAPSULE_RADIUS[bones] * view.camera.K[0, 0] / mean_depth


def has_evidence(stage, views, assigned):
    """Whether any view has the stage's keypoints, labelled boundaries, or outline points."""
    return any(name in view.keypoints for view in views for name in STAGE_KEYPOINTS[stage]) or any(
        view.distances is not None and label in view.distances.widths
        for view in views for _, label in STAGE_BONES[stage]) or any(
        points is not None and len(points) for points in assigned)


class StageSearch:
    """The stages' objectives and searches for one person (bone lengths [m] by name) under `settings`
    (FitterSettings)."""

    def __init__(self, settings, lengths):
        self.settings = settings
        self.lengths = lengths
        self.bone_lengths = bone_length_array(lengths)

    def search(self, stage, parameters, views, assigned, frame):
        """One Nelder–Mead stage over STAGE_PARAMETERS[stage]; (new parameters, StageResult). assigned:
        per view the outline points the stage explains (outline_assignment); frame: the views'
        compiled.FramePack. The search is compiled_search.nelder_mead (SciPy's, step for step) and each
        evaluation compiled.stage_objective: stage_cost plus the priors."""
        settings = self.settings
        if not has_evidence(stage, views, assigned):
            return parameters, StageResult(stage, 0.0, 0, [], False)
        indices = stage_indices(stage)
        pack = self.stage_pack(stage, parameters, views, assigned, priors=True)
        start = parameters[indices]
        found, _, evaluations = search(
            np.vstack([start, start + np.diag(pack.steps)]), settings.simplex_tolerance, np.inf,
            settings.max_evaluations_per_parameter * len(indices), self.bone_lengths, FRACTIONS, SAMPLES,
            np.zeros(len(views), np.bool_), *pack, *frame)
        fitted = parameters.copy()
        fitted[indices] = found
        final, used = self.compiled_cost(stage, fitted, views, assigned, frame, pack)
        return fitted, StageResult(stage, final, int(evaluations), sorted(views[i].camera.number for i in used), True)

    def compiled_cost(self, stage, parameters, views, assigned, frame, pack=None, limits=False):
        """stage_cost (without the priors; with `limits`, plus limit_cost) by the compiled objective at
        `parameters` (29,): (cost, indices of the views that contributed). pack: a stage_pack of this stage,
        views and assignment to reuse (its start does not matter here; with `limits`, one made with priors), or None
        to make one."""
        if pack is None:
            pack = self.stage_pack(stage, parameters, views, assigned, priors=limits)
        factors = WITHOUT_SMOOTHNESS if limits else WITHOUT_PRIORS
        pack = pack._replace(base=np.asarray(parameters, float).copy(), weights=pack.weights * factors)
        used = np.zeros(len(views), np.bool_)
        vertices = np.tile(parameters[pack.indices], (len(pack.indices) + 1, 1))   # a search of one evaluation
        _, cost, _ = search(vertices, 0.0, 0.0, 1, self.bone_lengths, FRACTIONS, SAMPLES, used, *pack, *frame)
        return float(cost), np.flatnonzero(used).tolist()

    def stage_pack(self, stage, parameters, views, assigned, priors):
        """The compiled.StagePack of the stage's search from `parameters` (29,) (the start, and the values
        of the parameters it does not search); priors=False leaves the smoothness and limits out."""
        settings = self.settings
        names = STAGE_PARAMETERS[stage]
        indices = np.array(stage_indices(stage), np.int64)
        steps = np.array([settings.step_position if name.endswith(('_x', '_y', '_z')) else settings.step_angle
                          for name in names])
        limits = np.array([JOINT_LIMITS.get(name, (-np.inf, np.inf)) for name in names], float)
        mine = STAGE_CAPSULE_INDEX[stage]
        assigned = [None] * len(views) if assigned is None else assigned
        points = [a for a in assigned if a is not None and len(a)]
        targets = self.keypoint_targets(stage, views)
        bones = STAGE_BONES[stage]
        return StagePack(
            indices, np.asarray(parameters, float).copy(), np.asarray(parameters, float)[indices].copy(), steps,
            limits[:, 0].copy(), limits[:, 1].copy(), mine.astype(np.int64), CAPSULE_RADIUS[mine],
            CAPSULE_TERMINAL[mine], np.array([a is not None for a in assigned], np.bool_),
            np.concatenate(points).astype(float) if points else np.zeros((0, 2)),
            np.concatenate([np.full(len(a), i) for i, a in enumerate(assigned) if a is not None and len(a)]).astype(np.int64)
            if points else np.zeros(0, np.int64),
            np.array([BONE_INDEX[name] for name, _ in bones], np.int64),
            np.array([LABEL_SLOT[label] for _, label in bones], np.int64),
            np.array([i for i, joints, _, _ in targets for _ in joints], np.int64),
            np.array([j for _, joints, _, _ in targets for j in joints], np.int64),
            np.concatenate([xy for _, _, xy, _ in targets]) if targets else np.zeros((0, 2)),
            np.concatenate([c for _, _, _, c in targets]) if targets else np.zeros(0),
            *twist_arrays(stage),
            np.array([settings.enclosure_weight, settings.outline_weight, settings.inside_weight, settings.outline_scale,
                      settings.outline_gate, settings.boundary_weight, settings.keypoint_weight, settings.keypoint_scale,
                      settings.smoothness_weight if priors else 0.0, settings.limit_weight if priors else 0.0]))

    def outline_assignment(self, stage, parameters, views, frame, nearest=None):
        """Per view, the outline points (M, 2) [px] that the stage's capsules explain in the pose
        `parameters`: those nearer to one of them than to any other capsule, within outline_gate (None for
        a view without an outline). Fixed for the stage's search, so that the torso is not pulled to
        explain the limbs, which are still where they were in the last frame. frame: the views'
        compiled.FramePack; nearest: outline_nearest of the same pose and views, when the caller assigns
        several stages from it."""
        nearest = self.outline_nearest(parameters, frame) if nearest is None else nearest
        mine = STAGE_CAPSULE_MASK[stage]
        return [None if view.outline is None else view.outline.points[mine[capsule] & within]
                for view, (capsule, within) in zip(views, nearest)]

    def outline_nearest(self, parameters, frame):
        """Per view of `frame` (compiled.FramePack), for each outline point, the index (into BONES) of the
        capsule nearest to it in the pose `parameters` (29,) and whether it lies within outline_gate of it:
        (N,) int, (N,) bool ((None, None) for a view without an outline); compiled.outline_nearest."""
        nearest, within = outline_nearest(np.asarray(parameters, float), self.bone_lengths, CAPSULE_RADIUS,
                                          CAPSULE_TERMINAL, self.settings.outline_gate, frame.K, frame.R, frame.t,
                                          frame.D, frame.outline_x, frame.outline_y, frame.outline_range)
        return [(nearest[first:last], within[first:last]) if present else (None, None)
                for present, (first, last) in zip(frame.has_outline, frame.outline_range)]

    def explained_cost(self, stage, parameters, views, frame):
        """A limb stage's searches from different starts, each with its own outline assignment, compared on one
        footing: the stage's cost at `parameters` (29,) with the outline assigned from that pose, its joint
        limits, and every outline point of the views that no capsule explains (beyond outline_gate of all)
        at the Cauchy cost of a residual of outline_gate, as outline_cost caps it. So a folded arm that
        leaves a raised arm's outline unexplained costs more than the raised arm explaining it; within one
        assignment (the stage's own objective) such points are left out and cost nothing."""
        settings = self.settings
        nearest = self.outline_nearest(parameters, frame)
        unexplained = sum(int(np.count_nonzero(~within)) for _, within in nearest if within is not None)
        capped = settings.outline_weight * OUTLINE_STEP * cauchy_loss(settings.outline_gate, settings.outline_scale)
        return self.posed_cost(stage, parameters, views, frame, nearest) + capped * unexplained

    def posed_cost(self, stage, parameters, views, frame, nearest):
        """The stage's objective at the pose `parameters` (29,) with the outline assigned from that pose
        (`nearest`: its outline_nearest), without the smoothness prior, plus its joint limits (limit_cost)."""
        assigned = self.outline_assignment(stage, parameters, views, frame, nearest)
        return self.compiled_cost(stage, parameters, views, assigned, frame, limits=True)[0]

    def limit_cost(self, stage, parameters, frames=None):
        """The stage's joint limits at `parameters` (29,): limit_weight × the squared excess [rad²] of its
        parameters beyond JOINT_LIMITS and of its limb's twist beyond TWIST_LIMITS (twist_excess), as the
        search's prior adds them (the reference of compiled.stage_objective's limit term). frames: the
        pose's forward_kinematics bone frames, if the caller has them."""
        excess = 0.0
        for name, index in zip(STAGE_PARAMETERS[stage], stage_indices(stage)):
            low, high = JOINT_LIMITS.get(name, (-np.inf, np.inf))
            excess += (max(low - parameters[index], 0.0) + max(parameters[index] - high, 0.0)) ** 2
        if stage in TWIST_LIMITS:
            if frames is None:
                frames = forward_kinematics(parameters, self.lengths)[1]
            excess += twist_excess(stage, frames, parameters)
        return self.settings.limit_weight * excess

    def stage_cost(self, stage, parameters, views, assigned=None):
        """The stage's objective (module docstring) and the indices of the views that contributed;
        assigned: per view the outline points the stage explains (None: no outline term)."""
        settings = self.settings
        projections = [view.camera.project(forward_kinematics(parameters, self.lengths)[0]) for view in views]  # once per camera
        total, used = 0.0, set()
        mine = STAGE_CAPSULE_INDEX[stage]
        points, capsules = [], []   # the outline points of all views at once: one vectorised evaluation
        for index, (view, (pixels, depth)) in enumerate(zip(views, projections)):
            if assigned is None or assigned[index] is None or depth[CAPSULE_ENDS[mine]].min() <= 0:
                continue
            starts, ends, radii = projected_capsules(view, pixels, depth, mine)
            total += settings.inside_weight * inside_cost(starts, ends, view.outline)
            points.append(assigned[index])
            capsules.append(np.broadcast_to(np.column_stack([starts, ends, radii]), (len(assigned[index]), len(mine), 5)))
            used.add(index)
        if points:
            capsules = np.concatenate(capsules)
            total += settings.outline_weight * outline_cost(
                np.concatenate(points), capsules[..., 0:2], capsules[..., 2:4], capsules[..., 4],
                CAPSULE_TERMINAL[mine], settings.outline_scale, settings.outline_gate)
        for bone_name, label in STAGE_BONES[stage]:
            bone = BONES[BONE_INDEX[bone_name]]
            ends = (JOINT_INDEX[bone.parent_joint], JOINT_INDEX[bone.joint])
            segments = [(pixels[ends[0]], pixels[ends[1]]) if depth[list(ends)].min() > 0 and view.distances else None
                        for view, (pixels, depth) in zip(views, projections)]
            cost, cameras = limb_cost(segments, [view.distances for view in views], label,
                                      enclosure_weight=settings.enclosure_weight)
            total += settings.boundary_weight * cost
            used.update(cameras)
        for index, joint_indices, observed, weights in self.keypoint_targets(stage, views):
            errors = np.linalg.norm(projections[index][0][joint_indices] - observed, axis=1)
            total += settings.keypoint_weight * settings.keypoint_scale * float(
                weights @ np.log1p(errors / settings.keypoint_scale))
            used.add(index)
        return total, used

    @staticmethod
    def keypoint_targets(stage, views):
        """[(view index, joint indices (K,), keypoints (K, 2) [px], weights (K,))] of the stage's keypoints in
        each view that has some. A keypoint's weight is its confidence, times (views / views that have it)
        when two views or more have it: a joint's keypoints weigh as much against the outline whether every
        view sees it or a view's was left out (initialisation.consistent_views: with one camera's elbows and
        wrists 200 px off and left out, the rendered walk of test_recovery was fitted 11-13 % worse than with
        them right, 4-7 % with the weights made up). One view's alone keeps its confidence: nothing checks it."""
        targets = []
        views_with = {n: sum(n in view.keypoints for view in views) for n in STAGE_KEYPOINTS[stage]}
        for index, view in enumerate(views):
            names = [n for n in STAGE_KEYPOINTS[stage] if n in view.keypoints]
            if names:
                values = np.array([view.keypoints[n] for n in names], dtype=float)
                made_up = np.array([len(views) / views_with[n] if views_with[n] >= 2 else 1.0 for n in names])
                targets.append((index, [JOINT_INDEX[KEYPOINT_JOINT.get(n, n)] for n in names], values[:, :2],
                                values[:, 2] * made_up))
        return targets
