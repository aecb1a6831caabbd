"""The skeleton fitter: exact keypoints give the pose back; the evaluation table on a known offset; the
skeleton_fitter node in the real graph over DDS."""
import numpy as np
import pytest
import yaml
from conftest import run_mvpose
from rclpy.serialization import serialize_message

from mvpose_nodes.io.bagfile import BagWriter
from mvpose_nodes.body.model import JOINT_NAMES
from mvpose_nodes.body.camera import studio_rig
from mvpose_nodes.fitting.fitter import SkeletonFitter, View
from mvpose_nodes.fitting.stage_search import KEYPOINT_JOINT
from mvpose_nodes.studio.mocap import cmu_clip, load_bvh, retarget
from mvpose_nodes.ros.conversions import skeleton_message

KEYPOINTS = ('root', 'neck', 'head', 'left_wrist', 'right_wrist', 'left_elbow', 'right_elbow', 'left_ankle',
             'right_ankle', 'left_knee', 'right_knee')


def test_exact_keypoints_give_the_walk_back():
    """With keypoints projected from the true joints (and no contour), the fit follows the walk to within
    the body model's reach: the template's hips and shoulders are not the mocap subject's, and no
    keypoint sees them, nor how long the subject's bones are (measured: about 30 mm mean, under 40 mm
    at the head, wrists and ankles)."""
    motion = retarget(load_bvh(cmu_clip('07_01'))).placed()
    cameras = studio_rig(cameras=[3, 5, 7])
    fitter, errors = SkeletonFitter(), []
    for frame in range(0, 12):
        truth = motion.joints[frame]
        views = []
        for camera in cameras:
            pixels, _ = camera.project(truth)
            views.append(View(camera, None, {n: (*pixels[JOINT_NAMES.index(KEYPOINT_JOINT.get(n, n))], 1.0)
                                             for n in KEYPOINTS}))
        fit = fitter.fit(frame / 25.0, views)
        errors.append(np.linalg.norm(fit.joints - truth, axis=1))
        assert [s.name for s in fit.stages] == ['torso', 'head_neck', 'left_arm', 'right_arm', 'left_leg',
                                                'right_leg']
    errors = np.array(errors) * 1000
    assert errors.mean() < 45, errors.mean(axis=0).round()
    for name in ('head', 'left_wrist', 'right_wrist', 'left_ankle', 'right_ankle'):
        assert errors[:, JOINT_NAMES.index(name)].mean() < 40, name


def test_eval_prints_table_2_for_a_known_offset(tmp_path):
    motion = retarget(load_bvh(cmu_clip('07_01')))
    bag = tmp_path / 'recorded'
    with BagWriter(bag) as out:
        out.add_topic('/mvpose/skeleton', 'mvpose_msgs/msg/Skeleton')
        out.add_topic('/mvpose/ground_truth', 'mvpose_msgs/msg/Skeleton')
        for frame in range(5):
            stamp = 10**18 + frame * 40_000_000
            truth = motion.joints[frame]
            out.write('/mvpose/ground_truth', serialize_message(skeleton_message(truth, stamp)), stamp)
            out.write('/mvpose/skeleton', serialize_message(skeleton_message(truth + [0.010, 0, -0.020], stamp)), stamp)
    table = run_mvpose('eval', bag).stdout
    mean_row = next(line for line in table.splitlines() if line.strip().startswith('mean'))
    cells = mean_row.split()
    assert cells[1].startswith('10.0±0.0') and cells[2].startswith('0.0±0.0') and cells[3].startswith('20.0±0.0')
    assert float(cells[4]) == pytest.approx(np.hypot(10, 20), abs=0.05) and cells[5] == '44.4'
    assert '5 frames matched' in table


def wait_for_graph(topics_with_both_ends, timeout=60):
    """Until every topic has a publisher and a subscriber in the graph, then a moment for them to match:
    the player waits for its own subscribers only, not for the nodes downstream of them."""
    import time
    import rclpy
    node = rclpy.create_node('graph_watcher')
    try:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and not all(
                node.count_publishers(t) and node.count_subscribers(t) for t in topics_with_both_ends):
            rclpy.spin_once(node, timeout_sec=0.1)
        time.sleep(1.0)
    finally:
        node.destroy_node()


def test_skeleton_fitter_node_in_the_graph(tmp_path, background, ros_context):
    bag = tmp_path / 'walk'
    # Five frames: the first may reach the fitter before the calibration does (other topics), and is then skipped.
    run_mvpose('synth', '--cameras', 3, 5, '--frames', '70-74', '--resolution', '960x540', '-o', bag, timeout=300)
    for k in (3, 5):
        background('run', 'camera_features', '--ros-args', '-r', f'__ns:=/cam{k}')
    fitter = background('run', 'skeleton_fitter', '--ros-args', '-p', 'cameras:=[3, 5]')
    echo = background('topic', 'echo', '/mvpose/skeleton', '--count', 3, '--timeout', 120)
    wait_for_graph([f'/cam{k}/{name}' for k in (3, 5) for name in ('silhouette', 'skin_ellipses', 'labelled_contour')]
                   + ['/mvpose/skeleton'])
    run_mvpose('bag', 'play', bag, '--topics', '/cam3/image_raw/compressed', '/cam5/image_raw/compressed',
               '/cam3/camera_info', '/cam5/camera_info', '/cam3/camera_pose', '/cam5/camera_pose',
               '--wait-for-subscribers', '--delay', 1.0, '--rate', 0.2, timeout=180)
    code, out, err = echo.finish(timeout=150)
    assert code == 0, err
    skeletons = [d for d in yaml.safe_load_all(out) if d]
    assert len(skeletons) == 3
    stamps = [s['header']['stamp']['nanosec'] for s in skeletons]
    assert stamps == sorted(stamps) and set(stamps) <= {800_000_000 + 40_000_000 * i for i in range(5)}
    for skeleton in skeletons:
        assert skeleton['joint_names'] == list(JOINT_NAMES) and len(skeleton['parameters']) == 29
        assert [stage['name'] for stage in skeleton['stages']][0] == 'torso'
    assert skeletons[0]['status'] == 1 and skeletons[1]['status'] == 0   # INITIALISING, then OK
    fitter.interrupt()


def exact_views(cameras, truth, names=KEYPOINTS):
    views = []
    for camera in cameras:
        pixels, _ = camera.project(truth)
        views.append(View(camera, None, {n: (*pixels[JOINT_NAMES.index(KEYPOINT_JOINT.get(n, n))], 1.0) for n in names}))
    return views


def test_time_jump_or_reversal_reinitialises_and_missing_evidence_keeps_a_limb():
    motion = retarget(load_bvh(cmu_clip('07_01'))).placed()
    cameras = studio_rig(cameras=[3, 5, 7])
    fitter = SkeletonFitter()
    assert fitter.fit(1.00, exact_views(cameras, motion.joints[0])).initialised
    assert not fitter.fit(1.04, exact_views(cameras, motion.joints[1])).initialised
    assert fitter.fit(1.00, exact_views(cameras, motion.joints[2])).initialised, 'time went back'
    assert fitter.fit(3.00, exact_views(cameras, motion.joints[3])).initialised, 'time jumped'
    before = fitter.parameters.copy()
    without_left_arm = [n for n in KEYPOINTS if n not in ('left_elbow', 'left_wrist')]
    fit = fitter.fit(3.04, exact_views(cameras, motion.joints[4], without_left_arm))
    left_arm = next(s for s in fit.stages if s.name == 'left_arm')
    assert not left_arm.fitted and left_arm.evaluations == 0
    from mvpose_nodes.fitting.stage_search import STAGE_PARAMETERS
    from mvpose_nodes.body.model import PARAMETER_INDEX
    indices = [PARAMETER_INDEX[n] for n in STAGE_PARAMETERS['left_arm']]
    assert np.array_equal(fit.parameters[indices], before[indices]), 'the left arm keeps its angles'


def test_too_few_views_is_a_clear_error():
    motion = retarget(load_bvh(cmu_clip('07_01')))
    with pytest.raises(ValueError, match='too few views'):
        SkeletonFitter().fit(0.0, exact_views(studio_rig(cameras=[3]), motion.joints[0]))


def walk_found(motion, frame, rng, swap):
    """'Triangulated' joints of a walk frame: the truth with 2 cm noise, pairs given the wrong way round
    where `swap` says (as triangulation leaves them: it does not know the person's sides)."""
    truth = motion.joints[frame]
    found = {name: truth[JOINT_NAMES.index(name)] + rng.normal(0, 0.02, 3)
             for name in ('pelvis', 'neck', 'head', *(f'{side}_{limb}' for side in ('left', 'right')
                                                      for limb in ('knee', 'ankle', 'elbow', 'wrist')))}
    for limb in ('knee', 'ankle', 'elbow', 'wrist'):
        if swap[limb]:
            found[f'left_{limb}'], found[f'right_{limb}'] = found[f'right_{limb}'], found[f'left_{limb}']
    return found


def test_limb_tracks_correct_a_wrong_start_and_keep_the_sides_through_a_walk():
    """Started the wrong way round (no face seen), the pairs are put right once the person is seen
    walking (within 0.2 s) and then stay right through the strides, whatever the triangulation's order."""
    from mvpose_nodes.fitting.limb_sides import LimbTracks
    from mvpose_nodes.fitting.settings import FitterSettings
    motion = retarget(load_bvh(cmu_clip('07_01'))).placed()
    rng = np.random.default_rng(3)
    tracks = LimbTracks(FitterSettings())
    wrong = []
    for frame in range(60):
        swap = {limb: bool(rng.integers(2)) for limb in ('knee', 'ankle', 'elbow', 'wrist')}
        found = walk_found(motion, frame, rng, swap if frame else dict.fromkeys(swap, True))
        tracks.label(frame / 25.0, found)
        joints = motion.joints[frame].copy()
        for name, position in found.items():
            joints[JOINT_NAMES.index(name)] = position   # the fit follows the labelled joints
        tracks.append(frame / 25.0, joints)
        truth = motion.joints[frame]
        wrong.append([np.linalg.norm(found[f'left_{limb}'] - truth[JOINT_NAMES.index(f'left_{limb}')])
                      > np.linalg.norm(found[f'left_{limb}'] - truth[JOINT_NAMES.index(f'right_{limb}')])
                      for limb in ('knee', 'ankle', 'elbow', 'wrist')])
    wrong = np.array(wrong)
    assert wrong[0].all(), 'the first frame keeps its (wrong) guess: nothing tells yet'
    assert not wrong[5:].any(), np.flatnonzero(wrong.any(axis=1))


def test_skeleton_fitter_node_survives_nan_calibration_and_malformed_contours(background, ros_context):
    """Over DDS: a NaN camera_info and a contour whose arrays disagree are logged with the topic and the
    cause, and dropped; the node keeps running (it still answers Ctrl-C with exit 0)."""
    fitter = background('run', 'skeleton_fitter', '--ros-args', '-p', 'cameras:=[3, 5]')
    wait_for_graph([])
    nan_info = ("{header: {frame_id: cam3}, width: 1920, height: 1080, distortion_model: plumb_bob, "
                "k: [.nan, 0, 960, 0, 1400, 540, 0, 0, 1], d: [0, 0, 0, 0, 0]}")
    pose = "{header: {frame_id: world}, pose: {orientation: {w: 1.0}}}"
    qos = ('--qos-durability', 'transient_local', '-w', 1, '--once')
    run_mvpose('topic', 'pub', '/cam3/camera_info', 'sensor_msgs/msg/CameraInfo', nan_info, *qos)
    run_mvpose('topic', 'pub', '/cam3/camera_pose', 'geometry_msgs/msg/PoseStamped', pose, *qos)
    run_mvpose('topic', 'pub', '/cam5/camera_info', 'sensor_msgs/msg/CameraInfo', nan_info.replace('.nan', '1400'), *qos)
    run_mvpose('topic', 'pub', '/cam5/camera_pose', 'geometry_msgs/msg/PoseStamped', pose, *qos)
    stamp = '{header: {stamp: {sec: 5}}'
    for k in (3, 5):  # one frame set whose contours have 3 pixels but 1 label
        run_mvpose('topic', 'pub', f'/cam{k}/silhouette', 'sensor_msgs/msg/Image', stamp + '}', '-w', 1, '--once')
        run_mvpose('topic', 'pub', f'/cam{k}/skin_ellipses', 'mvpose_msgs/msg/SkinEllipseArray', stamp + '}',
                   '-w', 1, '--once')
        run_mvpose('topic', 'pub', f'/cam{k}/labelled_contour', 'mvpose_msgs/msg/LabelledContour',
                   stamp + ', x: [1, 2, 3], y: [1, 2, 3], labels: [1], sides: [1]}', '-w', 1, '--once')
    import time
    time.sleep(2.0)
    code, _, err = fitter.interrupt()
    assert code == 0, err
    assert '/cam3 calibration unusable: camera_info K is not a valid intrinsic matrix' in err, err
    assert '/cam5/labelled_contour: LabelledContour x, y, labels and sides differ in length; dropped' in err, err
