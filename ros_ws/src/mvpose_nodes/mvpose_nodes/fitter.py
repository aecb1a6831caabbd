"""Fitting the 29-DOF skeleton to the features of several calibrated views (paper 000 Sec. 4–6).

Per frame: start from the previous frame's pose, or, on the first frame and after a jump in time,
from an initialisation (the 2D keypoints triangulated across views, turned into angles by paper
004's method, bone lengths from the template scaled to the estimated height); then six Nelder–Mead
searches (Sec. 5.1): torso, head and neck, left arm, right arm, left leg, right leg, each over its own
parameters with the rest fixed, each minimising its own objective:
  - Eq. 4–5 for every bone that has labelled boundaries (torso, head, thighs, shins): the projected
    bone midway between its part's two sides, summed over the cameras that see them; plus the
    "stay on the part" term of objective._camera_cost, so that a bone cannot rest equidistant from
    both sides far off the part (weight ENCLOSURE_WEIGHT);
  - the reprojection distance of the joints that the features located in 2D (root, neck, head,
    elbows, wrists, knees, ankles), robust (KEYPOINT_SCALE) and weighted by confidence (the
    paper uses these keypoints for initialisation; the arms have no labelled contour, so for them
    the skin keypoints are the evidence, as in paper 000 Sec. 3.2).
Left and right: a single view often cannot tell them apart (features.py), so each camera's left/right
labels of legs and arms are swapped where the current pose projects better onto the swapped ones.
Nelder–Mead (Lagarias et al. 1998): SciPy's with its standard coefficients, which are the paper's
(Eq. 7: ρ = 1, χ = 2, γ = 0.5, σ = 0.5; non-adaptive), stopped by the simplex size (xatol) alone.
"""
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize

from mvpose_nodes.features import FRONT_SKIN_FRACTION
from mvpose_nodes.body_model import (LABEL_HEAD, LABEL_LEFT_LEG, LABEL_RIGHT_LEG, LABEL_TORSO, PARAMETER_NAMES,
                                     STAGE_NAMES)
from mvpose_nodes.kinematics import BONE_INDEX, BONES, J, P, bone_lengths, forward_kinematics, inverse_kinematics
from mvpose_nodes.objective import limb_cost
from mvpose_nodes.triangulation import best_assignment, triangulate

ENCLOSURE_WEIGHT = 1.0
BOUNDARY_WEIGHT = 0.1    # per pixel of Eq. 4 (a sum over N = 100 points), against KEYPOINT_WEIGHT per keypoint pixel
KEYPOINT_WEIGHT = 20.0   # a pixel of keypoint error costs as much as 20 px of summed boundary distance (N = 100)
KEYPOINT_SCALE = 30.0    # [px] keypoint errors e cost KEYPOINT_SCALE·log(1 + e/KEYPOINT_SCALE): about e when small,
                         # growing ever slower when large, so a wrong detection pulls little but always leads back
SIMPLEX_TOLERANCE = 5e-3  # [m or rad] stop when the simplex is this small (5 mm, 0.3°)
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
SWAPPABLE = {'legs': ('knee', 'ankle'), 'arms': ('elbow', 'wrist')}


@dataclass
class View:
    """One camera's evidence for one frame: its Camera, the boundary distance maps of its labelled
    contour (objective.BoundaryDistances, or None), its 2D keypoints {name: (x, y, confidence)}, and how
    much of the face it sees (features.Features.frontness; None if unknown)."""
    camera: object
    distances: object
    keypoints: dict
    frontness: float = None


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

    def fit(self, stamp, views):
        started = time.perf_counter()
        jump = self.last_stamp is None or stamp < self.last_stamp or stamp - self.last_stamp > TIME_JUMP
        self.last_stamp = stamp
        initialised = False
        if self.parameters is None or jump:
            start = self.initial_parameters(views)
            if start is None:
                raise ValueError('too few views with keypoints to initialise (need root, neck and head in 2 views)')
            self.parameters, initialised = start, True
        parameters = self.parameters.copy()
        # Paper 000 Sec. 5.3: local minima are avoided by starting from the previous frame's pose or
        # from the frame's own features; each stage starts from whichever of the two fits better.
        found = None if initialised else self.triangulated_joints(views)
        reference, _ = forward_kinematics(parameters, self.lengths)
        if found is not None:
            # Which triangulated limb is left: the one nearer the previous frame's left (a single
            # frame's evidence can flip between frames; the pose moves little in 40 ms).
            for limb in ('knee', 'ankle', 'elbow', 'wrist'):
                left, right = f'left_{limb}', f'right_{limb}'
                if left in found and right in found and crossed_is_nearer(
                        found[left], found[right], reference[J[left]], reference[J[right]]):
                    found[left], found[right] = found[right], found[left]
            for name, position in found.items():
                reference[J[name]] = position
        candidate = None
        oriented = [self.oriented_view(view, reference) for view in views]
        results = []
        for stage in STAGE_NAMES:
            if found is not None and stage != 'torso':
                if candidate is None:  # the limbs' triangulated joints, as angles relative to the fitted torso
                    hybrid, _ = forward_kinematics(parameters, self.lengths)
                    for name, position in found.items():
                        if name not in ('pelvis', 'neck'):
                            hybrid[J[name]] = position
                    candidate = inverse_kinematics(hybrid)
                indices = [P[name] for name in STAGE_PARAMETERS[stage]]
                alternative = parameters.copy()
                alternative[indices] = candidate[indices]
                if self.stage_cost(stage, alternative, oriented)[0] < self.stage_cost(stage, parameters, oriented)[0]:
                    parameters = alternative
            parameters, result = self.search(stage, parameters, oriented)
            results.append(result)
        self.parameters = parameters
        joints, _ = forward_kinematics(parameters, self.lengths)
        return Fit(joints, parameters, results, initialised, time.perf_counter() - started)

    def initial_parameters(self, views):
        """Angles from triangulated keypoints (paper 000 Sec. 3.1 and 6; paper 004), or None."""
        joints = self.triangulated_joints(views)
        if joints is None:
            return None
        if self.lengths is None:
            self.lengths = self.person_lengths(joints)
        return inverse_kinematics(self.completed_joints(joints))

    def triangulated_joints(self, views):
        """{joint: (3,) [m]} triangulated from the views' keypoints (left/right pairs assigned across views
        and to the person's sides), or None without root, neck and head in two views."""
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
        right = self.facing_right(views, joints)
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
            if right is not None and np.dot(left - right_point, right) > 0:  # the pair's "left" is on the right
                left, right_point = right_point, left
            joints[f'left_{limb}'], joints[f'right_{limb}'] = left, right_point
        return joints

    @staticmethod
    def person_lengths(joints):
        """Bone lengths of the person, on the first frame: the template scaled to the height (head above
        the ankles), then the bones whose both ends were triangulated measured instead (the template's
        proportions are an average person's; within ±LENGTH_TRUST of it a measurement is believed)."""
        ankles = [joints[n][2] for n in ('left_ankle', 'right_ankle') if n in joints]
        height = joints['head'][2] - (min(ankles) - ANKLE_HEIGHT * 1.75 if ankles else 0.0)
        lengths = bone_lengths(float(np.clip(height / (1 - ANKLE_HEIGHT) if ankles else height, 1.2, 2.2)))
        measurable = {'shin': ('knee', 'ankle'), 'forearm': ('elbow', 'wrist')}
        for key, (start, end) in measurable.items():
            measured = [np.linalg.norm(joints[f'{side}_{end}'] - joints[f'{side}_{start}']) for side in ('left', 'right')
                        if f'{side}_{start}' in joints and f'{side}_{end}' in joints]
            if measured and abs(np.median(measured) / lengths[key] - 1) < LENGTH_TRUST:
                lengths[key] = float(np.median(measured))
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
        if np.linalg.norm(forward) < 0.2:
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
            labelled = [(f'left_{n}', f'right_{n}') for n in names if f'left_{n}' in keypoints and f'right_{n}' in keypoints]
            if not labelled:
                continue
            projected, _ = view.camera.project(joints[[J[j] for pair in labelled for j in pair]])
            # All the group's pairs at once: the projected lefts and rights against the labelled ones.
            if crossed_is_nearer(projected[0::2], projected[1::2], [keypoints[left][:2] for left, _ in labelled],
                                 [keypoints[right][:2] for _, right in labelled]):
                for name in names:
                    left, right = f'left_{name}', f'right_{name}'
                    for mine, other in ((left, right), (right, left)):
                        if other in view.keypoints:
                            keypoints[mine] = view.keypoints[other]
                        else:
                            keypoints.pop(mine, None)
                if group == 'legs' and distances is not None:
                    distances = distances.swapped(LABEL_LEFT_LEG, LABEL_RIGHT_LEG)
        return View(view.camera, distances, keypoints, view.frontness)

    def search(self, stage, parameters, views):
        """One Nelder–Mead stage over STAGE_PARAMETERS[stage]; (new parameters, StageResult)."""
        indices = [P[name] for name in STAGE_PARAMETERS[stage]]
        steps = np.array([STEP['position'] if name.endswith(('_x', '_y', '_z')) else STEP['angle']
                          for name in STAGE_PARAMETERS[stage]])
        if not self.has_evidence(stage, views):
            return parameters, StageResult(stage, 0.0, 0, [], False)
        trial = parameters.copy()
        start = parameters[indices]
        limits = [(i, JOINT_LIMITS[name]) for i, name in enumerate(STAGE_PARAMETERS[stage]) if name in JOINT_LIMITS]

        def cost(values):
            trial[indices] = values
            total, _ = self.stage_cost(stage, trial, views)
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
        final, used = self.stage_cost(stage, fitted, views)
        return fitted, StageResult(stage, float(final), int(result.nfev),
                                   sorted(views[i].camera.number for i in used), True)

    @staticmethod
    def has_evidence(stage, views):
        return any(name in view.keypoints for view in views for name in STAGE_KEYPOINTS[stage]) or any(
            view.distances is not None and label in view.distances.widths
            for view in views for _, label in STAGE_BONES[stage])

    def stage_cost(self, stage, parameters, views):
        """The stage's objective (module docstring) and the indices of the views that contributed."""
        joints, _ = forward_kinematics(parameters, self.lengths)
        projections = [view.camera.project(joints) for view in views]  # every joint, once per camera
        total, used = 0.0, set()
        for bone_name, label in STAGE_BONES[stage]:
            bone = BONES[BONE_INDEX[bone_name]]
            ends = (J[bone.parent_joint], J[bone.joint])
            segments = [(pixels[ends[0]], pixels[ends[1]]) if depth[list(ends)].min() > 0 and view.distances else None
                        for view, (pixels, depth) in zip(views, projections)]
            cost, cameras = limb_cost(segments, [view.distances for view in views], label,
                                      enclosure_weight=ENCLOSURE_WEIGHT)
            total += BOUNDARY_WEIGHT * cost
            used.update(cameras)
        for index, (view, (pixels, _)) in enumerate(zip(views, projections)):
            names = [n for n in STAGE_KEYPOINTS[stage] if n in view.keypoints]
            if not names:
                continue
            for name in names:
                x, y, confidence = view.keypoints[name]
                point = pixels[J[KEYPOINT_JOINT.get(name, name)]]
                error = np.hypot(point[0] - x, point[1] - y)
                total += KEYPOINT_WEIGHT * confidence * KEYPOINT_SCALE * np.log1p(error / KEYPOINT_SCALE)
            used.add(index)
        return total, used


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
    from mvpose_nodes.objective import boundary_distances
    distances = None
    if contour is not None and len(contour.points):
        distances = boundary_distances(contour, (camera.width, camera.height))
    return View(camera, distances, keypoints, frontness)


def crossed_is_nearer(left, right, to_left, to_right):
    """Whether left/right points ((d,) or (N, d) for N pairs) lie nearer to others the other way round:
    the summed distances, left to right and right to left, against left to left and right to right."""
    def distance(a, b):
        return np.linalg.norm(np.subtract(a, b), axis=-1).sum()
    return distance(left, to_right) + distance(right, to_left) < distance(left, to_left) + distance(right, to_right)
