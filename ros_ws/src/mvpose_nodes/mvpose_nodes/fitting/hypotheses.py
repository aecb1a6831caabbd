"""Left and right, front and back, decided by which labelling of the body explains the views best (issue 13).

A silhouette is nearly the same for a person and for the same points labelled the other way round: every
left/right pair exchanged (the person turned round), or only the legs', or only the arms'. Paper 000 does
not say how to tell. With the limbs' twist limited as anatomy limits it (stage_search.TWIST_LIMITS), a
bent knee or elbow no longer fits a body turned round, and the stages' objective prefers the right
labelling: fitted from the true pose of the suite's first draw, the body turned round cost more in 95 %
of the frame sets where the two differ by over 30 mm, the legs or arms exchanged in 90 % (without the
twist limits: turned round 49 %). The limits on the thighs' adduction and the upper arms' reach across
the body do the same for legs or arms exchanged, which cross the body's middle. For a body standing
straight, the feet and the face tell front from back (SkeletonFitter.cost_of): the feet point the way
the hips face (feet_outside), and the face is where the views see skin on the head (weaker: hair of
skin's colour reads as a face, so the face is not asked of a person whose skin reaches the top of the head:
initialisation.face_tells).

So the fitter follows hypotheses (Track): at a start, the fit and each other labelling of it (RELABELLINGS
and their combinations) are each tracked for hypothesis_frames frame sets and the one whose fits cost the
least over them is kept; later, every probe_period frame sets the body turned round (PERIODIC_PROBE) is
tracked beside the fit for as long, and taken if its fits cost hypothesis_margin less, and so are the
legs exchanged at each stride (as the fit's ankles come within crossing_distance, and again once they are
stride_apart of the leg apart) and whenever the fit's knees cross with the feet together while standing
(pair_crossing, crossing_judged); the arms exchanged whenever the fit's wrists cross; and crossed knees
(standing so) and wrists raise a labelling's cost. After every
frame set, tracks whose fits cost hypothesis_prune more than the cheapest's are dropped. A labelling's
first fit searches only the stages whose pairs it exchanges (relabelled_stages): the legs or the arms
exchanged keep the fit's torso, head and other limbs, the body turned round searches them all. A track's
cost is its fits' objective with the outline assigned from the fitted pose (SkeletonFitter.cost_of), not
the searches' own costs, whose assignments were made from where each search started. A fit that leaves
much of the outline unexplained (unexplained_share) has lost the person, and the fitter starts again.
No ROS: NumPy and the compiled nearest capsules.
"""
import itertools
from dataclasses import dataclass, field

import numpy as np

from mvpose_nodes.body.model import JOINT_INDEX, STAGE_NAMES, torso_frame
from mvpose_nodes.fitting.limb_sides import LimbTracks, exchange, exchanged_pairs
from mvpose_nodes.fitting.compiled import nearest_capsules
from mvpose_nodes.fitting.objective import outside_distances
from mvpose_nodes.fitting.stage_search import CAPSULE_ENDS

HYPOTHESES_POOL = 'hypotheses'   # the name of the threads that fit hypotheses side by side (SkeletonFitter.pool)
LOST_MARGIN = 0.25  # [m] an outline point this far from every bone is not explained by the skeleton
# A point of each foot, ahead of the ankle where the hips face and below it, which a labelling turned round
# puts behind the heel, off the shoe: FOOT_REACH of the stature ahead (15 cm at 1.75 m, the ball of the
# foot: a foot is about 15 % of the stature long, the ankle over its back third).
FOOT_REACH = 0.085
FOOT_CAP_PX = 50.0   # [px] a foot point's distance outside the silhouette counts up to this (a hidden foot)
# Only a foot on the ground lies flat, pointing the way the body faces; a swinging foot points down, as do both
# in a hop's or a run's flight. A foot counts if its ankle is within STANCE_HEIGHT of the stature (9 cm at
# 1.75 m) of its height standing on the floor (z = 0, the world frame's, README).
STANCE_HEIGHT = 0.05

# The labellings tried beside the fit: the pairs each exchanges (body/model's joint names without the side).
RELABELLINGS = {
    'turned round': ('hip', 'knee', 'ankle', 'shoulder', 'elbow', 'wrist'),
    'legs exchanged': ('knee', 'ankle'),
    'arms exchanged': ('elbow', 'wrist'),
}
# The labelling probed every probe_period frame sets while tracking: the body turned round, the costliest
# mistake (every pair wrong). The legs exchanged are probed after each stride instead, and the arms only at a
# start: on the suite's 70 tuning cases (seeds 1-6) probing the legs and the arms in turn with it took the
# wrong labelling in a sit-down and a turn on the spot (21 swapped frame sets each) and righted none
# (docs/method.md, session 30).
PERIODIC_PROBE = 'turned round'
# The stages (stage_search.STAGE_PARAMETERS) whose parameters place the joints of each pair: a labelling that
# exchanges none of a stage's pairs leaves that stage's fit as it was (SkeletonFitter.spawn keeps it).
PAIR_STAGES = {'hip': ('torso', 'left_leg', 'right_leg'), 'shoulder': ('torso', 'left_arm', 'right_arm'),
               'knee': ('left_leg', 'right_leg'), 'ankle': ('left_leg', 'right_leg'),
               'elbow': ('left_arm', 'right_arm'), 'wrist': ('left_arm', 'right_arm')}


def combined(names):
    """The pairs exchanged by the RELABELLINGS `names` applied one after the other (each pair exchanged an
    odd number of times), in body order."""
    counts = {}
    for name in names:
        for pair in RELABELLINGS[name]:
            counts[pair] = counts.get(pair, 0) + 1
    return tuple(pair for pair in RELABELLINGS['turned round'] if counts.get(pair, 0) % 2)


# At a start every labelling: each relabelling and each combination of them (2³ − 1).
START_LABELLINGS = tuple(
    (' and '.join(names), combined(names))
    for count in range(1, len(RELABELLINGS) + 1) for names in itertools.combinations(RELABELLINGS, count))


@dataclass(eq=False)   # a hypothesis is itself, not its values: list.remove finds this one
class Track:
    """One hypothesis being followed: its parameters (29,) and its recent fits (limbs: LimbTracks, which
    label the frame's triangulated pairs by continuity), its fits' cost summed over the comparison window
    (counted only while one is under way), and its last fit's joints (15, 3) [m] and stage_search.StageResults."""
    parameters: np.ndarray
    limbs: LimbTracks
    cost: float = 0.0
    joints: np.ndarray = None
    results: list = field(default_factory=list)

    def relabelled(self, pairs):
        """A new Track with `pairs` exchanged in its remembered fits (its parameters are set by its first fit)."""
        limbs = LimbTracks(self.limbs.settings)
        limbs.history = [(stamp, exchanged_pairs(joints, pairs)) for stamp, joints in self.limbs.history]
        return Track(self.parameters.copy(), limbs)


def relabelled_stages(pairs):
    """The stage names a labelling that exchanges `pairs` has to fit afresh: with the hips or shoulders (the
    torso turned round) every stage, else the limbs whose pairs it exchanges (PAIR_STAGES)."""
    stages = {stage for pair in pairs for stage in PAIR_STAGES[pair]}
    return set(STAGE_NAMES) if 'torso' in stages else stages


def relabelled_joints(found, pairs):
    """A copy of triangulated joints {name: (3,)} (or None) with the left/right `pairs` exchanged."""
    if found is None:
        return None
    found = dict(found)
    for pair in pairs:
        exchange(found, pair)
    return found


def face_away(joints, face_right):
    """How far the hips of `joints` (15, 3) [m] face away from the face the views see: max(0, −cos θ) of the
    angle θ between the hips' right (right hip − left hip) and `face_right` (unit, initialisation.facing_right),
    0 for a pose facing the face's way or side on to it, 1 for one facing straight away. Graded, not all or
    nothing: the face's direction is the frontness-weighted mean of a few cameras' directions (in the suite's
    seed 7 case 9 it lay 70-80° from the true right), and a pose whose hips were 20° off the truth's was taken
    as facing away and charged in full, so the body turned round was kept for 20 frame sets."""
    hips = joints[JOINT_INDEX['right_hip']] - joints[JOINT_INDEX['left_hip']]
    return max(0.0, -float(np.dot(hips, face_right)) / max(float(np.linalg.norm(hips)), 1e-9))


CROSSING_BASE = {'knee': 'hip', 'wrist': 'shoulder'}   # the pair whose line a limb pair's crossing is measured across


def pair_crossing(joints, limb):
    """[m] How far the left `limb` joint ('knee' or 'wrist') of joints (15, 3) [m] lies right of the right one,
    across the floor along the line of its CROSSING_BASE pair (the hips, the shoulders); 0 if it lies left of
    it. In the suite's tuning motions neither the true knees nor the true wrists ever cross (the left knee at
    least 0.04 m left of the right, the left wrist 0.36 m), nor do a correctly labelled fit's wrists (0.2 % of
    its frame sets) or, standing, its knees (0-0.2 %), while those of a fit with its arms or legs exchanged do
    (its wrists in 63-83 % of such frame sets, its knees in a turn on the spot 51 %; session 42), where the
    silhouettes cannot tell the labellings apart. (Arms folded or crossed do cross the wrists: those were not
    in the tuning set.)"""
    base = CROSSING_BASE[limb]
    left = joints[JOINT_INDEX[f'left_{base}']] - joints[JOINT_INDEX[f'right_{base}']]
    left[2] = 0.0
    across = np.dot(joints[JOINT_INDEX[f'left_{limb}']] - joints[JOINT_INDEX[f'right_{limb}']], left)
    return max(0.0, -float(across) / max(float(np.linalg.norm(left)), 1e-9))


def crossing_judged(joints, limbs, settings):
    """Whether the knees' crossing (pair_crossing) tells the legs' labelling of joints (15, 3) [m]: the ankles
    within settings.crossing_distance and the pelvis of the fits in `limbs` (LimbTracks.pelvis_speed) slower than
    settings.standing_speed; not before two fits. Walking, the knees pass close by each other with
    the hips' line turned by the fit as much as 35° off (the rigid torso follows the shoulders, which counter-
    rotate), so crossed knees there are mostly not exchanged legs: judged while striding, they swapped correct
    walks for frame sets at a time (session 42)."""
    speed = limbs.pelvis_speed()
    apart = np.linalg.norm(joints[JOINT_INDEX['left_ankle']] - joints[JOINT_INDEX['right_ankle']])
    return speed is not None and bool(apart < settings.crossing_distance and speed < settings.standing_speed)


def due_probe(track, lengths, apart, last_apart, legs_passed, since_probe, settings):
    """The labelling (a RELABELLINGS name) to follow beside the fit `track` (Track) from this frame set on, or
    None. A stride, where continuity is least sure of the legs: the legs exchanged as the fit's ankles close in
    again from crossing_distance or more (as they pass, or a short stride's widest; `apart`, `last_apart`: the
    ankles' distance [m] now and at the last fit) and once they are stride_apart of the leg (`lengths`: the
    person's bone lengths [m]) apart, if they have passed each other since the last legs' probe
    (`legs_passed`); and standing with the feet together, whenever the knees cross (crossing_judged), which
    the true knees do not. The arms exchanged whenever the wrists cross, which the true wrists do not. Else
    PERIODIC_PROBE once `since_probe` frame sets have passed since the last probe (probe_period)."""
    leg = lengths['thigh'] + lengths['shin']
    closing = settings.crossing_distance <= last_apart > apart
    far = apart >= max(settings.crossing_distance, settings.stride_apart * leg)
    crossed = pair_crossing(track.joints, 'knee') > 0 and crossing_judged(track.joints, track.limbs, settings)
    if (legs_passed and (far or closing)) or crossed:
        return 'legs exchanged'
    if pair_crossing(track.joints, 'wrist') > 0:
        return 'arms exchanged'
    return PERIODIC_PROBE if since_probe >= settings.probe_period else None


def crossed_cost(cost, joints, limbs, settings):
    """A labelling's `cost` (SkeletonFitter.cost_of) raised by settings.crossed_cost_share, in full at a crossing
    of settings.crossed_by [m] and by as much less for less, for its pose's (joints (15, 3) [m]) knees crossed
    while crossing_judged (limbs: the fit's LimbTracks), and again for its wrists crossed (pair_crossing)."""
    knees = [pair_crossing(joints, 'knee')] if crossing_judged(joints, limbs, settings) else []
    for crossing in knees + [pair_crossing(joints, 'wrist')]:
        cost *= 1 + settings.crossed_cost_share * min(1.0, crossing / settings.crossed_by)
    return cost


def on_the_floor(heights, stature, ankle_height):
    """Whether ankles at `heights` [m] above the floor (a number or an array) stand on it: within STANCE_HEIGHT
    of the stature [m] of an ankle's height standing (ankle_height, a share of the stature)."""
    return np.asarray(heights) <= (ankle_height + STANCE_HEIGHT) * stature


def feet_outside(views, joints, stature, ankle_height):
    """Σ over the views with an outline (fitter.View) and the feet on the floor (STANCE_HEIGHT) of the
    squared distance [px²] (each capped at FOOT_CAP_PX) outside the silhouette of a point of the foot:
    FOOT_REACH × stature [m] ahead of the ankle, level, along the hips' forward direction
    (body.model.torso_frame), and half the ankle's height (ankle_height, a share of the stature) below it.
    Beyond the paper: a person's feet point the way the hips face, which the silhouette shows in every view
    that sees a foot from the side; with the true joints of the suite's 34 tuning cases (the 1561 of their
    1700 frame sets where the two sums differ), the body turned round has the larger sum in 98 % (by over
    400 px² in 93 %), the true one in 2 % (by over 400 px² in 2 %)."""
    forward = torso_frame(joints)[:, 0].copy()
    forward[2] = 0.0
    length = np.linalg.norm(forward)
    if length < 1e-6:   # the torso lying level, head first: the hips say nothing about the feet
        return 0.0
    ankles = joints[[JOINT_INDEX['left_ankle'], JOINT_INDEX['right_ankle']]]
    ankles = ankles[on_the_floor(ankles[:, 2], stature, ankle_height)]
    points = ankles + FOOT_REACH * stature * forward / length - (0.0, 0.0, 0.5 * ankle_height * stature)
    total = 0.0
    for view in views:
        if view.outline is not None:
            pixels, _ = view.camera.project(points)
            total += float(np.sum(np.minimum(outside_distances(view.outline, pixels), FOOT_CAP_PX) ** 2))
    return total


def unexplained_share(views, joints):
    """The share of the silhouettes' outline that the skeleton joints (15, 3) [m] does not explain: per view
    with an outline, its points further than LOST_MARGIN (in metres at the pelvis's depth) from every
    projected bone; the median over the views. 0 without outlines. Measured on the suite's 70 tuning cases
    (seeds 1-6) fitted by this code and by two variants that lose the person more often (9552 frame sets;
    docs/method.md, session 43): at most 9.6 % for fits within 80 mm of the truth (99.9th percentile 3.8 %,
    also with arms overhead, where the head and neck keypoints are 0.3-0.6 m off and cannot tell); 27 % of
    the fits over 200 mm off leave more than 15 % unexplained (a variant's walk with its pelvis 0.4 m high:
    27-30 % for 30 frame sets), 0.5 % more than 30 %; runs fitted 0.5-1.7 m off 30-70 %. A mirrored fit
    explains the outline as well as the right one (0-9 %), so this cannot see that (hypotheses.py does)."""
    shares = []
    for view in views:
        if view.outline is None or not len(view.outline.points):
            continue
        pixels, depths = view.camera.project(joints)
        _, residuals = nearest_capsules(view.outline.points, pixels[CAPSULE_ENDS[:, 0]], pixels[CAPSULE_ENDS[:, 1]],
                                        np.zeros(len(CAPSULE_ENDS)), np.zeros(len(CAPSULE_ENDS), np.bool_))
        metres = residuals * depths[JOINT_INDEX['pelvis']] / view.camera.K[0, 0]
        shares.append(float(np.mean(metres > LOST_MARGIN)))
    return float(np.median(shares)) if shares else 0.0
