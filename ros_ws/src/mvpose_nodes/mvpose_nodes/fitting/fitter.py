"""Fitting the 29-DOF skeleton to the features of several calibrated views (paper 000 Sec. 4–6).

Per frame: start from the previous frame's pose, moved on at the pelvis's velocity, or, on the first
frame and after a jump in time, from an initialisation (the 2D keypoints triangulated across views,
turned into angles by paper 004's method, bone lengths from the template scaled to the estimated
height, the legs' length measured); then six Nelder–Mead searches (Sec. 5.1): torso, head and neck,
left arm, right arm, left leg, right leg, each over its own parameters with the rest fixed, each
minimising its own objective:
  - Eq. 4–5 for every bone that has labelled boundaries (torso, head, thighs, shins): the projected
    bone midway between its part's two sides, summed over the cameras that see them; plus the
    "stay on the part" term of objective._camera_cost, so that a bone cannot rest equidistant from
    both sides far off the part (weight ENCLOSURE_WEIGHT);
  - the outline term (objective.outline_cost, beyond the paper): the stage's bones as capsules
    explaining the part of each camera's outline that lies nearest to them, and staying inside the
    silhouette. It sees what the labelled parts cannot: the arms, and the torso's turn about the spine
    from the widths of shoulders and hips (halving the error on the synthetic walk);
  - the reprojection distance of the joints that the features located in 2D (root, neck, head,
    elbows, wrists, knees, ankles), robust (KEYPOINT_SCALE) and weighted by confidence (the
    paper uses these keypoints for initialisation; the arms have no labelled contour, so for them
    the skin keypoints are evidence too, as in paper 000 Sec. 3.2).
Left and right: a single view often cannot tell them apart (features.py). The triangulated pairs are
labelled by LimbTracks (continuity, and the direction of travel while walking), then each camera's
left/right labels of legs and arms are swapped where that labelled pose projects better onto the
swapped ones.
Nelder–Mead (Lagarias et al. 1998): SciPy's with its standard coefficients, which are the paper's
(Eq. 7: ρ = 1, χ = 2, γ = 0.5, σ = 0.5; non-adaptive), stopped by the simplex size (xatol) alone.
"""
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize

from mvpose_nodes.vision.features import FRONT_SKIN_FRACTION
from mvpose_nodes.body.model import (LABEL_HEAD, LABEL_LEFT_LEG, LABEL_RIGHT_LEG, LABEL_TORSO, PARAMETER_NAMES,
                                     STAGE_NAMES)
from mvpose_nodes.body.kinematics import BONE_INDEX, BONES, J, P, bone_lengths, forward_kinematics, inverse_kinematics
from mvpose_nodes.fitting.objective import (CAPSULE_RADII, TERMINAL_BONES, boundary_distances, capsule_residuals, inside_cost,
                                    limb_cost, outline_cost, outline_of)
from mvpose_nodes.body.triangulation import best_assignment, triangulate

ENCLOSURE_WEIGHT = 1.0
OUTLINE_WEIGHT = 1 / 9   # per px² of the outline objective's Cauchy cost, per contour pixel
INSIDE_WEIGHT = 1.0      # per px² of a bone's sample point outside the silhouette
OUTLINE_SCALE = 10.0     # [px] of the Cauchy loss of an outline point's residual
OUTLINE_GATE = 20.0      # [px] outline points farther than this from every capsule are left out of a stage
BOUNDARY_WEIGHT = 0.1    # per pixel of Eq. 4 (a sum over N = 100 points), against KEYPOINT_WEIGHT per keypoint pixel
KEYPOINT_WEIGHT = 20.0   # a pixel of keypoint error costs as much as 20 px of summed boundary distance (N = 100)
KEYPOINT_SCALE = 30.0    # [px] keypoint errors e cost KEYPOINT_SCALE·log(1 + e/KEYPOINT_SCALE): about e when small,
                         # growing ever slower when large, so a wrong detection pulls little but always leads back
SIMPLEX_TOLERANCE = 1e-2  # [m or rad] stop when the simplex is this small (1 cm, 0.6°)
STEP = {'position': 0.05, 'angle': 0.15}  # initial simplex sizes [m], [rad]
MAX_EVALUATIONS_PER_PARAMETER = 150
TIME_JUMP = 0.5          # [s] a larger gap (or going back in time) re-initialises
ANKLE_HEIGHT = 0.039     # of the stature (the template's ankle)
OUTLIER_RMS = 12.0       # [px] a triangulation worse than this tries leaving one view out
LENGTH_TRUST = 0.35      # measured bone lengths within this share of the template's are believed
SMOOTHNESS_WEIGHT = 20.0  # cost of moving a parameter by one STEP from the previous frame's value (squared)
JOINT_LIMITS = {'left_shin_rx': (-2.6, 0.05), 'right_shin_rx': (-2.6, 0.05),     # knees bend backwards,
                'left_forearm_rx': (-0.05, 2.6), 'right_forearm_rx': (-0.05, 2.6),  # elbows forwards [rad];
                # the clavicles move little, and no keypoint sees the shoulders: keep them near the rest
                **{f'{side}_clavicle_{axis}': (-0.5, 0.5) for side in ('left', 'right') for axis in ('ry', 'rz')}}
LIMIT_WEIGHT = 1e4        # per rad² beyond a joint limit
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
CAPSULE_ENDS = np.array([(J[bone.parent_joint], J[bone.joint]) for bone in BONES])   # (14, 2) joint indices
CAPSULE_RADIUS = np.array([CAPSULE_RADII[bone.name.replace('left_', '').replace('right_', '')] for bone in BONES])
CAPSULE_TERMINAL = np.array([bone.name.endswith(TERMINAL_BONES) for bone in BONES])
STAGE_CAPSULE_INDEX = {stage: np.array([BONE_INDEX[name] for name in names]) for stage, names in STAGE_CAPSULES.items()}
SWAPPABLE = {'legs': ('knee', 'ankle'), 'arms': ('elbow', 'wrist')}
FACE_EVIDENCE = 0.2      # the summed (frontness − FRONT_SKIN_FRACTION) towards the cameras needed to trust the face
TRAVEL_YAW_LIMIT = np.radians(45)  # a walking torso turned further from its direction of travel is turned back
WALKING_SPEED = 0.4      # [m/s] faster than this, the pelvis's direction of travel is the person's forward
WALKING_BASELINE = 0.4   # [s] over which that direction is measured
CONTINUITY_SCALE = 0.5   # [m] turns a difference of squared distances [m²] into evidence [m] (LimbTracks)


@dataclass
class View:
    """One camera's evidence for one frame: its Camera, the boundary distance maps of its labelled
    contour (objective.BoundaryDistances, or None), its 2D keypoints {name: (x, y, confidence)}, how
    much of the face it sees (features.Features.frontness; None if unknown) and its outline
    (objective.Outline, or None)."""
    camera: object
    distances: object
    keypoints: dict
    frontness: float = None
    outline: object = None


@dataclass
class StageResult:
    name: str
    cost: float
    evaluations: int
    cameras: list
    fitted: bool


@dataclass
class Fit:
    joints: np.ndarray           # (15, 3) [m]
    parameters: np.ndarray       # (29,)
    stages: list = field(default_factory=list)
    initialised: bool = False
    seconds: float = 0.0


class SkeletonFitter:
    """Frame-by-frame fitting: `fit(stamp_s, views) -> Fit`, keeping the pose and the person's size."""

    def __init__(self):
        self.parameters = None
        self.lengths = None
        self.last_stamp = None
        self.tracks = LimbTracks()
        self._targets = {}
        self.turns = 0   # times the torso was turned to face the direction of travel (facing_travel)

    def fit(self, stamp, views):
        started = time.perf_counter()
        self._targets = {}   # keypoint_targets of this frame
        jump = self.last_stamp is None or stamp < self.last_stamp or stamp - self.last_stamp > TIME_JUMP
        self.last_stamp = stamp
        initialised = False
        if self.parameters is None or jump:
            start = self.initial_parameters(views)
            if start is None:
                raise ValueError('too few views with keypoints to initialise (need root, neck and head in 2 views)')
            self.parameters, initialised = start, True
            self.tracks.restart()
        parameters = self.parameters.copy()
        predicted = None if initialised else self.tracks.predicted(stamp)
        if predicted is not None:  # the body moves on at its speed (5 cm a frame walking): start, and
            # centre the smoothness prior, where it will be, not where it was
            position = [P[name] for name in ('torso_x', 'torso_y', 'torso_z')]
            parameters[position] += predicted[J['pelvis']] - self.tracks.history[-1][1][J['pelvis']]
        # Paper 000 Sec. 5.3: local minima are avoided by starting from the previous frame's pose or
        # from the frame's own features; each stage starts from whichever of the two fits better.
        found = None if initialised else self.triangulated_joints(views)
        if not initialised:
            parameters = self.facing_travel(parameters)
        reference, _ = forward_kinematics(parameters, self.lengths)
        if found is not None:
            self.tracks.label(stamp, found)
            for name, position in found.items():
                reference[J[name]] = position
        candidate = None
        oriented = [self.oriented_view(view, reference) for view in views]
        results = []
        for stage in STAGE_NAMES:
            if found is not None and stage != 'torso' and candidate is None:
                # The limbs' triangulated joints, as angles relative to the fitted torso.
                hybrid, _ = forward_kinematics(parameters, self.lengths)
                for name, position in found.items():
                    if name not in ('pelvis', 'neck'):
                        hybrid[J[name]] = position
                candidate = inverse_kinematics(hybrid)
            assigned = self.outline_assignment(stage, parameters, oriented)
            if found is not None and stage != 'torso':
                indices = [P[name] for name in STAGE_PARAMETERS[stage]]
                alternative = parameters.copy()
                alternative[indices] = candidate[indices]
                if (self.stage_cost(stage, alternative, oriented, assigned)[0]
                        < self.stage_cost(stage, parameters, oriented, assigned)[0]):
                    parameters = alternative
            parameters, result = self.search(stage, parameters, oriented, assigned)
            results.append(result)
        self.parameters = parameters
        joints, _ = forward_kinematics(parameters, self.lengths)
        self.tracks.append(stamp, joints)
        return Fit(joints, parameters, results, initialised, time.perf_counter() - started)

    def facing_travel(self, parameters):
        """The parameters with the torso turned about the vertical to face the direction of travel, if
        the person walks and the torso's right is more than TRAVEL_YAW_LIMIT away from the walk's. The
        outline and the midlines look much the same from the front and from the back, and a poor
        initial guess (no face seen, the limbs' pairs not yet labelled) would otherwise stay; people
        walk forwards. Rz is the outermost of the torso's Euler angles: the turn adds to torso_rz."""
        right = self.tracks.walking_right()
        if right is None:
            return parameters
        joints, _ = forward_kinematics(parameters, self.lengths)
        torso_right = joints[J['right_hip']] - joints[J['left_hip']]
        turn = np.arctan2(right[1], right[0]) - np.arctan2(torso_right[1], torso_right[0])
        turn = (turn + np.pi) % (2 * np.pi) - np.pi
        if abs(turn) <= TRAVEL_YAW_LIMIT:
            return parameters
        turned = parameters.copy()
        turned[P['torso_rz']] = (turned[P['torso_rz']] + turn + np.pi) % (2 * np.pi) - np.pi
        self.turns += 1
        return turned

    def initial_parameters(self, views):
        """Angles from triangulated keypoints (paper 000 Sec. 3.1 and 6; paper 004), or None."""
        joints = self.triangulated_joints(views)
        if joints is None:
            return None
        right = self.facing_right(views, joints)
        if right is not None:  # which of each pair is the person's left: the face's side tells
            for limb in ('knee', 'ankle', 'elbow', 'wrist'):
                left, right_name = f'left_{limb}', f'right_{limb}'
                if left in joints and right_name in joints and np.dot(joints[left] - joints[right_name], right) > 0:
                    joints[left], joints[right_name] = joints[right_name], joints[left]
        if self.lengths is None:
            self.lengths = self.person_lengths(joints)
        return inverse_kinematics(self.completed_joints(joints))

    def triangulated_joints(self, views):
        """{joint: (3,) [m]} triangulated from the views' keypoints, or None without root, neck and head in
        two views. Each left/right pair is assigned consistently across the views, but which of the two
        is the person's left is not decided here (initial_parameters and LimbTracks do)."""
        cameras = [view.camera for view in views]

        def pixels(name):
            return np.array([view.keypoints.get(name, (np.nan, np.nan, 0))[:2] for view in views], float)

        def weights(name):
            return np.array([view.keypoints.get(name, (0, 0, 0.0))[2] for view in views], float)
        joints = {}
        for name in ('root', 'neck', 'head'):
            found = robust_triangulate(cameras, pixels(name), weights(name))
            if found is None:
                return None
            joints[KEYPOINT_JOINT.get(name, name)] = found
        for limb in ('knee', 'ankle', 'elbow', 'wrist'):
            left_pixels, right_pixels = pixels(f'left_{limb}'), pixels(f'right_{limb}')
            pair_weights = np.column_stack([weights(f'left_{limb}'), weights(f'right_{limb}')])
            pair = best_assignment(cameras, left_pixels, right_pixels, pair_weights)
            if pair is None:
                continue
            swaps = pair[2]
            observed = np.where(swaps[:, None], right_pixels, left_pixels), np.where(swaps[:, None], left_pixels, right_pixels)
            observed_weights = np.where(swaps, pair_weights[:, 1], pair_weights[:, 0]), np.where(swaps, pair_weights[:, 0], pair_weights[:, 1])
            left, right_point = (robust_triangulate(cameras, p, w) for p, w in zip(observed, observed_weights))
            if left is None or right_point is None:
                continue
            joints[f'left_{limb}'], joints[f'right_{limb}'] = left, right_point
        return joints

    @staticmethod
    def person_lengths(joints):
        """Bone lengths of the person, on the first frame: the template scaled to the height (head above
        the ankles), then the legs and the head measured (the template's proportions are an average
        person's; a measurement within ±LENGTH_TRUST of the template's value is believed).
        The legs: a standing or stance leg is nearly straight, so the longer pelvis–ankle distance is
        about √(hip² + (thigh + shin)²); the knee keypoints are too rough to split it (features.py
        takes them from a band of the silhouette), so the template's thigh : shin proportion is kept."""
        ankles = [joints[n][2] for n in ('left_ankle', 'right_ankle') if n in joints]
        height = joints['head'][2] - (min(ankles) - ANKLE_HEIGHT * 1.75 if ankles else 0.0)
        lengths = bone_lengths(float(np.clip(height / (1 - ANKLE_HEIGHT) if ankles else height, 1.2, 2.2)))
        reach = max((np.linalg.norm(joints[n] - joints['pelvis']) for n in ('left_ankle', 'right_ankle') if n in joints),
                    default=0.0)
        if reach > lengths['hip']:
            leg = np.sqrt(reach ** 2 - lengths['hip'] ** 2)
            scale = leg / (lengths['thigh'] + lengths['shin'])
            if abs(scale - 1) < LENGTH_TRUST:
                lengths['thigh'] *= scale
                lengths['shin'] *= scale
        head = np.linalg.norm(joints['head'] - joints['neck'])
        if abs(head / lengths['head'] - 1) < LENGTH_TRUST:
            lengths['head'] = float(head)
        return lengths

    @staticmethod
    def facing_right(views, joints):
        """The person's right (unit, horizontal) from where the face is seen: the cameras that see the
        face are in front of the person (paper 000's views cannot tell left from right otherwise).
        None when no view says (all side views)."""
        pelvis = joints['pelvis']
        forward = np.zeros(3)
        for view in views:
            if view.frontness is None:
                continue
            towards = view.camera.center - pelvis
            towards[2] = 0.0
            forward += (view.frontness - FRONT_SKIN_FRACTION) * towards / np.linalg.norm(towards)
        if np.linalg.norm(forward) < FACE_EVIDENCE:
            return None
        return np.cross(forward / np.linalg.norm(forward), [0.0, 0.0, 1.0])

    def completed_joints(self, found):
        """All 15 joints for inverse kinematics: the triangulated ones, the rest from the template."""
        up = found['neck'] - found['pelvis']
        up /= np.linalg.norm(up)
        sideways = [found[f'right_{n}'] - found[f'left_{n}'] for n in ('knee', 'ankle', 'elbow', 'wrist')
                    if f'left_{n}' in found]
        right = np.sum(sideways, axis=0) if sideways else np.cross([0.0, 0.0, 1.0], up) + [1e-3, 0, 0]
        right -= np.dot(right, up) * up
        right /= np.linalg.norm(right)
        rest, _ = forward_kinematics(np.zeros(len(PARAMETER_NAMES)), self.lengths)
        frame = np.column_stack([right, np.cross(up, right), up])
        joints = found['pelvis'] + (rest - rest[J['pelvis']]) @ frame.T
        for name, position in found.items():
            joints[J[name]] = position
        joints[J['left_hip']] = found['pelvis'] - self.lengths['hip'] * right
        joints[J['right_hip']] = found['pelvis'] + self.lengths['hip'] * right
        joints[J['left_shoulder']] = found['neck'] - self.lengths['clavicle'] * right
        joints[J['right_shoulder']] = found['neck'] + self.lengths['clavicle'] * right
        return joints

    def oriented_view(self, view, joints):
        """The view with its left/right labels of legs and arms swapped where `joints` (15, 3), the
        frame's reference pose, say they are."""
        keypoints = dict(view.keypoints)
        distances = view.distances
        for group, names in SWAPPABLE.items():
            # The group's keypoints (a whole pair, or one side only when a limb is hidden) against the
            # reference's projected joints of the same side and of the other.
            seen = [f'{side}_{n}' for n in names for side in ('left', 'right') if f'{side}_{n}' in keypoints]
            if not seen:
                continue
            other_side = [name.replace('left_', 'RIGHT_').replace('right_', 'left_').replace('RIGHT_', 'right_')
                          for name in seen]
            projected, _ = view.camera.project(joints[[J[name] for name in seen + other_side]])
            observed = np.array([keypoints[name][:2] for name in seen])
            straight = np.linalg.norm(projected[:len(seen)] - observed, axis=1).sum()
            if np.linalg.norm(projected[len(seen):] - observed, axis=1).sum() < straight:
                for name in names:
                    left, right = f'left_{name}', f'right_{name}'
                    for mine, other in ((left, right), (right, left)):
                        if other in view.keypoints:
                            keypoints[mine] = view.keypoints[other]
                        else:
                            keypoints.pop(mine, None)
                if group == 'legs' and distances is not None:
                    distances = distances.swapped(LABEL_LEFT_LEG, LABEL_RIGHT_LEG)
        return View(view.camera, distances, keypoints, view.frontness, view.outline)

    def search(self, stage, parameters, views, assigned):
        """One Nelder–Mead stage over STAGE_PARAMETERS[stage]; (new parameters, StageResult). assigned:
        per view the outline points the stage explains (outline_assignment)."""
        indices = [P[name] for name in STAGE_PARAMETERS[stage]]
        steps = np.array([STEP['position'] if name.endswith(('_x', '_y', '_z')) else STEP['angle']
                          for name in STAGE_PARAMETERS[stage]])
        if not self.has_evidence(stage, views, assigned):
            return parameters, StageResult(stage, 0.0, 0, [], False)
        trial = parameters.copy()
        start = parameters[indices]
        limits = [(i, JOINT_LIMITS[name]) for i, name in enumerate(STAGE_PARAMETERS[stage]) if name in JOINT_LIMITS]

        def cost(values):
            trial[indices] = values
            total, _ = self.stage_cost(stage, trial, views, assigned)
            # Priors: the pose changes little between frames at 25 fps, and joints have limits.
            total += SMOOTHNESS_WEIGHT * np.sum(((values - start) / steps) ** 2)
            for i, (low, high) in limits:
                total += LIMIT_WEIGHT * (max(low - values[i], 0.0) + max(values[i] - high, 0.0)) ** 2
            return total
        simplex = np.vstack([start, start + np.diag(steps)])
        result = minimize(cost, start, method='Nelder-Mead', options={
            'initial_simplex': simplex, 'xatol': SIMPLEX_TOLERANCE, 'fatol': np.inf, 'adaptive': False,
            'maxfev': MAX_EVALUATIONS_PER_PARAMETER * len(indices)})
        fitted = parameters.copy()
        fitted[indices] = result.x
        final, used = self.stage_cost(stage, fitted, views, assigned)
        return fitted, StageResult(stage, float(final), int(result.nfev),
                                   sorted(views[i].camera.number for i in used), True)

    @staticmethod
    def has_evidence(stage, views, assigned):
        """Whether any view has the stage's keypoints, labelled boundaries, or outline points."""
        return any(name in view.keypoints for view in views for name in STAGE_KEYPOINTS[stage]) or any(
            view.distances is not None and label in view.distances.widths
            for view in views for _, label in STAGE_BONES[stage]) or any(
            points is not None and len(points) for points in assigned)

    @staticmethod
    def capsules(view, pixels, depth, bones=slice(None)):
        """The projected capsules of `bones` (indices into BONES; default all) in one view: starts, ends
        (B, 2) [px], radii (B,) [px] (CAPSULE_RADIUS at the bone's mean depth), from the projected joints
        pixels (15, 2), depth (15,)."""
        ends = CAPSULE_ENDS[bones]
        mean_depth = np.maximum(0.5 * (depth[ends[:, 0]] + depth[ends[:, 1]]), 0.1)
        return pixels[ends[:, 0]], pixels[ends[:, 1]], CAPSULE_RADIUS[bones] * view.camera.K[0, 0] / mean_depth

    def outline_assignment(self, stage, parameters, views):
        """Per view, the outline points (M, 2) [px] that the stage's capsules explain in the pose
        `parameters`: those nearer to one of them than to any other capsule, within OUTLINE_GATE (None for
        a view without an outline). Fixed for the stage's search, so that the torso is not pulled to
        explain the limbs, which are still where they were in the last frame."""
        joints, _ = forward_kinematics(parameters, self.lengths)
        mine = STAGE_CAPSULE_INDEX[stage]
        assigned = []
        for view in views:
            if view.outline is None:
                assigned.append(None)
                continue
            residuals = capsule_residuals(view.outline.points, *self.capsules(view, *view.camera.project(joints)),
                                          CAPSULE_TERMINAL)
            nearest = residuals.argmin(axis=1)
            keep = np.isin(nearest, mine) & (np.abs(residuals[np.arange(len(nearest)), nearest]) < OUTLINE_GATE)
            assigned.append(view.outline.points[keep])
        return assigned

    def stage_cost(self, stage, parameters, views, assigned=None):
        """The stage's objective (module docstring) and the indices of the views that contributed;
        assigned: per view the outline points the stage explains (None: no outline term)."""
        joints, _ = forward_kinematics(parameters, self.lengths)
        projections = [view.camera.project(joints) for view in views]  # every joint, once per camera
        total, used = 0.0, set()
        mine = STAGE_CAPSULE_INDEX[stage]
        points, capsules = [], []   # the outline points of all views at once: one vectorised evaluation
        for index, (view, (pixels, depth)) in enumerate(zip(views, projections)):
            if assigned is None or assigned[index] is None or depth[CAPSULE_ENDS[mine]].min() <= 0:
                continue
            starts, ends, radii = self.capsules(view, pixels, depth, mine)
            total += INSIDE_WEIGHT * inside_cost(starts, ends, view.outline)
            points.append(assigned[index])
            capsules.append(np.broadcast_to(np.column_stack([starts, ends, radii]), (len(assigned[index]), len(mine), 5)))
            used.add(index)
        if points:
            capsules = np.concatenate(capsules)
            total += OUTLINE_WEIGHT * outline_cost(np.concatenate(points), capsules[..., 0:2], capsules[..., 2:4],
                                                   capsules[..., 4], CAPSULE_TERMINAL[mine], OUTLINE_SCALE, OUTLINE_GATE)
        for bone_name, label in STAGE_BONES[stage]:
            bone = BONES[BONE_INDEX[bone_name]]
            ends = (J[bone.parent_joint], J[bone.joint])
            segments = [(pixels[ends[0]], pixels[ends[1]]) if depth[list(ends)].min() > 0 and view.distances else None
                        for view, (pixels, depth) in zip(views, projections)]
            cost, cameras = limb_cost(segments, [view.distances for view in views], label,
                                      enclosure_weight=ENCLOSURE_WEIGHT)
            total += BOUNDARY_WEIGHT * cost
            used.update(cameras)
        for index, joint_indices, observed, weights in self.keypoint_targets(stage, views):
            errors = np.linalg.norm(projections[index][0][joint_indices] - observed, axis=1)
            total += KEYPOINT_WEIGHT * KEYPOINT_SCALE * float(weights @ np.log1p(errors / KEYPOINT_SCALE))
            used.add(index)
        return total, used

    def keypoint_targets(self, stage, views):
        """[(view index, joint indices (K,), keypoints (K, 2) [px], confidences (K,))] of the stage's
        keypoints in each view that has some; worked out once per stage and frame (`views` is the
        frame's list), since the search evaluates the cost hundreds of times."""
        key = (stage, id(views))
        if key not in self._targets:
            self._targets[key] = []
            for index, view in enumerate(views):
                names = [n for n in STAGE_KEYPOINTS[stage] if n in view.keypoints]
                if names:
                    values = np.array([view.keypoints[n] for n in names], dtype=float)
                    self._targets[key].append((index, [J[KEYPOINT_JOINT.get(n, n)] for n in names],
                                               values[:, :2], values[:, 2]))
        return self._targets[key]


class LimbTracks:
    """Which of each triangulated left/right pair (knees, ankles, elbows, wrists) is the person's left.

    Single views cannot tell (features.py), and the face's direction is too rough to (20° off moves a
    60 cm stride 20 cm sideways). Two cues decide, frame by frame and pair by pair:
    - continuity: the labelling whose points lie nearer the positions predicted from the last two fitted
      poses at constant velocity; decisive while the two limbs are far apart (mid-stride), weak when
      they pass each other;
    - sides: while the person walks (pelvis faster than WALKING_SPEED over WALKING_BASELINE), the
      direction of travel is forward and the left limb lies to its left; knees and ankles are 5–20 cm
      apart sideways all through a walk (CMU 07_01), elbows more.
    The evidence of each, in metres: continuity (d(a, p_r)² + d(b, p_l)² − d(a, p_l)² − d(b, p_r)²) /
    CONTINUITY_SCALE, the sides' the lateral offset of the "left" point to the right; the labelling is
    exchanged when their sum says so. Until the person is first seen walking (after a (re)start), the
    labels come from the face (SkeletonFitter.initial_parameters) or are a guess: continuity would keep
    a wrong guess, so on that first walking frame each group (legs, arms) is labelled by its mean lateral
    offset over the remembered fits alone. Someone walking backwards would be labelled mirrored.
    """

    def __init__(self):
        self.history = []   # [(stamp [s], joints (15, 3) [m])] of the fits within WALKING_BASELINE
        self.anchored = False  # whether the sides have been seen while walking since the (re)start
        self.exchanges = 0  # exchanged pairs so far (for diagnostics)

    def restart(self):
        self.history.clear()
        self.anchored = False

    def append(self, stamp, joints):
        self.history = [(t, p) for t, p in self.history if stamp - t <= WALKING_BASELINE] + [(stamp, joints.copy())]

    def predicted(self, stamp):
        """Joints (15, 3) expected at `stamp` (constant velocity from the last two fits), or None."""
        if not self.history:
            return None
        t1, p1 = self.history[-1]
        if len(self.history) < 2 or t1 <= self.history[-2][0]:
            return p1
        t0, p0 = self.history[-2]
        return p1 + (p1 - p0) * (stamp - t1) / (t1 - t0)

    def walking_right(self):
        """The person's right (3,) unit horizontal, from the direction of travel; None when not walking."""
        if len(self.history) < 2 or self.history[-1][0] - self.history[0][0] < WALKING_BASELINE / 4:
            return None
        (t0, p0), (t1, p1) = self.history[0], self.history[-1]
        velocity = (p1[J['pelvis']] - p0[J['pelvis']]) / (t1 - t0)
        velocity[2] = 0.0
        speed = np.linalg.norm(velocity)
        return np.cross(velocity / speed, [0.0, 0.0, 1.0]) if speed > WALKING_SPEED else None

    def label(self, stamp, found):
        """Exchange, in `found` ({joint: (3,)} triangulated), the pairs that belong the other way round."""
        right = self.walking_right()
        if right is not None and not self.anchored:
            self.anchor(right, found)
        predicted = self.predicted(stamp)
        if predicted is None:
            return
        for name in ('knee', 'ankle', 'elbow', 'wrist'):
            left, right_name = f'left_{name}', f'right_{name}'
            if left not in found or right_name not in found:
                continue
            a, b = found[left], found[right_name]
            p_left, p_right = predicted[J[left]], predicted[J[right_name]]
            evidence = (np.sum((a - p_right) ** 2) + np.sum((b - p_left) ** 2)
                        - np.sum((a - p_left) ** 2) - np.sum((b - p_right) ** 2)) / CONTINUITY_SCALE
            if right is not None:
                evidence -= np.dot(a - b, right)
            if evidence < 0:
                _exchange(found, name)
                self.exchanges += 1

    def anchor(self, right, found):
        """Label each group by its mean lateral offset over the history and `found` (see the class)."""
        self.anchored = True
        for names in SWAPPABLE.values():
            offsets = [np.dot(joints[J[f'left_{n}']] - joints[J[f'right_{n}']], right)
                       for _, joints in self.history for n in names]
            offsets += [np.dot(found[f'left_{n}'] - found[f'right_{n}'], right) for n in names
                        if f'left_{n}' in found and f'right_{n}' in found]
            if np.mean(offsets) > 0:
                for name in names:
                    _exchange(found, name)
                    for _, joints in self.history:
                        joints[[J[f'left_{name}'], J[f'right_{name}']]] = joints[[J[f'right_{name}'], J[f'left_{name}']]]
                self.exchanges += 1


def _exchange(joints, name):
    """Swap joints['left_' + name] and joints['right_' + name] (when both are there)."""
    left, right = f'left_{name}', f'right_{name}'
    if left in joints and right in joints:
        joints[left], joints[right] = joints[right], joints[left]


def robust_triangulate(cameras, pixels, weights):
    """A DLT triangulation (triangulation.triangulate) that leaves out the one view that disagrees: with
    three or more views and an RMS reprojection error above OUTLIER_RMS, the subset without the view
    whose removal lowers the error most is used if it brings the error under OUTLIER_RMS. (point, or None)"""
    found = triangulate(cameras, pixels, weights)
    if found is None:
        return None
    point, rms = found
    usable = [i for i in range(len(cameras)) if np.all(np.isfinite(pixels[i])) and weights[i] > 0]
    if rms > OUTLIER_RMS and len(usable) >= 3:
        trials = []
        for left_out in usable:
            reduced = weights.copy()
            reduced[left_out] = 0.0
            trial = triangulate(cameras, pixels, reduced)
            if trial is not None:
                trials.append(trial)
        best = min(trials, key=lambda t: t[1], default=None)
        if best is not None and best[1] < OUTLIER_RMS:
            point = best[0]
    return point


def view_from_features(camera, keypoints, contour, frontness=None):
    """A View of one camera from its features: keypoints {name: (x, y, confidence)} (the visible ones),
    its ContourLabels (or None) and its frontness."""
    distances = outline = None
    if contour is not None and len(contour.points):
        distances = boundary_distances(contour, (camera.width, camera.height))
        outline = outline_of(contour.points)
    return View(camera, distances, keypoints, frontness, outline)


def crossed_is_nearer(left, right, to_left, to_right):
    """Whether left/right points ((d,) or (N, d) for N pairs) lie nearer to others the other way round:
    the summed distances, left to right and right to left, against left to left and right to right."""
    def distance(a, b):
        return np.linalg.norm(np.subtract(a, b), axis=-1).sum()
    return distance(left, to_right) + distance(right, to_left) < distance(left, to_left) + distance(right, to_right)
