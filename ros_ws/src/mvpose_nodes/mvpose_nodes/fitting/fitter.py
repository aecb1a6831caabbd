"""Fitting the 29-DOF skeleton to the features of several calibrated views (paper 000 Sec. 4–6).

Per frame: start from the previous frame's pose, moved on at the pelvis's velocity, or, on the first
frame, after a jump in time and after the fit has lost the person (much of the outline unexplained
for lost_frames fits), from an initialisation (initialisation.py: the 2D keypoints triangulated across
views, turned into angles by paper 004's method, bone lengths from the template scaled to the
estimated height, the legs' length measured); label left and right (limb_sides.py; at a start, limbs
fitted on the torso's wrong side are put on their own and fitted again: SkeletonFitter.sided); then six
Nelder–Mead searches (Sec. 5.1, stage_search.py): torso, head and neck, left arm, right arm, left leg,
right leg, each over its own parameters with the rest fixed, each minimising its own objective. Paper
000 Sec. 5.3: local minima are avoided by starting each limb stage from whichever fits better of the
previous frame's pose and the frame's own triangulated joints. When the feet have said for a while
that the fit faces backwards (limb_sides.foot_evidence), the searches are done again the other way round.
Every tuning constant is a field of settings.FitterSettings.
"""
import time
from dataclasses import dataclass, field

import numpy as np

from mvpose_nodes.body.camera import intrinsics, look_at
from mvpose_nodes.body.kinematics import bone_lengths, forward_kinematics, inverse_kinematics
from mvpose_nodes.body.model import JOINT_INDEX, LABEL_TORSO, STAGE_NAMES
from mvpose_nodes.fitting.compiled import MAP_LABELS, nearest_capsules, pack_frame
from mvpose_nodes.fitting.initialisation import (PAIRED_LIMBS, completed_joints, labelled_joints, person_lengths,
                                                 stature, triangulated_joints, upright)
from mvpose_nodes.fitting.limb_sides import (SWAPPABLE, FacingWatch, LimbTracks, exchange, face_votes, facing_travel,
                                             exchanged_pairs, foot_evidence, mirrored_joints, oriented_view,
                                             torso_right, wrong_sided)
from mvpose_nodes.fitting.objective import MapArena, boundary_distances, map_floats, outline_of
from mvpose_nodes.fitting.settings import FitterSettings
from mvpose_nodes.fitting.stage_search import CAPSULE_ENDS, StageSearch, stage_indices
from mvpose_nodes.vision.contour import SIDE_A, SIDE_B, ContourLabels

TORSO_POSITION = stage_indices('torso')[:3]   # torso_x, torso_y, torso_z: the root's position [m]
LOST_MARGIN = 0.25  # [m] an outline point this far from every bone is not explained by the skeleton


@dataclass
class View:
    """One camera's evidence for one frame: its Camera, the boundary distance maps of its labelled
    contour (objective.BoundaryDistances, or None), its 2D keypoints {name: (x, y, confidence)}, how
    much of the face it sees (features.Features.frontness; None if unknown), its outline
    (objective.Outline, or None) and its skin regions (N, 3): centre x, y [px] and area [px²] (or None)."""
    camera: object
    distances: object
    keypoints: dict
    frontness: float = None
    outline: object = None
    skin: np.ndarray = None


@dataclass
class Fit:
    joints: np.ndarray           # (15, 3) [m]
    parameters: np.ndarray       # (29,)
    stages: list = field(default_factory=list)   # stage_search.StageResult, in STAGE_NAMES order
    initialised: bool = False
    seconds: float = 0.0
    lost: float = 0.0            # when the fit has lost the person: the outline's unexplained_share, else 0


class SkeletonFitter:
    """Frame-by-frame fitting: `fit(stamp_s, views) -> Fit`, keeping the pose and the person's size.
    settings: FitterSettings (default: the measured defaults); lengths: the person's bone lengths
    {length key (kinematics.LENGTH_FRACTIONS): [m]} when known beforehand, else None: measured at the
    first initialisation and on the upright frame sets after it (measure), afresh when time goes back."""

    def __init__(self, settings=None, lengths=None):
        self.settings = settings or FitterSettings()
        self.parameters = None
        self.lengths = None if lengths is None else dict(lengths)
        # The person's measurements on upright frame sets (measure), while the lengths are not given.
        self.measurements = [] if lengths is None else None
        self.last_stamp = None
        self.tracks = LimbTracks(self.settings)
        # The stage searches, once the person's bone lengths are known.
        self.stages = None if lengths is None else StageSearch(self.settings, self.lengths)
        self.turns = 0   # times the torso was turned to face the direction of travel (facing_travel)
        self.facing = FacingWatch(self.settings)
        self.flips = 0   # times the fit was turned round because the feet pointed backwards
        self.lost_fits = 0   # consecutive fits that left much of the outline unexplained (unexplained_share)

    def fit(self, stamp, views):
        started = time.perf_counter()
        settings = self.settings
        jump = self.last_stamp is None or stamp < self.last_stamp or stamp - self.last_stamp > settings.time_jump
        if self.last_stamp is not None and stamp < self.last_stamp and self.measurements is not None:
            # Time went back: another recording (a bag played again, or someone else's), measured afresh,
            # so that the same bag gives the same skeletons; nor is its last pose this recording's.
            self.lengths, self.stages, self.measurements, self.parameters = None, None, [], None
        self.last_stamp = stamp
        initialised = False
        if self.parameters is None or jump or self.lost_fits >= settings.lost_frames:
            start = self.initial_parameters(views)
            if start is None:
                raise ValueError('too few views with keypoints to initialise (need root, neck and head in 2 views)')
            self.parameters, initialised = start, True
            self.lost_fits = 0
            self.tracks.restart()
            self.facing.clear()
        self.stages.new_frame()
        parameters = self.parameters.copy()
        predicted = None if initialised else self.tracks.predicted(stamp)
        if predicted is not None:  # the body moves on at its speed (5 cm a frame walking): start, and
            # centre the smoothness prior, where it will be, not where it was
            pelvis = JOINT_INDEX['pelvis']
            parameters[TORSO_POSITION] += predicted[pelvis] - self.tracks.history[-1][1][pelvis]
        found = None if initialised else triangulated_joints(views, settings)
        if not initialised:
            turned, turn = facing_travel(parameters, self.lengths, self.tracks.walking_right(),
                                         np.radians(settings.travel_yaw_limit_deg))
            # People walk forwards, unless the faces the views see say otherwise (walking backwards).
            if turn and (face_votes(views, forward_kinematics(turned, self.lengths)[0])
                         >= face_votes(views, forward_kinematics(parameters, self.lengths)[0])):
                parameters = turned
                self.turns += 1
        if found is not None:
            self.tracks.label(stamp, found, torso_right(forward_kinematics(parameters, self.lengths)[0]))
            self.measure(found)
        parameters, results = self.search_stages(parameters, views, found)
        joints, _ = forward_kinematics(parameters, self.lengths)
        if initialised:
            parameters, results, joints = self.sided(parameters, results, joints, views)
        self.facing.append(foot_evidence(views, joints))
        if self.facing.wrong():  # turn round: the same points, every pair the other way
            for limb in PAIRED_LIMBS:
                exchange(found or {}, limb)
            self.tracks.mirror()
            self.facing.clear()
            self.flips += 1
            parameters, results = self.search_stages(inverse_kinematics(mirrored_joints(joints)), views, found)
            joints, _ = forward_kinematics(parameters, self.lengths)
        self.parameters = parameters
        self.tracks.append(stamp, joints)
        unexplained = unexplained_share(views, joints)
        self.lost_fits = self.lost_fits + 1 if unexplained > settings.lost_share else 0
        return Fit(joints, parameters, results, initialised, time.perf_counter() - started,
                   unexplained if self.lost_fits >= settings.lost_frames else 0.0)

    def sided(self, parameters, results, joints, views):
        """At a (re)start, where the pairs were labelled by a cue as rough as the face (initial_parameters):
        the groups of limbs fitted on the torso's wrong side (limb_sides.wrong_sided) exchanged and the stages
        searched again from there. Returns (parameters, results, joints)."""
        groups = wrong_sided(joints)
        if not groups:
            return parameters, results, joints
        exchanged = exchanged_pairs(joints, [name for group in groups for name in SWAPPABLE[group]])
        self.tracks.exchanges += len(groups)
        # Started from the exchanged pose, with it as the frame's joints too: the stages' own choice between
        # the two (search_stages) would go back, as the objective explains either labelling about as well.
        found = {name: exchanged[JOINT_INDEX[name]] for name in ('pelvis', 'neck', 'head', *(
            f'{side}_{limb}' for limb in PAIRED_LIMBS for side in ('left', 'right')))}
        parameters, results = self.search_stages(inverse_kinematics(exchanged), views, found)
        return parameters, results, forward_kinematics(parameters, self.lengths)[0]

    def search_stages(self, parameters, views, found):
        """The six stages of paper 000 Sec. 5.1 from `parameters` (29,), each limb stage started from
        whichever fits better of them and the frame's triangulated joints `found` ({joint: (3,)} or
        None) (Sec. 5.3). Returns the fitted parameters and the stage_search.StageResults."""
        reference, _ = forward_kinematics(parameters, self.lengths)
        if found is not None:
            for name, position in found.items():
                reference[JOINT_INDEX[name]] = position
        candidate = None
        oriented = [oriented_view(view, reference) for view in views]
        frame = pack_frame(oriented)
        results = []
        for stage in STAGE_NAMES:
            if found is not None and stage != 'torso' and candidate is None:
                # The limbs' triangulated joints, as angles relative to the fitted torso.
                hybrid, _ = forward_kinematics(parameters, self.lengths)
                for name, position in found.items():
                    if name not in ('pelvis', 'neck'):
                        hybrid[JOINT_INDEX[name]] = position
                candidate = inverse_kinematics(hybrid)
            assigned = self.stages.outline_assignment(stage, parameters, oriented)
            if found is not None and stage != 'torso':
                indices = stage_indices(stage)
                alternative = parameters.copy()
                alternative[indices] = candidate[indices]
                pack = self.stages.stage_pack(stage, parameters, oriented, assigned, priors=False)
                if (self.stages.compiled_cost(stage, alternative, oriented, assigned, frame, pack)[0]
                        < self.stages.compiled_cost(stage, parameters, oriented, assigned, frame, pack)[0]):
                    parameters = alternative
            parameters, result = self.stages.search(stage, parameters, oriented, assigned, frame)
            results.append(result)
        return parameters, results

    def measure(self, joints):
        """Measure the person on triangulated joints {name: (3,) [m]} if they stand upright
        (initialisation.upright) and fewer than length_frames frame sets have measured them: the bone
        lengths become the median of the measurements (initialisation.person_lengths) whose stature is
        within stature_spread of the tallest, as knees bend while walking and a crouch shortens; so
        neither a first frame set crouched, sitting or with raised arms nor one rough triangulation
        sets them."""
        if (self.measurements is None or len(self.measurements) >= self.settings.length_frames
                or not upright(joints, self.settings)):
            return
        self.measurements.append(person_lengths(joints, self.settings))
        tallest = max(stature(m) for m in self.measurements)
        standing = [m for m in self.measurements if stature(m) >= (1 - self.settings.stature_spread) * tallest]
        self.lengths = {key: float(np.median([m[key] for m in standing])) for key in self.lengths}
        self.stages = StageSearch(self.settings, self.lengths)

    def initial_parameters(self, views):
        """Angles (29,) from triangulated keypoints (paper 000 Sec. 3.1 and 6; paper 004), or None: the
        pairs labelled by the face where a view sees it (initialisation.labelled_joints), or all the other
        way round (the torso facing the other way) when the skin in the views' heads says so better
        (limb_sides.face_votes). The first initialisation also measures the person
        (initialisation.person_lengths)."""
        joints = labelled_joints(views, self.settings)
        if joints is None:
            return None
        if self.lengths is None:  # measured whatever the posture, until an upright frame set measures better
            self.lengths = person_lengths(joints, self.settings)
            self.stages = StageSearch(self.settings, self.lengths)
        self.measure(joints)
        mirrored = dict(joints)
        for limb in PAIRED_LIMBS:
            exchange(mirrored, limb)
        starts = [completed_joints(labelled, self.lengths) for labelled in (joints, mirrored)]
        feet = foot_evidence(views, starts[0])
        if abs(feet) >= self.settings.facing_evidence:
            best = 0 if feet > 0 else 1
        else:
            best = max(range(2), key=lambda k: (face_votes(views, starts[k]), -k))
        return inverse_kinematics(starts[best])


def unexplained_share(views, joints):
    """The share of the silhouettes' outline that the skeleton joints (15, 3) [m] does not explain: per view
    with an outline, its points further than LOST_MARGIN (in metres at the pelvis's depth) from every
    projected bone; the median over the views. 0 without outlines. Measured on the suite's tuning cases:
    0-4 % for fits that follow the person (also with arms overhead, where the head and neck keypoints are
    0.3-0.6 m off and cannot tell), 30-70 % for runs fitted 0.5-1.7 m off; a mirrored fit explains the
    outline as well as the right one (0-9 %), so this cannot see that (limb_sides.foot_evidence does)."""
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


def view_from_features(camera, keypoints, contour, frontness=None, skin=None, arena=None):
    """A View of one camera from its features: keypoints {name: (x, y, confidence)} (the visible ones),
    its ContourLabels (or None), its frontness and its skin regions [(x, y, area)] (the skin ellipses'
    centres [px] and areas [px²]); its distance maps in `arena` (objective.MapArena, sized by
    frame_set_arena) if given."""
    distances = outline = None
    if contour is not None and len(contour.points):
        distances = boundary_distances(contour, (camera.width, camera.height), MAP_LABELS, arena=arena)
        outline = outline_of(contour.points, arena=arena)
    skin = None if skin is None else np.asarray(skin, float).reshape(-1, 3)
    return View(camera, distances, keypoints, frontness, outline, skin)


def frame_set_arena(contours):
    """The objective.MapArena for the views of a frame set's ContourLabels (None for a camera without)."""
    return MapArena(sum(map_floats(c.points, 2 * len(MAP_LABELS)) for c in contours if c is not None))


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
    stages.new_frame()
    stages.search('torso', parameters, views, stages.outline_assignment('torso', parameters, views), pack_frame(views))
