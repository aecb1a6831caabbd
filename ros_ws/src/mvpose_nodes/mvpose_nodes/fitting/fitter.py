"""Fitting the 29-DOF skeleton to the features of several calibrated views (paper 000 Sec. 4–6).

Per frame set: the views' keypoints are triangulated (initialisation.triangulated_joints) and a view's
keypoint that disagrees with the others is left out, the joints triangulated again without it
(initialisation.consistent_evidence). The pose follows
from the previous frame's, moved on at the pelvis's velocity (after a gap of over velocity_horizon, when
frame sets were skipped to keep up: moved as far as the triangulated pelvis, its limbs started from the
frame's triangulated joints, after one of over continuity_horizon labelled by the side of the body they
are on), or, on the first frame, after a jump in time (not a gap in which frame sets were skipped to
keep up) and after the fit has lost the person (much of the outline unexplained for lost_frames fits),
from an initialisation (initialisation.py: the keypoints' triangulation turned into angles by paper
004's method, bone lengths from the template scaled to the estimated height, the legs' length measured).
Then six Nelder–Mead searches (Sec. 5.1, stage_search.py): torso, head and neck, left arm, right arm,
left leg, right leg, each over its own parameters with the rest fixed, each minimising its own objective.
Paper 000 Sec. 5.3 avoids local minima by good starts: each limb stage is searched from the previous
frame's pose and from the frame's own triangulated joints, and the better result kept. A (re)start also
searches each limb from canonical poses (limb_starts.py: raised, out, forward, hanging; a stride, seated),
each with the outline assigned from its own start and the results compared by how much of the outline
they leave unexplained (StageSearch.explained_cost), so that misread or missing hand keypoints do not
leave a raised arm folded down.

Left and right, front and back (beyond the paper; hypotheses.py): the same silhouettes fit a person and
the same points labelled the other way round, every pair exchanged (turned round), or one pair of limbs
exchanged. With the hips' and shoulders' turn, the thighs' adduction and the upper arms' reach across the
body limited as anatomy limits them (stage_search.TWIST_LIMITS), a bent knee or elbow no longer fits the
wrong way, nor do limbs crossed, so the objective tells them apart (and where the pose cannot, the way
the feet point in the silhouettes and the face the views see): after a start, every other labelling is
followed beside the fit for hypothesis_frames frame sets (those clearly worse dropped on the way:
hypothesis_prune), and the one whose fits explain the views best is kept; after that, one other labelling
at a time is followed so, every probe_period frame sets, and taken when it explains the views clearly
better. Every tuning constant is a field of settings.FitterSettings.
"""
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace

import numpy as np

from mvpose_nodes.body.camera import intrinsics, look_at
from mvpose_nodes.body.kinematics import BONES, bone_lengths, forward_kinematics, inverse_kinematics
from mvpose_nodes.body.model import JOINT_INDEX, LABEL_TORSO, PARAMETER_INDEX, STAGE_NAMES
from mvpose_nodes.fitting.compiled import pack_frame
from mvpose_nodes.fitting.hypotheses import (HYPOTHESES_POOL, RELABELLINGS, START_LABELLINGS, Track,
                                             crossed_cost, due_probe, face_away, feet_outside, relabelled_joints,
                                             relabelled_stages, unexplained_share)
from mvpose_nodes.fitting.initialisation import (
    completed_joints, consistent_evidence, face_tells, facing_right, labelled_joints, person_lengths, stature,
    tallest_measurements, triangulated_joints, upright)
from mvpose_nodes.fitting.limb_sides import LimbTracks, exchanged_pairs, oriented_view
from mvpose_nodes.fitting.limb_starts import limb_start_joints
from mvpose_nodes.fitting.settings import FitterSettings
from mvpose_nodes.fitting.stage_search import StageSearch, stage_indices
from mvpose_nodes.fitting.views import view_from_features, whole_views
from mvpose_nodes.vision.contour import SIDE_A, SIDE_B, ContourLabels

TORSO_POSITION = stage_indices('torso')[:3]   # torso_x, torso_y, torso_z: the root's position [m]
TORSO_YAW = PARAMETER_INDEX['torso_rz']   # the body's turn about the vertical [rad]
# A start's torso is also searched from its pose turned about the vertical by each of these [rad] (±45 and
# ±90 degrees: every line of facing within 22.5 degrees of one start; which way along it, front or back, the
# hypotheses decide): the facing from the keypoints (initialisation.completed_joints, the limbs' left-to-right
# offsets) is 40-90 degrees off for a runner or walker mid-stride, whose ankles and wrists lie apart along
# the way they go (in 20 of the suite's 46 tuning cases of seeds 1-4), and one search does not turn the
# torso that far (search_stages).
TORSO_START_YAWS = tuple(np.pi * eighth / 4 for eighth in (-2, -1, 1, 2))
HAIR_VIEWS = 500   # the person's hair_gap is measured on this many views (400 in a 50-frame case of 8 cameras), no more


@dataclass
class Fit:
    joints: np.ndarray           # (15, 3) [m]
    parameters: np.ndarray       # (29,)
    stages: list = field(default_factory=list)   # stage_search.StageResult, in STAGE_NAMES order
    initialised: bool = False    # a start: the fit is the best guess of the start's hypotheses so far
    seconds: float = 0.0
    lost: float = 0.0            # when the fit has lost the person: the outline's unexplained_share, else 0
    cameras: tuple = ()          # the numbers of the cameras whose views were fitted (views.whole_views)


class SkeletonFitter:
    """Frame-by-frame fitting: `fit(stamp_s, views) -> Fit`, keeping the pose and the person's size.
    settings: FitterSettings (default: the measured defaults); lengths: the person's bone lengths
    {length key (kinematics.LENGTH_FRACTIONS): [m]} when known beforehand, else None: measured at the
    first initialisation and on the upright frame sets after it (measure), afresh when time goes back;
    known_lengths: {length key: [m]} of some of them known beforehand, the others measured (a diagnosis:
    `eval suite --true-lengths KEY …` shows what measuring those costs)."""

    def __init__(self, settings=None, lengths=None, threads=1, known_lengths=None):
        self.settings = settings or FitterSettings()
        # The hypotheses' fits are independent of one another and spend most of their time in the compiled
        # search, which releases the GIL: with threads > 1 they run side by side (the same results); so do a
        # stage's searches from its several starts while one hypothesis is fitted (search_stages).
        self.local = threading.local()   # .worker: this thread is one of the pool's
        self.pool = ThreadPoolExecutor(threads, thread_name_prefix=HYPOTHESES_POOL,
                                       initializer=lambda: setattr(self.local, 'worker', True)) if threads > 1 else None
        self.lengths = None if lengths is None else dict(lengths)
        self.known_lengths = dict(known_lengths or {})
        # The person's measurements on upright frame sets (measure), while the lengths are not given.
        self.measurements = [] if lengths is None else None
        self.last_stamp = None
        # The stage searches, once the person's bone lengths are known.
        self.stages = None if lengths is None else StageSearch(self.settings, self.lengths)
        self.track = None     # the hypothesis followed as the fit (hypotheses.Track), None before a start
        self.given = None     # the Track whose fit was given out last (during a start: the cheapest so far)
        self.rivals = []      # other hypotheses followed beside it (hypotheses.py)
        self.window = 0       # frame sets left before they are compared with it
        self.starting = False  # the comparison is a start's (its fits are INITIALISING)
        self.since_probe = 0  # frame sets since the last probe ended
        self.lost_fits = 0    # consecutive fits that left much of the outline unexplained (unexplained_share)
        self.start_labels = None  # the start's triangulated joints, labelled (initial_parameters)
        self.face_right = None    # this frame set's person's right as the face says (initialisation.facing_right)
        self.legs_passed = False  # the fit's ankles have passed each other since the last probe of the legs
        self.last_apart = 0.0     # [m] how far apart the fit's ankles were in the last frame set followed
        self.last_found = None    # the last frame set's triangulated joints {name: (3,) [m]} (or None)
        self.hair_gaps = []       # the person's initialisation.hair_gap in every view so far (face_tells)

    @property
    def starts_next(self):
        """Whether the next fit starts (no fit yet, or the person lost; a jump in time shows only in its stamp)."""
        return self.track is None or self.lost_fits >= self.settings.lost_frames

    @property
    def parameters(self):
        """The 29 parameters of the last fit given out, or None before the first."""
        return None if self.given is None else self.given.parameters

    def fit(self, stamp, views, skipped=0):
        """The Fit of the views (views.View) of the frame set at `stamp` [s]; `skipped`: frame sets passed over since
        the last one (the node's, to keep up), which make a gap of any length no jump in time: the person was
        there throughout, so the fit follows on (re-initialised only if it loses the person) rather than
        start again; a start's comparison costs several fits, and on a slow machine a gap over time_jump after
        each would make every fit a start."""
        started = time.perf_counter()
        settings = self.settings
        views = whole_views(views, settings.cut_share)
        jump = (self.last_stamp is None or stamp < self.last_stamp
                or (stamp - self.last_stamp > settings.time_jump and not skipped))
        if self.last_stamp is not None and stamp < self.last_stamp and self.measurements is not None:
            # Time went back: another recording (a bag played again, or someone else's), measured afresh,
            # so that the same bag gives the same skeletons; nor is its last pose this recording's.
            self.lengths, self.stages, self.measurements, self.track, self.rivals = None, None, [], None, []
            self.given, self.last_found, self.hair_gaps = None, None, []
        self.last_stamp = stamp
        if len(self.hair_gaps) < HAIR_VIEWS:   # a person's hair does not change: a live feed's list stays short
            self.hair_gaps += [view.hair_gap for view in views if view.hair_gap is not None]
        if not face_tells(self.hair_gaps, settings.hair_gap):   # hair read as skin: no face to see
            views = [replace(view, frontness=None) for view in views]
        found = triangulated_joints(views, settings)
        self.face_right = None
        if found is not None:
            views, found = consistent_evidence(views, found, settings)
            self.measure(found)
            self.face_right = facing_right(views, found, settings.face_evidence)
        if jump or self.starts_next:
            self.start(stamp, views, found)
        else:
            comparing = bool(self.rivals)

            def follow(track):
                self.follow(track, stamp, views, found)
                if comparing:
                    track.cost += self.cost_of(track.parameters, views)
            self.each(follow, [self.track] + self.rivals)
            ankles = self.track.joints[[JOINT_INDEX['left_ankle'], JOINT_INDEX['right_ankle']]]
            apart = np.linalg.norm(ankles[0] - ankles[1])
            self.legs_passed |= apart < settings.crossing_distance
            if not self.rivals:
                self.since_probe += 1
                labelling = due_probe(self.track, self.lengths, apart, self.last_apart, self.legs_passed,
                                      self.since_probe, settings)
                if labelling == 'legs exchanged':
                    self.legs_passed = False
                if labelling is not None:
                    self.probe(stamp, views, found, labelling)
            self.last_apart = apart
        starting = self.starting
        if self.rivals:
            self.window -= 1
            self.prune()
            if self.window <= 0 or not self.rivals:
                self.compare()
        # Given out: while a start's hypotheses are compared, the one that explains the views best so far; else
        # the fit, which this frame set's pruning or comparison may just have replaced by a rival.
        track = min([self.track] + self.rivals, key=lambda t: t.cost) if self.starting else self.track
        self.given = track
        self.last_found = found
        unexplained = unexplained_share(views, track.joints)
        self.lost_fits = self.lost_fits + 1 if unexplained > settings.lost_share else 0
        return Fit(track.joints, track.parameters, track.results, starting, time.perf_counter() - started,
                   unexplained if self.lost_fits >= settings.lost_frames else 0.0, tuple(v.camera.number for v in views))

    def start(self, stamp, views, found):
        """A (re)start: the pose from the frame's keypoints (initial_parameters), fitted, and every other
        labelling of it (hypotheses.START_LABELLINGS) fitted beside it, to be compared over the next
        hypothesis_frames frame sets. ValueError when the keypoints are too few to start from."""
        start = self.initial_parameters(views, found)
        if start is None:
            raise ValueError('too few views with keypoints to initialise (need root, neck and head in 2 views)')
        self.track = Track(start, LimbTracks(self.settings))
        self.follow(self.track, stamp, views, found, canonical=True)
        self.track.cost = self.cost_of(self.track.parameters, views)
        self.rivals = self.each(lambda pairs: self.spawn(pairs, stamp, views, found),
                                [pairs for _, pairs in START_LABELLINGS])
        self.window, self.starting, self.lost_fits = self.settings.hypothesis_frames, True, 0

    def each(self, function, items):
        """[function(item) for item in items], on the thread pool if there is one and this is not one of its
        threads (which would wait for work queued behind its own; the calls must touch no state but their own
        item's)."""
        if self.pool is None or len(items) < 2 or getattr(self.local, 'worker', False):
            return [function(item) for item in items]
        return list(self.pool.map(function, items))

    def probe(self, stamp, views, found, labelling):
        """Follow `labelling` (a name of hypotheses.RELABELLINGS) beside the fit, from this frame set on."""
        self.track.cost = self.cost_of(self.track.parameters, views)
        self.rivals = [self.spawn(RELABELLINGS[labelling], stamp, views, found)]
        self.window, self.since_probe = self.settings.hypothesis_frames, 0

    def spawn(self, pairs, stamp, views, found):
        """A rival Track: this frame's fit with `pairs` exchanged, fitted from there (the frame's triangulated
        pairs exchanged alike), its cost so far that fit's."""
        rival = self.track.relabelled(pairs)
        rival.limbs.history = rival.limbs.history[:-1]   # this frame's fit, to be replaced by the rival's own
        start = inverse_kinematics(exchanged_pairs(self.track.joints, pairs))
        # The stages whose pairs stay as they were keep this frame's fit: the same joints, the same evidence.
        searched = relabelled_stages(pairs)
        kept = {stage: result for stage, result in zip(STAGE_NAMES, self.track.results) if stage not in searched}
        for stage in kept:
            start[stage_indices(stage)] = self.track.parameters[stage_indices(stage)]
        rival.parameters, rival.results = self.search_stages(start, views, relabelled_joints(found, pairs), kept=kept)
        rival.joints, _ = forward_kinematics(rival.parameters, self.lengths)
        rival.limbs.append(stamp, rival.joints)
        rival.cost = self.cost_of(rival.parameters, views)
        return rival

    def prune(self):
        """Drop the hypotheses whose fits so far cost over hypothesis_prune more than the cheapest's: the
        rivals, and the fit itself, whose place the cheapest rival then takes."""
        bound = (1 + self.settings.hypothesis_prune) * min(track.cost for track in [self.track] + self.rivals)
        self.rivals = [rival for rival in self.rivals if rival.cost <= bound]
        if self.track.cost > bound:
            self.track = min(self.rivals, key=lambda rival: rival.cost)
            self.rivals.remove(self.track)

    def compare(self):
        """End of a window (or of its rivals, pruned): the rival that cost the least over it replaces the
        fit if it cost hypothesis_margin less (at a start, any less: nothing is known yet)."""
        if self.rivals:
            best = min(self.rivals, key=lambda rival: rival.cost)
            margin = 0.0 if self.starting else self.settings.hypothesis_margin
            if best.cost < (1 - margin) * self.track.cost:
                self.track = best
        self.rivals, self.starting, self.since_probe = [], False, 0

    def follow(self, track, stamp, views, found, canonical=False):
        """Fit `track` to this frame set: from its last pose with the pelvis moved on (pelvis_shift; the
        smoothness prior centred there too), the frame's triangulated pairs labelled by its fits
        (LimbTracks.label);
        `canonical`: the limbs also searched from the canonical poses (a start)."""
        parameters = track.parameters.copy()
        labelled = None
        if track.limbs.history:
            parameters[TORSO_POSITION] += self.pelvis_shift(track.limbs, stamp, found)
            if found is not None:
                labelled = dict(found)
                track.limbs.label(stamp, labelled)
        elif found is not None:   # a start: the pairs as initial_parameters labelled them
            labelled = self.start_labels
        last = None
        # After a gap the last fit's limbs are half a stride away: the frame's triangulated ones are nearer.
        after_gap = track.limbs.after_gap(stamp)
        if after_gap and labelled is not None:
            parameters, last = self.triangulated_limbs(parameters, labelled), parameters
        carried = None if after_gap else track.limbs.carried_legs(stamp)
        stale = track.limbs.after_gap(stamp, self.settings.outline_horizon)
        track.parameters, track.results = self.search_stages(parameters, views, labelled, canonical, last, stale,
                                                             carried=carried)
        track.joints, _ = forward_kinematics(track.parameters, self.lengths)
        track.limbs.append(stamp, track.joints)

    def pelvis_shift(self, limbs, stamp, found):
        """How far (3,) [m] the pelvis has moved since the last fit of `limbs` (LimbTracks): on at the fits'
        velocity, or, when that fit is over velocity_horizon old (frame sets skipped to keep up), as far as
        the triangulated pelvis has moved since then (`found`: this frame set's triangulated joints), since
        a walker's velocity from fits half a second apart misses by a stride."""
        shift = pelvis_displacement(self.last_found, found)
        if shift is not None and limbs.after_gap(stamp):
            return shift
        pelvis = JOINT_INDEX['pelvis']
        return limbs.predicted(stamp)[pelvis] - limbs.history[-1][1][pelvis]

    def cost_of(self, parameters, views):
        """How well the pose `parameters` (29,) explains the views: the six stages' objectives (without the
        smoothness prior, with the joint limits) with each view's left/right labels oriented to the pose
        and the outline assigned from it; raised by up to face_cost_share as far as the pose's hips face away
        from the face the views see (face_right; hypotheses.face_away), by up to crossed_cost_share as far as its
        wrists cross, and its knees with the feet together while standing (hypotheses.crossed_cost: the speed is
        the fit's), and by foot_weight per px² of its feet outside the silhouettes (hypotheses.feet_outside)."""
        joints, _ = forward_kinematics(parameters, self.stages.lengths)
        oriented = [oriented_view(view, joints) for view in views]
        frame = pack_frame(oriented)
        nearest = self.stages.outline_nearest(parameters, frame)
        cost = sum(self.stages.posed_cost(stage, parameters, oriented, frame, nearest) for stage in STAGE_NAMES)
        if self.face_right is not None:
            cost *= 1 + self.settings.face_cost_share * face_away(joints, self.face_right)
        cost = crossed_cost(cost, joints, self.track.limbs, self.settings)
        if self.settings.foot_weight:
            cost += self.settings.foot_weight * feet_outside(views, joints, stature(self.lengths),
                                                             self.settings.ankle_height)
        return cost

    def search_stages(self, parameters, views, found, canonical=False, last=None, stale=False, kept=None, carried=None):
        """The six stages of paper 000 Sec. 5.1 from `parameters` (29,); each stage after the torso's searched
        also from the frame's triangulated joints `found` ({joint: (3,)} or None) and, with `canonical` (a
        start), the torso also from its pose turned by TORSO_START_YAWS and each limb stage from the
        canonical limb poses (limb_starts.py), the best result kept (Sec. 5.3). `last`: the last fit's
        parameters when `parameters` are already the triangulated limbs (a gap over velocity_horizon);
        `stale`: the last fit is over outline_horizon old; `kept`: {stage: StageResult} of stages not
        searched, `parameters` already their fit; `carried`: knees and ankles {name: (3,)} carried on from the
        last fits (LimbTracks.carried_legs), the leg stages also searched from them. Returns the fitted
        parameters and the stage_search.StageResults."""
        reference, _ = forward_kinematics(parameters, self.lengths)
        if found is not None:
            for name, position in found.items():
                reference[JOINT_INDEX[name]] = position
        alternatives = None
        # Starts far apart, or the last fit's outline assignment stale: each search's outline assigned from its own.
        afresh = canonical or last is not None or stale
        oriented = [oriented_view(view, reference) for view in views]
        frame = pack_frame(oriented)
        results = []
        for stage in STAGE_NAMES:
            if kept and stage in kept:
                results.append(kept[stage])
                continue
            assigned = self.stages.outline_assignment(stage, parameters, oriented, frame)
            if stage == 'torso' and canonical:
                def search_turned(yaw):
                    turned = parameters.copy()
                    turned[TORSO_YAW] += yaw
                    return self.stages.search(stage, turned, oriented, assigned, frame)
                # One assignment (from the start's pose) for all: their costs compare as they are.
                searched, result = min(self.each(search_turned, (0.0,) + TORSO_START_YAWS),
                                       key=lambda outcome: outcome[1].cost)
            elif stage == 'torso' or (found is None and not canonical):
                searched, result = self.stages.search(stage, parameters, oriented, assigned, frame)
            else:
                if alternatives is None:   # starts relative to the fitted torso
                    alternatives = self.alternative_starts(parameters, found, canonical, last, carried)
                def search_from(start):
                    if start is None:
                        return self.stages.search(stage, parameters, oriented, assigned, frame)
                    alternative = parameters.copy()
                    alternative[stage_indices(stage)] = start[stage_indices(stage)]
                    # From a canonical start the outline is assigned from that pose: a raised arm's outline
                    # is nobody's in a pose with the arm down, and nothing would pull the arm up to it.
                    own = self.stages.outline_assignment(stage, alternative, oriented, frame) if afresh else assigned
                    return self.stages.search(stage, alternative, oriented, own, frame)
                outcomes = self.each(search_from, [None] + alternatives[stage])
                def rank(outcome):   # searches with their own outline assignments: one footing
                    return self.stages.explained_cost(stage, outcome[0], oriented, frame) if afresh \
                        else outcome[1].cost
                searched, result = min(outcomes, key=rank)
            parameters = searched
            results.append(result)
        return parameters, results

    def alternative_starts(self, parameters, found, canonical, last=None, carried=None):
        """{stage: [parameters (29,), ...]} to search each stage after the torso's from, besides `parameters`:
        the limbs' triangulated joints `found` as angles relative to the fitted torso (or, when `parameters`
        already has them, `last`: the last fit's limbs), with `canonical` the canonical limb poses
        (limb_starts.limb_start_joints) for the limb stages, and for the leg stages the knees and ankles
        `carried` on from the last fits, relative to the fitted torso too."""
        starts = {stage: [] for stage in STAGE_NAMES[1:]}
        if found is not None:
            candidate = self.triangulated_limbs(parameters, found) if last is None else last
            for stage in starts:
                starts[stage].append(candidate)
        if canonical:
            fitted, _ = forward_kinematics(parameters, self.lengths)
            arms, legs = limb_start_joints(fitted)
            for posed, stages in ((arms, ('left_arm', 'right_arm')), (legs, ('left_leg', 'right_leg'))):
                for candidate in map(inverse_kinematics, posed):
                    for stage in stages:
                        starts[stage].append(candidate)
        if carried is not None:
            candidate = self.triangulated_limbs(parameters, carried)
            for stage in ('left_leg', 'right_leg'):
                starts[stage].append(candidate)
        return starts

    def triangulated_limbs(self, parameters, found):
        """The pose `parameters` (29,) with its limbs and head moved to the triangulated joints `found`
        ({name: (3,)}; those it has), as angles relative to its torso (paper 004)."""
        hybrid, _ = forward_kinematics(parameters, self.lengths)
        for name, position in found.items():
            if name not in ('pelvis', 'neck'):
                hybrid[JOINT_INDEX[name]] = position
        return inverse_kinematics(hybrid)

    def measure(self, joints):
        """Measure the person on triangulated joints {name: (3,) [m]} if they stand upright
        (initialisation.upright) and fewer than length_frames measurements are within stature_spread of the
        tallest: the bone lengths become their median (initialisation.tallest_measurements), as knees bend
        while walking and a crouch shortens; so neither a first frame set crouched, sitting or with raised
        arms nor one rough triangulation sets them, and a person seen seated first (a seated silhouette's
        centroid passes `upright`) is measured again once standing. Once there is a fit, the legs are
        measured from its pelvis's height (the torso fitted to the views' outlines), not from the root
        keypoint's: that is the silhouettes' centroid, 7-112 mm below the pelvis for the suite's CMU walkers,
        up to 270 mm above it with the arms raised (session 29), and the legs measured from it as much too
        short or too long. Upright is either pelvis's verdict: the fit's alone would never measure again after
        a start crouched (its short lengths keep the fits low), the root's alone not one whose centroid is off."""
        spread, enough, support = self.settings.stature_spread, self.settings.length_frames, self.settings.stature_support
        if self.measurements is None or len(tallest_measurements(self.measurements, spread, support)) >= enough:
            return
        measured = joints
        if self.given is not None:
            measured = dict(joints)
            measured['pelvis'] = np.r_[joints['pelvis'][:2], self.given.joints[JOINT_INDEX['pelvis'], 2]]
        if not (upright(measured, self.settings) or upright(joints, self.settings)):
            return
        self.measurements.append(person_lengths(measured, self.settings))
        standing = tallest_measurements(self.measurements, spread, support)
        self.use_measured({key: float(np.median([m[key] for m in standing])) for key in standing[0]})

    def use_measured(self, lengths):
        """Fit with the measured bone `lengths` {length key: [m]}, those in known_lengths replaced by their
        known values."""
        self.lengths = {**lengths, **self.known_lengths}
        self.stages = StageSearch(self.settings, self.lengths)

    def initial_parameters(self, views, found):
        """Angles (29,) from the frame's triangulated joints `found` (paper 000 Sec. 3.1 and 6; paper 004), or
        None without them: the pairs labelled by the face where a view sees it (initialisation.labelled_joints;
        the hypotheses try the other labellings), the rest completed from the template. The first
        initialisation also measures the person (initialisation.person_lengths)."""
        if found is None:
            return None
        self.start_labels = labelled_joints(views, found, self.settings)
        if self.lengths is None:  # measured whatever the posture, until an upright frame set measures better
            self.use_measured(person_lengths(found, self.settings))
        return inverse_kinematics(completed_joints(self.start_labels, self.lengths))


def pelvis_displacement(before, after):
    """The triangulated pelvis's displacement (3,) [m] between two frame sets' triangulated joints
    {name: (3,)} (each or None), or None unless both have it."""
    if before is None or after is None or 'pelvis' not in before or 'pelvis' not in after:
        return None
    return after['pelvis'] - before['pelvis']


def warm_up():
    """Run the compiled search once on a made-up frame (a block seen by two cameras, torso stage), so that
    numba loads it from its disk cache, or compiles it on a machine's first run (about 10 s), now rather
    than in the first fit. The nodes call this while they start."""
    lengths = bone_lengths(1.75)
    block = np.array([(x, y) for x in range(40, 61) for y in (20, 80)] + [(x, y) for y in range(21, 80) for x in (40, 60)])
    contour = ContourLabels(block.astype(np.int32), np.full(len(block), LABEL_TORSO, np.uint8),
                            np.where(block[:, 0] < 50, SIDE_A, SIDE_B).astype(np.uint8))
    views = [view_from_features(look_at(number, (3.0 * side, -3.0, 1.0), (0.0, 0.0, 1.0), intrinsics(100.0, 100, 100),
                                        100, 100), {'root': (50.0, 50.0, 1.0)}, contour)
             for number, side in ((1, -1), (2, 1))]
    parameters = inverse_kinematics(forward_kinematics(np.r_[0.0, 0.0, 1.0, np.zeros(26)], lengths)[0])
    stages = StageSearch(FitterSettings(), lengths)
    frame = pack_frame(views)
    stages.search('torso', parameters, views, stages.outline_assignment('torso', parameters, views, frame), frame)
