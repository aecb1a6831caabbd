"""Left and right: which limb of each pair is the person's left, tracked from frame to frame.

A single view often cannot tell left from right (vision/features.py), and paper 000 does not say how
to. The triangulated pairs are labelled by LimbTracks (continuity, and the direction of travel while
walking); each camera's left/right labels of legs and arms are then swapped where the labelled pose
projects better onto the swapped ones (oriented_view); and a walking torso that faces away from its
direction of travel is turned back (facing_travel). Front or back, i.e. every pair at once: the faces
the views see (face_votes) and the feet (foot_evidence, FacingWatch). Beyond the paper; measured in
docs/method.md.
"""
from dataclasses import replace

import numpy as np

from mvpose_nodes.body.kinematics import forward_kinematics
from mvpose_nodes.body.model import JOINT_INDEX, LABEL_LEFT_LEG, LABEL_RIGHT_LEG, PARAMETER_INDEX
from mvpose_nodes.fitting.objective import outside_distances

SWAPPABLE = {'legs': ('knee', 'ankle'), 'arms': ('elbow', 'wrist')}


def exchange(joints, name):
    """Swap joints['left_' + name] and joints['right_' + name] (when both are there)."""
    left, right = f'left_{name}', f'right_{name}'
    if left in joints and right in joints:
        joints[left], joints[right] = joints[right], joints[left]


class LimbTracks:
    """Which of each triangulated left/right pair (knees, ankles, elbows, wrists) is the person's left.

    Single views cannot tell (features.py), and the face's direction is too rough to (20° off moves a
    60 cm stride 20 cm sideways). Two cues decide, frame by frame and pair by pair:
    - continuity: the labelling whose points lie nearer the positions predicted from the last two fitted
      poses at constant velocity; decisive while the two limbs are far apart (mid-stride), weak when
      they pass each other;
    - sides: while the person walks (pelvis faster than walking_speed over walking_baseline), the left
      limb lies to the left of the direction of travel, or to its right when the torso the fit starts
      from faces against it (someone walking backwards: the faces or the feet turned the fit round);
      knees and ankles are 5–20 cm apart sideways all through a walk (CMU 07_01), elbows more.
    The evidence of each, in metres: continuity (d(a, p_r)² + d(b, p_l)² − d(a, p_l)² − d(b, p_r)²) /
    continuity_scale, the sides' the lateral offset of the "left" point to the right; the labelling is
    exchanged when their sum says so. Until the person is first seen walking (after a (re)start), the
    labels come from the face (initialisation.labelled_joints) or are a guess: continuity would keep
    a wrong guess, so on that first walking frame each group (legs, arms) is labelled by its mean lateral
    offset over the remembered fits alone.
    settings: FitterSettings (walking_speed, walking_baseline, continuity_scale).
    """

    def __init__(self, settings):
        self.settings = settings
        self.history = []   # [(stamp [s], joints (15, 3) [m])] of the fits within walking_baseline
        self.anchored = False  # whether the sides have been seen while walking since the (re)start
        self.exchanges = 0  # exchanged pairs so far (for diagnostics)

    def restart(self):
        self.history.clear()
        self.anchored = False

    def mirror(self):
        """Exchange every pair in the remembered fits (the fit was turned round: limb_sides.mirrored_joints)."""
        self.history = [(t, mirrored_joints(joints)) for t, joints in self.history]

    def append(self, stamp, joints):
        baseline = self.settings.walking_baseline
        self.history = [(t, p) for t, p in self.history if stamp - t <= baseline] + [(stamp, joints.copy())]

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
        if len(self.history) < 2 or self.history[-1][0] - self.history[0][0] < self.settings.walking_baseline / 4:
            return None
        (t0, p0), (t1, p1) = self.history[0], self.history[-1]
        velocity = (p1[JOINT_INDEX['pelvis']] - p0[JOINT_INDEX['pelvis']]) / (t1 - t0)
        velocity[2] = 0.0
        speed = np.linalg.norm(velocity)
        return np.cross(velocity / speed, [0.0, 0.0, 1.0]) if speed > self.settings.walking_speed else None

    def label(self, stamp, found, torso):
        """Exchange, in `found` ({joint: (3,)} triangulated), the pairs that belong the other way round.
        torso: the right (3,) (torso_right) of the pose the frame's fit starts from: a torso that faces
        against the direction of travel (someone walking backwards, as the faces or the feet said) has
        its right on the walk's left."""
        right = self.walking_right()
        if right is not None and np.dot(right, torso) < 0:
            right = -right
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
            p_left, p_right = predicted[JOINT_INDEX[left]], predicted[JOINT_INDEX[right_name]]
            evidence = (np.sum((a - p_right) ** 2) + np.sum((b - p_left) ** 2)
                        - np.sum((a - p_left) ** 2) - np.sum((b - p_right) ** 2)) / self.settings.continuity_scale
            if right is not None:
                evidence -= np.dot(a - b, right)
            if evidence < 0:
                exchange(found, name)
                self.exchanges += 1

    def anchor(self, right, found):
        """Label each group by its mean lateral offset over the history and `found` (see the class)."""
        self.anchored = True
        for names in SWAPPABLE.values():
            offsets = [np.dot(joints[JOINT_INDEX[f'left_{n}']] - joints[JOINT_INDEX[f'right_{n}']], right)
                       for _, joints in self.history for n in names]
            offsets += [np.dot(found[f'left_{n}'] - found[f'right_{n}'], right) for n in names
                        if f'left_{n}' in found and f'right_{n}' in found]
            if np.mean(offsets) > 0:
                for name in names:
                    exchange(found, name)
                self.history = [(t, exchanged_pairs(joints, names)) for t, joints in self.history]
                self.exchanges += 1


def torso_right(joints):
    """The person's right (3,): the horizontal unit vector from the left hip to the right hip of joints (15, 3)."""
    right = joints[JOINT_INDEX['right_hip']] - joints[JOINT_INDEX['left_hip']]
    right[2] = 0.0
    return right / max(np.linalg.norm(right), 1e-9)


def wrong_sided(joints):
    """The SWAPPABLE groups ('legs', 'arms') of joints (15, 3) [m] whose left limb lies on the torso's right:
    the group's mean offset of left minus right joints along the torso's right (the hip line, horizontal)
    is positive. Hips and shoulders are 18–45 cm apart, so outside a crossing step or crossed arms each
    limb of a pair stays on its own side; the fitted torso's yaw comes from the outline (hips' and
    shoulders' widths), not from the pairs' labels."""
    right = torso_right(joints)
    return [group for group, names in SWAPPABLE.items()
            if np.mean([np.dot(joints[JOINT_INDEX[f'left_{n}']] - joints[JOINT_INDEX[f'right_{n}']], right)
                        for n in names]) > 0]


def facing_travel(parameters, lengths, right, yaw_limit):
    """The parameters (29,) with the torso turned about the vertical to face the direction of travel
    (`right`: the person's right from LimbTracks.walking_right, or None when not walking) if the torso's
    right is more than yaw_limit [rad] away from the walk's; and whether it was turned. The outline and
    the midlines look much the same from the front and from the back, and a poor initial guess (no face
    seen, the limbs' pairs not yet labelled) would otherwise stay; people walk forwards. Rz is the
    outermost of the torso's Euler angles: the turn adds to torso_rz."""
    if right is None:
        return parameters, False
    joints, _ = forward_kinematics(parameters, lengths)
    hips = torso_right(joints)
    turn = np.arctan2(right[1], right[0]) - np.arctan2(hips[1], hips[0])
    turn = (turn + np.pi) % (2 * np.pi) - np.pi
    if abs(turn) <= yaw_limit:
        return parameters, False
    turned = parameters.copy()
    rz = PARAMETER_INDEX['torso_rz']
    turned[rz] = (turned[rz] + turn + np.pi) % (2 * np.pi) - np.pi
    return turned, True


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


HEAD_RADIUS = 0.11        # [m] of the head, as a sphere centred HEAD_CENTRE_BELOW_TOP below the vertex
HEAD_CENTRE_BELOW_TOP = 0.11   # [m]
# Skin regions centred in the upper projected head covering this share of its disc: a face. Chosen on the
# suite's tuning motions only (seed 1: 0.4-0.6 right for 58-59 of 70 views that face towards or away).
FACE_SKIN_SHARE = 0.5
FACING_COS = 0.5          # a camera within 60° of the face direction sees the face; beyond 120°, the hair


def face_votes(views, joints):
    """How many views agree, minus how many disagree, that the torso of `joints` (15, 3) [m] faces the way
    it does: a view whose skin regions (View.skin: centres and areas) centred in the upper projected head
    cover FACE_SKIN_SHARE of its disc sees a face, and should be one the torso's forward looks towards
    (within 60°); one that sees less should be behind (beyond 120°). Views in between, or without skin
    regions, do not vote. Beyond paper 000: the face is the one front/back cue the silhouettes lack."""
    up = joints[JOINT_INDEX['head']] - joints[JOINT_INDEX['neck']]
    up /= max(np.linalg.norm(up), 1e-9)
    centre = joints[JOINT_INDEX['head']] - HEAD_CENTRE_BELOW_TOP * up
    forward = torso_forward(joints)
    votes = 0
    for view in views:
        if view.skin is None or not len(view.skin):
            continue
        towards = view.camera.center - centre
        towards[2] = 0.0
        cos = float(np.dot(forward, towards / max(np.linalg.norm(towards), 1e-9)))
        if abs(cos) < FACING_COS:
            continue
        (pixel,), (depth,) = view.camera.project(centre[None])
        if depth <= 0:
            continue
        radius = HEAD_RADIUS * view.camera.K[0, 0] / depth
        inside = (np.hypot(*(view.skin[:, :2] - pixel).T) < radius) & (view.skin[:, 1] < pixel[1] + 0.3 * radius)
        face = view.skin[inside, 2].sum() >= FACE_SKIN_SHARE * np.pi * radius ** 2
        votes += 1 if face == (cos > 0) else -1
    return votes


def torso_forward(joints):
    """The horizontal unit vector (3,) the torso of joints (15, 3) [m] faces: up × (right hip − left hip)."""
    return np.cross([0.0, 0.0, 1.0], torso_right(joints))


FOOT_REACH = 0.14   # [m] probe points this far ahead of and behind each ankle: on the shoe ahead, past the heel
FOOT_DROP = 0.03    # [m] ... and this much lower (a foot on the floor is below its ankle)
FOOT_CAP = 0.08     # [m] a probe's distance outside the silhouette counts up to this


def foot_evidence(views, joints):
    """[m] How much the views' silhouettes say that the feet point the way the torso of joints (15, 3) [m]
    faces; negative: the other way. Feet point forward, and reach 15–20 cm ahead of the ankle but only
    5–7 cm behind it, so a point FOOT_REACH ahead of an ankle falls on the shoe and one as far behind it
    on the floor in any view that sees the foot from the side. Per view and ankle: the distance outside
    the silhouette (View.outline) of the point behind minus that of the point ahead, each at most
    FOOT_CAP and turned into metres at the ankle's depth. Views facing the foot see both points on it and
    say nothing; neither do feet in the air, whose both points miss the silhouette. The ankles' labels do
    not matter, so the cue holds while left and right are still unsorted. It is only as good as the
    ankles: on the suite's truth poses it is right in 98-100 % of walking frames, on fitted ones far
    less (ankles 10-20 cm off), hence FacingWatch's window. Beyond paper 000: silhouettes are otherwise
    nearly the same from the front and from the back, and so is the fit's cost."""
    forward = torso_forward(joints) * FOOT_REACH
    evidence = 0.0
    for view in views:
        if view.outline is None:
            continue
        for name in ('left_ankle', 'right_ankle'):
            probe = joints[JOINT_INDEX[name]] - (0.0, 0.0, FOOT_DROP)
            pixels, depths = view.camera.project(np.array([probe + forward, probe - forward]))
            if np.any(depths <= 0):
                continue
            metres = outside_distances(view.outline, pixels) * depths / view.camera.K[0, 0]
            ahead, behind = np.minimum(metres, FOOT_CAP)
            evidence += behind - ahead
    return float(evidence)


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


class FacingWatch:
    """The feet's evidence (foot_evidence) about the fitted torso's facing over the last facing_window
    fits: `wrong()` once their sum is below −facing_flip_evidence, i.e. the fit has faced backwards for a
    while (a single frame's feet can mislead: a foot lifted, or the other foot's shoe behind the heel).
    settings: FitterSettings."""

    def __init__(self, settings):
        self.settings = settings
        self.evidence = []

    def clear(self):
        self.evidence.clear()

    def append(self, evidence):
        self.evidence = (self.evidence + [evidence])[-self.settings.facing_window:]

    def wrong(self):
        return sum(self.evidence) < -self.settings.facing_flip_evidence
