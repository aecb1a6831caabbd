"""One synchronised frame set of feature messages -> one mvpose_msgs/Skeleton, as the skeleton_fitter
node publishes it. The node only wires topics to this; `./mvpose eval suite` calls the same code on
features it computes itself, so the suite measures exactly what the node would publish.

The status (Skeleton.STATUS_*): INITIALISING on a frame that (re)started the fit from the keypoints;
DEGRADED when a configured camera gave nothing usable or a stage had no evidence; LOST when fewer than
two cameras see the person (the joints repeat the last fitted pose), or
when the fit has lost the person (fitter.Fit.lost: the joints are that fit, and the next frame set
re-initialises); OK otherwise. Before the first fit, a frame set the keypoints cannot initialise from
gets INITIALISING with a best guess (initialisation.guessed_parameters: standing at the root keypoint) if
any camera sees the person, and nothing if none does.
"""
from dataclasses import dataclass

from mvpose_msgs.msg import LabelledContour, Skeleton, SkinEllipse

from mvpose_nodes.body.kinematics import bone_lengths, forward_kinematics
from mvpose_nodes.body.model import PARAMETER_NAMES
from mvpose_nodes.fitting.fitter import SkeletonFitter
from mvpose_nodes.fitting.views import frame_set_arena, view_from_features
from mvpose_nodes.fitting.initialisation import TEMPLATE_HEIGHT, guessed_parameters
from mvpose_nodes.ros.conversions import (contour_from_message, keypoints_from_messages, skeleton_message,
                                          stage_messages)
from mvpose_nodes.ros.diagnostics import StageClock
from mvpose_nodes.vision.features import ellipse_top


@dataclass
class FrameSetResult:
    """What one frame set gave: the Skeleton to publish (None: nothing to publish), its 29 parameters,
    problems [(cause, text)] worth logging once per cause, and whether the Skeleton is a best guess, not a fit."""
    message: object = None
    parameters: object = None
    problems: list = None
    guessed: bool = False


@dataclass
class PreparedSet:
    """One frame set ready to fit (FrameSetFitter.prepare): its stamp [ns], the fitter.Views of the cameras
    with a person, problems [(cause, text)] met converting them, and the configured cameras the
    synchroniser left out."""
    stamp_ns: int
    views: list
    problems: list
    missing_cameras: tuple = ()


class FrameSetFitter:
    """The skeleton fitter behind the node: `settings` (fitting.settings.FitterSettings), the configured
    camera numbers, the StageClock that counts the CPU of its stages ('conversion', 'distance maps',
    'fit'), the person's bone lengths if known (SkeletonFitter's `lengths`, or some of them: `known_lengths`)
    and the threads that fit its hypotheses (SkeletonFitter's `threads`)."""

    def __init__(self, settings, cameras, clock=None, lengths=None, threads=1, known_lengths=None):
        self.fitter = SkeletonFitter(settings, lengths, threads, known_lengths)
        self.cameras = list(cameras)
        self.clock = clock or StageClock()

    @property
    def starts_next(self):
        """Whether the next frame set fitted starts the fit (SkeletonFitter.starts_next)."""
        return self.fitter.starts_next

    def fit(self, stamp_ns, features, missing_cameras=(), skipped=0):
        """features: {camera number: (body.camera.Camera or None while its calibration is missing,
        SkinEllipseArray, LabelledContour)} of the cameras that sent this frame set; missing_cameras:
        configured cameras left out by the synchroniser (silent); skipped: frame sets skipped since the
        last one (real time: fitting.sync.PendingSets), said in the status_message. A FrameSetResult."""
        return self.fit_prepared(self.prepare(stamp_ns, features, missing_cameras), skipped)

    def prepare(self, stamp_ns, features, missing_cameras=()):
        """The first half of `fit` (same arguments): the messages converted into the views' evidence
        (distance maps, outlines, keypoints). A PreparedSet for fit_prepared; the node runs the two
        halves in two threads, so that one frame set's maps are made while the previous one is fitted."""
        problems, converted = [], []
        for number in self.cameras:
            if number not in features:
                continue
            camera, ellipses, contour = features[number]
            if camera is None or contour.status != LabelledContour.STATUS_OK:
                continue
            with self.clock('conversion'):
                try:
                    labels = contour_from_message(contour)
                except ValueError as error:
                    problems.append((f'contour {number}', f'/cam{number}/labelled_contour: {error}; dropped'))
                    continue
                skin = [(e.center_x, e.center_y, e.area) for e in ellipses.ellipses]
                faces = [ellipse_top(e.center_y, e.semi_major, e.semi_minor, e.angle)
                         for e in ellipses.ellipses if e.role == SkinEllipse.ROLE_FACE]
                converted.append((camera, keypoints_from_messages(ellipses, contour), labels,
                                  ellipses.face_visibility, skin, faces[0] if faces else None))
        with self.clock('distance maps'):
            arena = frame_set_arena([labels for _, _, labels, _, _, _ in converted])
            views = [view_from_features(*parts, arena=arena) for parts in converted]
        return PreparedSet(stamp_ns, views, problems, tuple(missing_cameras))

    def fit_prepared(self, prepared, skipped=0):
        """The second half of `fit`: the PreparedSet fitted. A FrameSetResult."""
        stamp_ns, views, problems = prepared.stamp_ns, prepared.views, list(prepared.problems)
        skipped_text = f'{skipped} stale frame set(s) skipped before this one' if skipped else ''
        if len(views) < 2:
            return self.lost(stamp_ns, problems, 'few views',
                             joined(f'fewer than 2 cameras with a person at {stamp_ns} ns', skipped_text), views)
        try:
            with self.clock('fit'):
                fit = self.fitter.fit(stamp_ns / 1e9, views, skipped)
        except ValueError as error:
            return self.lost(stamp_ns, problems, 'fit', joined(f'no fit at {stamp_ns} ns: {error}', skipped_text), views)
        used = set(fit.cameras)   # without the views the fitter left out (cut off: views.whole_views)
        degraded = bool(prepared.missing_cameras) or used != set(self.cameras) or not all(s.fitted for s in fit.stages)
        status = (Skeleton.STATUS_LOST if fit.lost else Skeleton.STATUS_INITIALISING if fit.initialised
                  else Skeleton.STATUS_DEGRADED if degraded else Skeleton.STATUS_OK)
        reason = joined(f'lost: the fit leaves {100 * fit.lost:.0f} % of the outline unexplained; re-initialising'
                        if fit.lost else f'cameras used: {sorted(used)}' if degraded else '', skipped_text)
        with self.clock('conversion'):
            message = skeleton_message(fit.joints, stamp_ns, parameter_names=list(PARAMETER_NAMES),
                                       parameters=fit.parameters.tolist(), stages=stage_messages(fit.stages),
                                       status=status, status_message=reason, fit_time=fit.seconds)
        return FrameSetResult(message, fit.parameters, problems)

    def lost(self, stamp_ns, problems, cause, reason, views):
        """STATUS_LOST repeating the last fitted pose; before the first fit, STATUS_INITIALISING with a best
        guess from the `views` (fitter.View) if one sees the person, else no message."""
        problems.append((cause, f'{reason} (logged once; STATUS_LOST with the last pose while it lasts, '
                                'a standing guess before the first fit)'))
        parameters, lengths, status = self.fitter.parameters, self.fitter.lengths, Skeleton.STATUS_LOST
        if parameters is None:
            lengths = lengths or bone_lengths(TEMPLATE_HEIGHT)
            parameters = guessed_parameters(views, lengths, self.fitter.settings.ankle_height)
            if parameters is None:
                return FrameSetResult(None, None, problems)
            status, reason = Skeleton.STATUS_INITIALISING, f'best guess (standing at the root keypoint): {reason}'
        joints, _ = forward_kinematics(parameters, lengths)
        message = skeleton_message(joints, stamp_ns, parameter_names=list(PARAMETER_NAMES),
                                   parameters=parameters.tolist(), status=status, status_message=reason)
        return FrameSetResult(message, parameters, problems, guessed=status == Skeleton.STATUS_INITIALISING)


def joined(*parts):
    """The non-empty parts of a status_message, joined by '; '."""
    return '; '.join(part for part in parts if part)
