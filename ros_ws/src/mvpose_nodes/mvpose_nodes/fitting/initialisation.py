"""Initialisation of the fit from the views' 2D keypoints (paper 000 Sec. 3.1 and 6; paper 004).

On the first frame and after a jump in time the fitter has no previous pose: the keypoints are
triangulated across the views (one disagreeing view left out), left and right told apart by the face
where a camera sees it, the person's bone lengths estimated (the template scaled to the height, the
legs and head measured), and the joints the keypoints do not locate completed from the template, ready
for paper 004's inverse kinematics. Every frame after that uses `triangulated_joints` too, as the
frame's own evidence beside the pose carried over from the last frame. A frame set too few views locate
the torso in, before the first fit, gets a standing best guess (`guessed_parameters`) as its answer.
"""
from dataclasses import replace

import numpy as np

from mvpose_nodes.body.kinematics import LENGTH_FRACTIONS, bone_lengths, forward_kinematics
from mvpose_nodes.body.model import JOINT_INDEX, PARAMETER_INDEX, PARAMETER_NAMES
from mvpose_nodes.body.triangulation import Rig, best_assignments, rms_of, triangulate_many, usable
from mvpose_nodes.fitting.hypotheses import on_the_floor
from mvpose_nodes.fitting.stage_search import KEYPOINT_JOINT, stage_indices

PAIRED_LIMBS = ('knee', 'ankle', 'elbow', 'wrist')   # keypoints that come as a left/right pair
TRIANGULATED = ('root', 'neck', 'head')   # keypoints of one joint each, which initialisation needs
TEMPLATE_HEIGHT = 1.75   # [m] the stature at which ankle_height was measured on the template


def robust_triangulate(cameras, pixels, weights, outlier_rms):
    """A DLT triangulation (triangulation.triangulate) that leaves out the one view that disagrees
    (robust_points). pixels (V, 2) [px] (NaN where unseen), weights (V,); (3,) point [m], or None."""
    points, found = robust_points(Rig.of(cameras), np.asarray(pixels, float)[None], np.asarray(weights, float)[None],
                                  outlier_rms)
    return points[0] if found[0] else None


def robust_points(rig, pixels, weights, outlier_rms, normalized=None):
    """N DLT triangulations at once (triangulation.triangulate_many), each leaving out the one view that
    disagrees: with three or more views and an RMS reprojection error above outlier_rms [px], the views
    without the one whose removal lowers the error most are used if they bring it under outlier_rms.
    pixels (N, V, 2) [px] (NaN where unseen), weights (N, V), normalized (N, V, 2) their Rig.normalized
    coordinates if known. Returns points (N, 3) [m] and found (N,) bool (2 views or more)."""
    if normalized is None:
        normalized = rig.normalized(np.swapaxes(pixels, 0, 1)).swapaxes(0, 1)
    points, squared, count = triangulate_many(rig, pixels, weights, normalized)
    rms = rms_of(squared, count)
    retried = np.flatnonzero((count >= 3) & (rms > outlier_rms))
    if len(retried):
        views = pixels.shape[1]
        left_out = np.repeat(weights[retried], views, axis=0)   # (R V, V): each point with each view left out
        left_out[np.arange(len(left_out)), np.tile(np.arange(views), len(retried))] = 0.0
        trials, trial_squared, trial_count = triangulate_many(
            rig, np.repeat(pixels[retried], views, axis=0), left_out, np.repeat(normalized[retried], views, axis=0))
        trial_rms = np.where(usable(pixels[retried], weights[retried]).ravel(),   # the views there are to leave out
                             rms_of(trial_squared, trial_count), np.inf).reshape(len(retried), views)
        best = np.argmin(trial_rms, axis=1)
        better = trial_rms[np.arange(len(retried)), best] < outlier_rms
        points[retried[better]] = trials.reshape(len(retried), views, 3)[better, best[better]]
    return points, count >= 2


def triangulated_joints(views, settings):
    """{joint: (3,) [m]} triangulated from the views' keypoints, or None without root, neck and head in
    two views. Each left/right pair is assigned consistently across the views, but which of the two
    is the person's left is not decided here (labelled_joints and limb_sides.LimbTracks do)."""
    rig = Rig.of(view.camera for view in views)
    names = TRIANGULATED + tuple(f'{side}_{limb}' for limb in PAIRED_LIMBS for side in ('left', 'right'))
    pixels = np.array([[view.keypoints.get(name, (np.nan, np.nan, 0))[:2] for name in names] for view in views],
                      float).reshape(len(views), len(names), 2)   # (V, names, 2)
    weights = np.array([[view.keypoints.get(name, (0, 0, 0.0))[2] for name in names] for view in views],
                       float).reshape(len(views), len(names))
    normalized = rig.normalized(pixels)

    def robust(columns):
        """robust_points of the keypoints in `columns` (V, K) (each view's index into `names`): (K, 3), (K,)."""
        rows = np.arange(len(views))[:, None]
        return robust_points(rig, pixels[rows, columns].swapaxes(0, 1), weights[rows, columns].T,
                             settings.outlier_rms, normalized[rows, columns].swapaxes(0, 1))
    points, found = robust(np.tile(np.arange(len(TRIANGULATED)), (len(views), 1)))
    if not found.all():
        return None
    joints = {KEYPOINT_JOINT.get(name, name): point for name, point in zip(TRIANGULATED, points)}
    # The pairs' columns: left, left + 1 (right); every pair's labellings across the views solved together.
    lefts = len(TRIANGULATED) + 2 * np.arange(len(PAIRED_LIMBS))
    pair_columns = np.stack([lefts, lefts + 1], axis=1)   # (pairs, 2)
    by_pair = (values[:, pair_columns].swapaxes(0, 1) for values in (pixels, weights, normalized))   # (pairs, C, 2, ...)
    assignments = best_assignments(rig, *by_pair)
    assigned = [(limb, left, result[2]) for limb, left, result in zip(PAIRED_LIMBS, lefts, assignments)
                if result is not None]
    if assigned:
        # Each point's observation in each view: the view's own labels, or the other's where it was swapped.
        columns = np.concatenate([left + np.column_stack([swaps, ~swaps]).astype(int) for _, left, swaps in assigned],
                                 axis=1)
        pair_points, pair_found = robust(columns)
        for index, (limb, _, _) in enumerate(assigned):
            if pair_found[2 * index:2 * index + 2].all():
                joints[f'left_{limb}'], joints[f'right_{limb}'] = pair_points[2 * index:2 * index + 2]
    return joints


def consistent_views(views, found, gate):
    """The views (fitter.View) without the keypoints that disagree with the others (issue 13: one camera's
    elbow and wrist 200 px off would otherwise pull the fit): a keypoint farther than `gate` [m, at its
    depth] from the projection of its joint triangulated from the views (`found`, triangulated_joints, which
    leaves the one disagreeing view out of each point), or for a left/right pair from the nearer of the
    pair's two joints (a view's labels may be the other way round), is left out of that view. Keypoints
    without a triangulated joint are kept."""
    kept = []
    for view in views:
        keypoints = {}
        for name, value in view.keypoints.items():
            joint = KEYPOINT_JOINT.get(name, name)
            side, _, limb = joint.partition('_')
            joints = [found[n] for n in ((f'left_{limb}', f'right_{limb}') if limb in PAIRED_LIMBS else (joint,))
                      if n in found]
            if joints:
                pixels, depths = view.camera.project(np.array(joints))
                metres = np.hypot(*(pixels - value[:2]).T) * depths / view.camera.K[0, 0]
                if not np.any((depths > 0) & (metres <= gate)):
                    continue
            keypoints[name] = value
        kept.append(replace(view, keypoints=keypoints))
    return kept


def consistent_evidence(views, found, settings):
    """(views, joints): consistent_views with settings.keypoint_gate, and the joints `found` triangulated
    again from the keypoints it kept if it left any out (a joint that two views saw, one of them far off,
    was triangulated through the bad keypoint); `found` itself if nothing was left out or too little is
    left to triangulate from. Then, with the hands raised, the root and neck put below the head
    (torso_below_the_head)."""
    kept = consistent_views(views, found, settings.keypoint_gate)
    if any(len(kept_view.keypoints) != len(view.keypoints) for kept_view, view in zip(kept, views)):
        found = triangulated_joints(kept, settings) or found
    return torso_below_the_head(kept, found, settings)


def torso_below_the_head(views, found, settings):
    """(views, joints) with the root and neck where they are when the hands are raised (hands_raised): the
    silhouettes' centroid, the root keypoint, is lifted with the arms, and the neck keypoint, on the row
    where the silhouette widens below the head, moves with the raised upper arms (on the suite's seed 2
    case 9, a tuning case that starts with the hands overhead, the triangulated pelvis was 0.27 m high and
    the neck 0.24 m off, and every labelling's fit with them). The head keypoint stays right (the
    silhouette's middle column): standing with a foot on the floor (or none seen), the pelvis and the neck
    are put below it at the template's shares of its height (a person stands upright to raise the hands),
    and each view's root and neck keypoints at their projections, with the same confidence. Otherwise the
    views and joints `found` as they are."""
    if not hands_raised(found):
        return views, found
    height = found['head'][2]
    ankles = [found[n][2] for n in ('left_ankle', 'right_ankle') if n in found]
    if ankles and not on_the_floor(min(ankles), height, settings.ankle_height):
        return views, found
    shares = {'root': 1 - LENGTH_FRACTIONS['head'] - LENGTH_FRACTIONS['spine'], 'neck': 1 - LENGTH_FRACTIONS['head']}
    placed = {name: np.r_[found['head'][:2], share * height] for name, share in shares.items()}
    positions = np.array(list(placed.values()))
    lowered = []
    for view in views:
        pixels, _ = view.camera.project(positions)
        keypoints = dict(view.keypoints)
        for name, pixel in zip(placed, pixels):
            if name in keypoints:
                keypoints[name] = (*pixel, keypoints[name][2])
        lowered.append(replace(view, keypoints=keypoints))
    return lowered, dict(found, pelvis=placed['root'], neck=placed['neck'])


def hair_gap(face_top, keypoints):
    """How far below the head keypoint (the silhouette's top) the face's skin begins, as a share of the head
    keypoint's height above the neck keypoint: face_top [px] the face ellipse's topmost row
    (vision.features.ellipse_top), keypoints {name: (x, y, confidence)} [px]. None without a face ellipse or
    either keypoint. About 0 when the hair reads as skin (the skin reaches the top of the head), 0.03–0.4 per
    person under hair that does not (issue 13; docs/method.md, session 47)."""
    if face_top is None or 'head' not in keypoints or 'neck' not in keypoints:
        return None
    height = keypoints['neck'][1] - keypoints['head'][1]
    return (face_top - keypoints['head'][1]) / height if height > 1.0 else None


def face_tells(hair_gaps, min_hair_gap):
    """Whether the skin on the head can tell a face from the back of a head: the median of the person's
    hair_gap over the views so far (a list) at least min_hair_gap (FitterSettings.hair_gap), or none measured
    yet. Hair read as skin (blond or light brown in the suite's studio, or a bald head) covers the head from
    every side: the views' skin shares then rank front against back no better than chance (front-against-back
    AUC over the views of the 48 tuning cases of seeds 13-16: blond 0.44, brown 0.57; black 0.62, dark 0.82,
    auburn 0.88, grey 0.91)."""
    return not hair_gaps or float(np.median(hair_gaps)) >= min_hair_gap


def facing_right(views, joints, face_evidence):
    """The person's right (unit, horizontal) from where the face is seen: the cameras that see more skin
    on the head than the others (Features.frontness) are in front of the person (paper 000's views cannot
    tell left from right otherwise). Against the views' mean, not an absolute share: hair of a skin
    colour reads as skin from every side (on the suite's tuning draw of seed 1, a dark-brown-haired
    person's back showed 0.5–0.75 of the head as skin, the face 0.6). None when the views do not say
    (all side views, or heads alike from every side)."""
    pelvis = joints['pelvis']
    seen = [view for view in views if view.frontness is not None]
    if not seen:
        return None
    mean = np.mean([view.frontness for view in seen])
    forward = np.zeros(3)
    for view in seen:
        towards = view.camera.center - pelvis
        towards[2] = 0.0
        forward += (view.frontness - mean) * towards / np.linalg.norm(towards)
    if np.linalg.norm(forward) < face_evidence:
        return None
    return np.cross(forward / np.linalg.norm(forward), [0.0, 0.0, 1.0])


def labelled_joints(views, found, settings):
    """Triangulated joints `found` ({joint: (3,)}, triangulated_joints) with each pair's left and right from
    the face where a view sees it (a copy)."""
    joints = dict(found)
    right = facing_right(views, joints, settings.face_evidence)
    if right is not None:  # which of each pair is the person's left: the face's side tells
        for limb in PAIRED_LIMBS:
            left, right_name = f'left_{limb}', f'right_{limb}'
            if left in joints and right_name in joints and np.dot(joints[left] - joints[right_name], right) > 0:
                joints[left], joints[right_name] = joints[right_name], joints[left]
    return joints


def upright(joints, settings):
    """Whether triangulated joints {name: (3,) [m]} show the person standing up with the head keypoint on
    the head, the posture person_lengths assumes: the pelvis-neck line within upright_tilt_deg of
    vertical, the pelvis at the template's share of the height (within upright_pelvis: not sitting or
    bent down), and the head as far from the neck, against the spine, as the template's (within
    length_trust: not hands raised above it, which the silhouette's top then is), and the lower ankle
    keypoint, if any, on the floor (hypotheses.on_the_floor; not a run's or a hop's flight, where the head is
    above the stature and the pelvis above its standing height, which person_lengths would take for a taller
    person with longer legs), and no wrist above the neck (hands_raised). Heights are above the world frame's
    floor, z = 0 (README)."""
    if hands_raised(joints):
        return False
    spine = joints['neck'] - joints['pelvis']
    tilt = np.degrees(np.arccos(np.clip(spine[2] / np.linalg.norm(spine), -1.0, 1.0)))
    height = joints['head'][2]
    standing = LENGTH_FRACTIONS['thigh'] + LENGTH_FRACTIONS['shin'] + settings.ankle_height
    head = np.linalg.norm(joints['head'] - joints['neck']) / np.linalg.norm(spine)
    ankles = [joints[n][2] for n in ('left_ankle', 'right_ankle') if n in joints]
    on_floor = not ankles or bool(on_the_floor(min(ankles), height, settings.ankle_height))
    return bool(tilt < settings.upright_tilt_deg and height > 0 and on_floor
                and abs(joints['pelvis'][2] / height / standing - 1) < settings.upright_pelvis
                and abs(head / (LENGTH_FRACTIONS['head'] / LENGTH_FRACTIONS['spine']) - 1) < settings.length_trust)


def hands_raised(joints):
    """Whether a triangulated wrist in joints {name: (3,) [m]} is above the neck. Raised arms lift the
    silhouettes' centroid, which the root keypoint (the pelvis triangulated) is: on the suite's tuning cases
    that start with the hands above the neck, person_lengths measured the legs 1.09–1.13 of the truth from it
    (the others 0.95–1.03)."""
    neck = joints['neck'][2]
    return any(joints[name][2] > neck for name in ('left_wrist', 'right_wrist') if name in joints)


def stature(lengths):
    """[m] the stature bone lengths {key: [m]} (person_lengths) were scaled from: the spine's template share."""
    return lengths['spine'] / LENGTH_FRACTIONS['spine']


def tallest_measurements(measurements, spread, support=1):
    """The bone lengths {key: [m]} among `measurements` (person_lengths, a list) whose stature is within the share
    `spread` of the tallest (settings.stature_spread) that `support` of them (itself among them) measure within
    `spread` of it (settings.stature_support), or while none is, the one the most measure so; [] for none. The
    tallest, since crouching, sitting or bending measures a person shorter; but a frame set whose raised hands
    are taken for the top of the head (the wrists unseen, so that `upright` cannot tell) measures them taller,
    and one such measurement alone had set a 1.59 m person's lengths for 1.99 m (docs/method.md, session 70)."""
    if not measurements:
        return []
    statures = np.array([stature(m) for m in measurements])
    near = np.abs(statures[None, :] - statures[:, None]) <= spread * statures[:, None]
    counts = near.sum(axis=1)
    supported = counts >= min(support, counts.max())
    reference = statures[supported].max()
    return [m for m, height in zip(measurements, statures)
            if (1 - spread) * reference <= height <= (1 + spread) * reference]


def person_lengths(joints, settings):
    """Bone lengths of the person in triangulated joints {name: (3,) [m]} (a first frame set, or an upright
    one: SkeletonFitter.measure): the template scaled to the height (the head's above the world frame's
    floor, z = 0 in the README's contract), then the legs and the head measured (the template's proportions
    are an average person's; a measurement within ±length_trust of the template's value is believed).
    The legs: the stance leg is nearly straight, so the pelvis's distance from the stance ankle is about
    √(hip² + (thigh + shin)²); the knee keypoints are too rough to split it (features.py takes them from a
    band of the silhouette), so the template's thigh : shin proportion is kept. The stance ankle is the
    lower ankle keypoint, where it is across the floor but at its height standing (ankle_height): the
    triangulated ankle keypoints lie 20 mm below the true ankles on median (interquartile −52 to +2 mm over
    the suite's 70 tuning cases, session 31: they sit near the foot's lowest pixel), the head keypoint
    within ±2 mm of its height; a floor put below the ankle keypoints took their errors into every length
    (8 % long on a turn on the spot with ankles 4-13 cm low in four frame sets)."""
    height = joints['head'][2]
    lengths = bone_lengths(float(np.clip(height, 1.2, 2.2)))
    ankles = [joints[n] for n in ('left_ankle', 'right_ankle') if n in joints]
    reach = 0.0
    if ankles:
        stance = np.r_[min(ankles, key=lambda ankle: ankle[2])[:2], settings.ankle_height * height]
        reach = float(np.linalg.norm(stance - joints['pelvis']))
    if reach > lengths['hip']:
        leg = np.sqrt(reach ** 2 - lengths['hip'] ** 2)
        scale = leg / (lengths['thigh'] + lengths['shin'])
        if abs(scale - 1) < settings.length_trust:
            lengths['thigh'] *= scale
            lengths['shin'] *= scale
    head = np.linalg.norm(joints['head'] - joints['neck'])
    if abs(head / lengths['head'] - 1) < settings.length_trust:
        lengths['head'] = float(head)
    return lengths


def completed_joints(found, lengths):
    """All 15 joints (15, 3) [m] for inverse kinematics: the triangulated ones (`found`, {joint: (3,)}),
    the rest from the template of bone `lengths` turned to the found torso."""
    up = found['neck'] - found['pelvis']
    up /= np.linalg.norm(up)
    sideways = [found[f'right_{n}'] - found[f'left_{n}'] for n in PAIRED_LIMBS if f'left_{n}' in found]
    right = np.sum(sideways, axis=0) if sideways else np.cross([0.0, 0.0, 1.0], up) + [1e-3, 0, 0]
    right -= np.dot(right, up) * up
    right /= np.linalg.norm(right)
    rest, _ = forward_kinematics(np.zeros(len(PARAMETER_NAMES)), lengths)
    frame = np.column_stack([right, np.cross(up, right), up])
    joints = found['pelvis'] + (rest - rest[JOINT_INDEX['pelvis']]) @ frame.T
    for name, position in found.items():
        joints[JOINT_INDEX[name]] = position
    joints[JOINT_INDEX['left_hip']] = found['pelvis'] - lengths['hip'] * right
    joints[JOINT_INDEX['right_hip']] = found['pelvis'] + lengths['hip'] * right
    joints[JOINT_INDEX['left_shoulder']] = found['neck'] - lengths['clavicle'] * right
    joints[JOINT_INDEX['right_shoulder']] = found['neck'] + lengths['clavicle'] * right
    return joints


def guessed_parameters(views, lengths, ankle_height):
    """A best guess (29,) for a frame set the keypoints cannot initialise from (root, neck and head not in two
    views), so that it still gets an answer: the rest pose of bone `lengths` {key: [m]} standing on the floor
    (ankles at ankle_height × the template's stature), its pelvis at the views' root keypoint, triangulated
    from two views or more; from one view, on the root's ray at the depth of the outline's lowest point put
    on the floor (a foot), or without an outline at the standing pelvis's height. It faces the first camera
    that sees it. None when no view has a root keypoint, or its ray does not reach the floor or that height."""
    seen = [view for view in views if 'root' in view.keypoints]
    if not seen:
        return None
    rest, _ = forward_kinematics(np.zeros(len(PARAMETER_NAMES)), lengths)
    pelvis_height = ankle_height * TEMPLATE_HEIGHT - rest[[JOINT_INDEX['left_ankle'], JOINT_INDEX['right_ankle']], 2].min()
    pelvis = None
    if len(seen) >= 2:
        pelvis = robust_triangulate([view.camera for view in seen], np.array([view.keypoints['root'][:2] for view in seen]),
                                    np.array([view.keypoints['root'][2] for view in seen], float),
                                    outlier_rms=np.inf)   # every view kept: nothing better to go on
    if pelvis is None:
        view = seen[0]
        camera, axis = view.camera, view.camera.R[2]   # the optical axis in the world
        (root,) = camera.rays(camera.undistort_pixels(np.array([view.keypoints['root'][:2]])))
        on_floor = view.outline is not None and len(view.outline.points)
        point, height = ((view.outline.points[np.argmax(view.outline.points[:, 1])], 0.0) if on_floor
                         else (view.keypoints['root'][:2], pelvis_height))
        (ray,) = camera.rays(camera.undistort_pixels(np.array([point], float)))
        if abs(ray[2]) < 1e-6 or (height - camera.center[2]) / ray[2] <= 0:
            return None
        depth = np.dot(ray, axis) * (height - camera.center[2]) / ray[2]
        pelvis = camera.center + root * depth / np.dot(root, axis)
    towards = seen[0].camera.center - pelvis
    parameters = np.zeros(len(PARAMETER_NAMES))
    parameters[stage_indices('torso')[:3]] = pelvis[0], pelvis[1], pelvis_height   # torso_x, torso_y, torso_z
    parameters[PARAMETER_INDEX['torso_rz']] = np.arctan2(-towards[0], towards[1])   # the rest pose faces +y
    return parameters
