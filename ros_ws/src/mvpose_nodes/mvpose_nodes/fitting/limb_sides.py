"""Left and right: which limb of each pair is the person's left, followed from frame to frame.

A single view often cannot tell left from right (vision/features.py), and paper 000 does not say how
to. The frame's triangulated pairs are labelled by continuity with the fits before (LimbTracks); each
camera's left/right labels of legs and arms are then swapped where the labelled pose projects better onto
the swapped ones (oriented_view). Which labelling of the whole body is right (turned round, legs or arms
exchanged) the objective decides (hypotheses.py). Beyond the paper; measured in docs/method.md.
"""
from dataclasses import replace

import numpy as np

from mvpose_nodes.body.kinematics import BONE_INDEX, BONES
from mvpose_nodes.body.model import JOINT_INDEX, LABEL_LEFT_LEG, LABEL_RIGHT_LEG
from mvpose_nodes.fitting.objective import segment_points
from mvpose_nodes.fitting.stage_search import STAGE_BONES

SWAPPABLE = {'legs': ('knee', 'ankle'), 'arms': ('elbow', 'wrist')}
LEG_JOINTS = tuple(f'{side}_{name}' for side in ('left', 'right') for name in SWAPPABLE['legs'])
# The legs' labelled bones (thigh, shin) by part label, as the leg stages have them (stage_search.STAGE_BONES),
# and the points per bone that say which labelled leg's part it lies on (legs_on_other_labels).
LEG_BONES = {label: [name for name, _ in STAGE_BONES[stage]]
             for stage, label in (('left_leg', LABEL_LEFT_LEG), ('right_leg', LABEL_RIGHT_LEG))}
LEG_SIDE_POINTS = 20


def exchange(joints, name):
    """Swap joints['left_' + name] and joints['right_' + name] (when both are there)."""
    left, right = f'left_{name}', f'right_{name}'
    if left in joints and right in joints:
        joints[left], joints[right] = joints[right], joints[left]


class LimbTracks:
    """Which of each triangulated left/right pair (knees, ankles, elbows, wrists) is the person's left: the
    labelling whose points lie nearer the positions predicted from the last two fits at constant velocity
    (decisive while the two limbs are far apart, mid-stride; weak when they pass each other, which the
    stages' searches from both starts and the hypotheses make up for); after a gap of over continuity_horizon,
    by the side of the body each point is on (label_across). Its remembered fits also give the
    pelvis's velocity, which moves the next fit's start on.
    settings: FitterSettings (walking_baseline: how long fits are remembered)."""

    def __init__(self, settings):
        self.settings = settings
        self.history = []   # [(stamp [s], joints (15, 3) [m])] of the fits within walking_baseline

    def append(self, stamp, joints):
        baseline = self.settings.walking_baseline
        self.history = [(t, p) for t, p in self.history if stamp - t <= baseline] + [(stamp, joints.copy())]

    def after_gap(self, stamp, horizon=None):
        """Whether `stamp` [s] comes over `horizon` [s] (default velocity_horizon) after the last fit (frame
        sets skipped to keep up): too long for the fits' velocity to say where the limbs and the pelvis are
        now (with continuity_horizon: for their continuity to say which limb of a pair is which)."""
        horizon = self.settings.velocity_horizon if horizon is None else horizon
        return bool(self.history) and stamp - self.history[-1][0] > horizon

    def predicted(self, stamp):
        """Joints (15, 3) expected at `stamp` (constant velocity from the last two fits), or None."""
        if not self.history:
            return None
        t1, p1 = self.history[-1]
        if len(self.history) < 2 or t1 <= self.history[-2][0]:
            return p1
        t0, p0 = self.history[-2]
        return p1 + (p1 - p0) * (stamp - t1) / (t1 - t0)

    def pelvis_speed(self):
        """[m/s] The pelvis's speed across the floor over the fits remembered (walking_baseline), or None before
        two of them."""
        if len(self.history) < 2 or self.history[-1][0] <= self.history[0][0]:
            return None
        (t0, p0), (t1, p1) = self.history[0], self.history[-1]
        pelvis = JOINT_INDEX['pelvis']
        return float(np.linalg.norm((p1[pelvis] - p0[pelvis])[:2]) / (t1 - t0))

    def carried_legs(self, stamp):
        """The knees and ankles {name: (3,) [m]} the last two fits put at `stamp` at constant velocity (predicted)
        while the pelvis moves as a walker's does (pelvis_speed from standing_speed up to running_speed), else
        None. A leg's search starts from the last pose moved on with the pelvis, where a swinging foot is a
        frame period's walk behind and a planted one as far ahead (session 62: the legs' swapped strides)."""
        speed = self.pelvis_speed()
        if speed is None or not self.settings.standing_speed <= speed < self.settings.running_speed:
            return None
        predicted = self.predicted(stamp)
        return {name: predicted[JOINT_INDEX[name]] for name in LEG_JOINTS}

    def label(self, stamp, found):
        """Exchange, in `found` ({joint: (3,)} triangulated), the pairs nearer the other side's predicted
        positions: (d(a, p_r)² + d(b, p_l)² − d(a, p_l)² − d(b, p_r)²) < 0 for the pair's points a (left),
        b (right) and predictions p_l, p_r; over continuity_horizon after the last fit, the pairs on the
        other side of its body (label_across)."""
        predicted = self.predicted(stamp)
        if predicted is None:
            return
        if self.after_gap(stamp, self.settings.continuity_horizon):
            label_across(found, self.history[-1][1])
            return
        for name in ('knee', 'ankle', 'elbow', 'wrist'):
            left, right = f'left_{name}', f'right_{name}'
            if left not in found or right not in found:
                continue
            a, b = found[left], found[right]
            p_left, p_right = predicted[JOINT_INDEX[left]], predicted[JOINT_INDEX[right]]
            if (np.sum((a - p_right) ** 2) + np.sum((b - p_left) ** 2)
                    < np.sum((a - p_left) ** 2) + np.sum((b - p_right) ** 2)):
                exchange(found, name)


def label_across(found, joints):
    """Exchange, in `found` ({joint: (3,)} triangulated), the pairs whose left point lies right of the
    right one across the body of `joints` (15, 3) [m]: (a − b)·(left_shoulder − right_shoulder) < 0 for the
    pair's points a (left), b (right). For fits too far apart in time for continuity: half a second on, a
    walker's legs have changed places front to back, not side to side. The legs too are judged across the
    shoulders, not the hips: the fits' hips' line is often 15–40° off for whole walks while the shoulders'
    is within a few degrees (docs/method.md, session 43), and a stride's feet, far apart front to back and
    little side to side, then lie on the wrong sides of it (the tuning cases' fits 6 frame periods before:
    the ankles' sides right in 93.5 % across the hips, 99.0 % across the shoulders; session 45)."""
    across = joints[JOINT_INDEX['left_shoulder']] - joints[JOINT_INDEX['right_shoulder']]
    for name in ('knee', 'ankle', 'elbow', 'wrist'):
        left, right = f'left_{name}', f'right_{name}'
        if left in found and right in found and np.dot(found[left] - found[right], across) < 0:
            exchange(found, name)


def oriented_view(view, joints):
    """The view (fitter.View) with its left/right labels of legs and arms swapped where `joints` (15, 3)
    [m], the frame's reference pose, say they are."""
    keypoints = dict(view.keypoints)
    distances = view.distances
    for group, names in SWAPPABLE.items():
        # The group's keypoints (a whole pair, or one side only when a limb is hidden) against the
        # reference's projected joints of the same side and of the other.
        seen = [f'{side}_{n}' for n in names for side in ('left', 'right') if f'{side}_{n}' in keypoints]
        if not seen:
            if group == 'legs' and distances is not None and legs_on_other_labels(distances, view.camera, joints):
                distances = distances.swapped(LABEL_LEFT_LEG, LABEL_RIGHT_LEG)
            continue
        other_side = [name.replace('left_', 'RIGHT_').replace('right_', 'left_').replace('RIGHT_', 'right_')
                      for name in seen]
        projected, _ = view.camera.project(joints[[JOINT_INDEX[name] for name in seen + other_side]])
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
    return replace(view, distances=distances, keypoints=keypoints)


def legs_on_other_labels(distances, camera, joints):
    """Whether the legs of `joints` (15, 3) [m], projected by `camera`, lie nearer the view's labelled leg
    boundaries (objective.BoundaryDistances) the other way round: Σ over the thighs' and shins' points of
    the distances to both sides of the other leg's part below that to their own. For a view without leg
    keypoints whose legs are still labelled: the image cutting the person off leaves the knees and ankles out
    (views.view_from_features) after the contour was labelled by them, from a front or back the face only
    guessed (vision.features), so the keypoints cannot orient its labels. False when a leg's part lacks a
    side or the legs lie behind the camera."""
    if any(label not in distances.widths for label in LEG_BONES):
        return False
    nearness = {}
    for label, names in LEG_BONES.items():
        bones = [BONES[BONE_INDEX[name]] for name in names]
        segments = [camera.project(joints[[JOINT_INDEX[bone.parent_joint], JOINT_INDEX[bone.joint]]]) for bone in bones]
        if any(np.any(depths <= 0) for _, depths in segments):
            return False
        points = np.vstack([segment_points(*pixels, LEG_SIDE_POINTS) for pixels, _ in segments])
        nearness[label] = {part: float(np.sum(distances.both_sides(part, points))) for part in LEG_BONES}
    own = nearness[LABEL_LEFT_LEG][LABEL_LEFT_LEG] + nearness[LABEL_RIGHT_LEG][LABEL_RIGHT_LEG]
    other = nearness[LABEL_LEFT_LEG][LABEL_RIGHT_LEG] + nearness[LABEL_RIGHT_LEG][LABEL_LEFT_LEG]
    return other < own


def exchanged_pairs(joints, names):
    """A copy of joints (15, 3) [m] with the left/right pair of each of `names` ('knee', …) exchanged."""
    exchanged = joints.copy()
    for name in names:
        pair = [JOINT_INDEX[f'left_{name}'], JOINT_INDEX[f'right_{name}']]
        exchanged[pair] = joints[pair[::-1]]
    return exchanged


def mirrored_joints(joints):
    """joints (15, 3) [m] with every left/right pair exchanged: the same points, the torso facing the
    other way."""
    return exchanged_pairs(joints, ('hip', 'knee', 'ankle', 'shoulder', 'elbow', 'wrist'))
