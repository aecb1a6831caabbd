"""The skeleton fitter's tuning constants in one place, each with its unit, range and reason.

`FitterSettings` is what `SkeletonFitter(settings)` reads; the skeleton_fitter node exposes every field
as a ROS parameter of the same name (ros/params.py builds the table from this dataclass: description
and range come from each field's metadata), so a user can see and change them with `ros2 param`.
The defaults are the values measured on the synthetic studio (docs/method.md).
"""
from dataclasses import dataclass, field, fields


def setting(default, description, low, high):
    """A dataclass field with the description and (low, high) range a ROS parameter declares."""
    return field(default=default, metadata={'description': description, 'range': (low, high)})


@dataclass(frozen=True)
class FitterSettings:
    # The objective's terms (fitting/stage_search.py; paper 000 Eq. 4-5 and beyond the paper).
    enclosure_weight: float = setting(
        1.0, "weight of Eq. 4's 'stay on the part' term against the distance to the part's sides", 0.0, 100.0)
    outline_weight: float = setting(
        1 / 9, "per px² of the outline objective's Cauchy cost, per contour pixel", 0.0, 100.0)
    inside_weight: float = setting(1.0, "per px² of a bone's sample point outside the silhouette", 0.0, 100.0)
    outline_scale: float = setting(10.0, "[px] scale of the Cauchy loss of an outline point's residual", 0.1, 1000.0)
    outline_gate: float = setting(
        20.0, '[px] outline points farther than this from every capsule are left out of a stage', 0.1, 1000.0)
    boundary_weight: float = setting(
        0.1, 'per pixel of Eq. 4 (a sum over N = 100 points), against keypoint_weight per keypoint pixel', 0.0, 100.0)
    keypoint_weight: float = setting(
        20.0, 'a pixel of keypoint error costs as much as this many px of summed boundary distance (N = 100)',
        0.0, 1000.0)
    keypoint_scale: float = setting(
        30.0, '[px] keypoint errors e cost keypoint_scale·log(1 + e/keypoint_scale): about e when small, growing '
              'ever slower when large, so a wrong detection pulls little but always leads back', 0.1, 1000.0)
    smoothness_weight: float = setting(
        20.0, "cost of moving a parameter by one initial simplex step from the previous frame's value (squared)",
        0.0, 1e4)
    limit_weight: float = setting(1e4, 'cost per rad² beyond a joint limit', 0.0, 1e8)
    # The Nelder-Mead search (paper 000 Sec. 5.1, Eq. 7 coefficients).
    simplex_tolerance: float = setting(
        1e-2, '[m or rad] a stage stops when its simplex is this small (1 cm, 0.6°)', 1e-5, 1.0)
    step_position: float = setting(0.05, '[m] initial simplex size of a position parameter', 1e-4, 1.0)
    step_angle: float = setting(0.15, '[rad] initial simplex size of an angle parameter', 1e-4, 3.14)
    max_evaluations_per_parameter: int = setting(
        150, "a stage's objective evaluations at most, per parameter it searches", 1, 100000)
    # Initialisation (fitting/initialisation.py; paper 000 Sec. 3.1 and 6, paper 004).
    time_jump: float = setting(
        0.5, '[s] a larger gap between frame sets (or going back in time) re-initialises, unless frame sets were '
             'skipped in it to keep up (the fit then follows on)', 0.01, 3600.0)
    lost_share: float = setting(
        0.15, "a fit that leaves more than this share of the outline unexplained (median over the views; "
              "hypotheses.unexplained_share) has left the person", 0.0, 1.0)
    lost_frames: int = setting(2, 'after this many such fits in a row the fit is lost: said so '
                                  '(STATUS_LOST) and re-initialised on the next frame set', 1, 1000)
    ankle_height: float = setting(0.039, "the ankle's height, as a share of the stature (the template's)", 0.0, 0.2)
    keypoint_gate: float = setting(
        0.2, '[m] a keypoint farther than this (at its depth) from its joint triangulated from the views is left '
             'out (initialisation.consistent_views)', 0.01, 10.0)
    outlier_rms: float = setting(
        12.0, '[px] a triangulation worse than this tries leaving one view out', 0.1, 1000.0)
    length_trust: float = setting(
        0.35, "measured bone lengths within this share of the template's are believed", 0.0, 1.0)
    length_frames: int = setting(
        20, 'the bone lengths are the median of the measurements on up to this many upright frame sets '
            '(initialisation.upright) within stature_spread of the tallest measured', 1, 10000)
    upright_tilt_deg: float = setting(
        20.0, '[deg] a frame set measures the person only if the pelvis-neck line leans less than this', 0.0, 90.0)
    upright_pelvis: float = setting(
        0.15, "... and the pelvis's height above the floor is within this share of the template's (standing) "
              'share of the height', 0.0, 1.0)
    stature_spread: float = setting(
        0.05, 'measurements of a stature more than this share below (or above) the tallest measured (stature_support) '
              'are left out', 0.0, 1.0)
    stature_support: int = setting(
        3, 'the tallest measured is the tallest stature that this many measurements (itself among them) measure '
           'within stature_spread of it (initialisation.tallest_measurements): not one frame set alone', 1, 10000)
    face_evidence: float = setting(
        0.2, "the sum over the views of (frontness − the views' mean) × the unit vector towards the camera "
             'needed to trust the face (initialisation.facing_right)', 0.0, 10.0)
    hair_gap: float = setting(
        0.04, "[share of the head's height] the face is asked only if the skin on the head starts at least this far "
              'below its top (the median over the views so far; initialisation.face_tells): hair read as skin '
              'reaches the top (per person 0.00-0.04 for blond and brown hair in the suite, 0.03-0.40 for the '
              'others)', 0.0, 1.0)
    cut_share: float = setting(
        0.1, 'a view with more than this share of its contour pixels on the image edge (the person cut off) is left '
             'out of a frame set in which at least three other views are cut less (fitting/views.py; 1: never)',
        0.0, 1.0)
    # Left and right, front and back (fitting/limb_sides.py, fitting/hypotheses.py).
    walking_baseline: float = setting(
        0.4, "[s] how long fits are remembered: the last two give each pair's predicted place and the pelvis's "
             'velocity', 0.04, 10.0)
    velocity_horizon: float = setting(
        0.1, "[s] a longer gap since the last fit (frame sets skipped to keep up) is bridged by the frame's own "
             "triangulated joints: the pelvis moved as far as the triangulated one, not at the fits' velocity, and the "
             'limbs started there too', 0.0, 10.0)
    continuity_horizon: float = setting(
        0.14, "[s] up to this long after the last fit the frame's triangulated left/right pairs are labelled by "
              'continuity with the fits, after a longer gap by the side of the body they are on (continuity is the '
              'surer of the two up to 3 frame periods at 25 fps, the side from 4 on: docs/method.md)', 0.0, 10.0)
    outline_horizon: float = setting(
        0.06, "[s] after a longer gap since the last fit (a frame set or more skipped) each stage's searches are "
              'ranked by how well each explains the outline assigned from its own start, as at a start: the last '
              "fit's assignment is stale by then (on the suite's tuning cases with gaps of 1-3 frame sets, 58 "
              'cases: 84.8 -> 82.7 mm mean, docs/method.md)', 0.0, 10.0)
    hypothesis_frames: int = setting(
        5, 'frame sets over which other labellings of the body (turned round, legs or arms exchanged) are followed '
           'beside the fit before the one that explains the views best is kept', 1, 1000)
    hypothesis_prune: float = setting(
        0.1, "a hypothesis whose fits so far cost this share more than the cheapest's is dropped before its window "
             'ends (a large value: every hypothesis followed to the end)', 0.0, 1e6)
    crossing_distance: float = setting(
        0.25, "[m] the fit's ankles nearer than this are passing each other (a stride, where continuity is least "
              'sure which leg is which): the legs exchanged are followed beside the fit as they close in from this '
              'far or more (as they pass, or at a short stride\'s widest) and once they are stride_apart apart',
        0.0, 2.0)
    stride_apart: float = setting(
        0.5, "[share of the leg: thigh + shin] a stride's legs exchanged are followed again once the fit's ankles "
             'are this far apart (and at least crossing_distance), where the two labellings differ more than as '
             'soon as they part (docs/method.md, session 41)', 0.0, 10.0)
    face_cost_share: float = setting(
        0.2, "a labelling whose hips face straight away from the face the views see (initialisation.facing_right) has "
             "its fit's cost raised by this share when labellings are compared, one side on to it not at all "
             "(hypotheses.face_away; 0: the face is not asked)", 0.0, 100.0)
    crossed_cost_share: float = setting(
        0.2, "a labelling whose fit has the wrists crossed (hypotheses.pair_crossing) by crossed_by or more has its "
             'cost raised by this share when labellings are compared, less crossed by as much less, and so for the '
             'knees while the feet are together and the person stands (hypotheses.crossing_judged); 0: neither is '
             'asked', 0.0, 100.0)
    crossed_by: float = setting(
        0.05, '[m] the crossing of the knees or of the wrists at which crossed_cost_share applies in full', 1e-3, 1.0)
    standing_speed: float = setting(
        0.5, "[m/s] the knees' crossing is judged while the fit's pelvis moves slower than this over "
             'walking_baseline (standing, turning on the spot, sitting; a stride is judged by its probes); from this '
             'speed up to running_speed the legs are carried on (running_speed)', 0.0, 100.0)
    running_speed: float = setting(
        2.0, "[m/s] while the fit's pelvis moves at standing_speed or faster but slower than this over "
             'walking_baseline (walking; people change from walking to running at about 2 m/s), the leg stages are '
             'also searched from the knees and ankles carried on from the last two fits at their velocity (a swinging '
             "foot moves at about twice the walker's speed, a planted one not at all); not running (a runner's "
             'swinging foot turns within a frame period or two) nor after a gap over velocity_horizon '
             '(LimbTracks.carried_legs)', 0.0, 100.0)
    foot_weight: float = setting(
        1.0, 'per px² of a point of a foot, ahead of the ankle where the hips face, outside the silhouette, added to '
             "a labelling's cost when labellings are compared (hypotheses.feet_outside; 0: the feet are not asked)",
        0.0, 1e4)
    probe_period: int = setting(
        10, 'frame sets between probes of the body turned round, followed beside the fit (the legs exchanged are '
            'probed after each stride)', 1, 100000)
    hypothesis_margin: float = setting(
        0.02, "a probed labelling replaces the fit when its fits' cost over hypothesis_frames is this share lower",
        0.0, 1.0)


SETTING_FIELDS = tuple(fields(FitterSettings))
