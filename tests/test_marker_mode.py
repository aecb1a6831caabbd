"""Marker mode around the tracker: triangulating the cameras' tracks (only detected markers count), the
MarkerTracks conversion, and the evaluation's identity-swap count."""
import numpy as np
import pytest

from mvpose_nodes.body.model import JOINT_NAMES
from mvpose_nodes.body.camera import studio_rig
from mvpose_nodes.markers.triangulation import triangulate_markers
from mvpose_nodes.markers.detection import FLAG_DETECTED, FLAG_LOST, FLAG_PREDICTED
from mvpose_nodes.app.markers import errors_and_swaps, swap_events
from mvpose_nodes.studio.mocap import cmu_clip, load_bvh, retarget


@pytest.fixture(scope='module')
def pose():
    return retarget(load_bvh(cmu_clip('07_01'))).placed().joints[10]


def test_detected_markers_triangulate_back_and_predicted_ones_are_not_used(pose):
    cameras = studio_rig(cameras=[3, 5, 7])
    positions = np.array([camera.project(pose)[0] for camera in cameras])
    flags = np.full((3, 15), FLAG_DETECTED)
    joints, used = triangulate_markers(cameras, positions, flags)
    np.testing.assert_allclose(joints, pose, atol=1e-6)
    assert used.tolist() == [3] * 15
    # A prediction far off, flagged as such, changes nothing; one flagged detected would.
    wrist = JOINT_NAMES.index('left_wrist')
    moved = positions.copy()
    moved[0, wrist] += 40.0
    flags[0, wrist] = FLAG_PREDICTED
    joints, used = triangulate_markers(cameras, moved, flags)
    np.testing.assert_allclose(joints[wrist], pose[wrist], atol=1e-6)
    assert used[wrist] == 2
    flags[0, wrist] = FLAG_DETECTED
    assert np.linalg.norm(triangulate_markers(cameras, moved, flags)[0][wrist] - pose[wrist]) > 0.01


def test_a_marker_seen_in_one_camera_keeps_its_previous_position(pose):
    cameras = studio_rig(cameras=[3, 5, 7])
    positions = np.array([camera.project(pose)[0] for camera in cameras])
    flags = np.full((3, 15), FLAG_DETECTED)
    head = JOINT_NAMES.index('head')
    flags[1:, head] = [FLAG_PREDICTED, FLAG_LOST]
    previous = pose + 0.05
    joints, used = triangulate_markers(cameras, positions, flags, previous)
    assert used[head] == 1 and np.array_equal(joints[head], previous[head])
    # Without a previous position the prediction helps out; a lost marker never does.
    np.testing.assert_allclose(triangulate_markers(cameras, positions, flags)[0][head], pose[head], atol=1e-6)
    flags[0, head] = FLAG_LOST
    assert np.isnan(triangulate_markers(cameras, positions, flags)[0][head]).all()


def test_marker_tracks_message_round_trip_and_bad_messages():
    from std_msgs.msg import Header
    from mvpose_nodes.ros.conversions import marker_tracks, tracks_from_message
    rng = np.random.default_rng(0)
    positions, flags = rng.uniform(0, 1000, (15, 2)), rng.integers(0, 2, 15)
    message = marker_tracks(Header(), positions, flags)
    back, back_flags = tracks_from_message(message)
    np.testing.assert_array_equal(back, positions)
    np.testing.assert_array_equal(back_flags, flags)
    message.names = message.names[::-1]                  # another order: read back by name
    message.x, message.y, message.flags = message.x[::-1], message.y[::-1], message.flags[::-1]
    np.testing.assert_array_equal(tracks_from_message(message)[0], positions)
    message.flags = message.flags[:3]
    with pytest.raises(ValueError, match='differ in length'):
        tracks_from_message(message)


def test_identity_swaps_are_counted_once_per_swap():
    true = np.array([[[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]]] * 6)   # 6 frames, 3 markers
    estimates = true.copy()
    estimates[2:4, [0, 1]] = estimates[2:4, [1, 0]]   # markers 0 and 1 exchanged in frames 2 and 3
    estimates[:, 2] += [1.0, 0.0]                       # marker 2 one pixel off: no swap
    runs = [(e, np.zeros(3), t, np.ones(3, bool)) for e, t in zip(estimates, true)]
    errors, visible, swapped = errors_and_swaps(runs)
    assert swapped[:, 0].tolist() == [False, False, True, True, False, False]
    assert swap_events(swapped) == 2          # one swap each for markers 0 and 1
    assert errors[0, 2] == pytest.approx(1.0) and visible.all()


def test_marker_mode_in_the_graph(tmp_path, background, ros_context):
    """Over DDS: three marker_tracker processes and marker_skeleton (launch/markers.launch.yaml) on a small
    marker bag: every frame comes out as a skeleton, and the markers detected in two or more cameras are
    triangulated at their true centres (median within 2 cm; the others are named in status_message as
    predicted), and each tracker gets its camera's fused tracks back."""
    import yaml
    from conftest import run_mvpose
    from test_fitting import wait_for_graph
    from mvpose_nodes.ros.camera_bag import frame_sets
    bag = tmp_path / 'markers'
    run_mvpose('synth', '--markers', '--cameras', 3, 5, 7, '--frames', '60-64', '--resolution', '960x540', '-o', bag,
               timeout=300)
    launch_file = 'ros_ws/src/mvpose_nodes/launch/markers.launch.yaml'
    graph = background('launch', launch_file)
    echo = background('topic', 'echo', '/mvpose/skeleton', '--count', 5, '--timeout', 120)
    echo_fused = background('topic', 'echo', '/cam5/marker_tracks_fused', '--count', 5, '--timeout', 120)
    wait_for_graph([f'/cam{k}/marker_tracks' for k in (3, 5, 7)] + ['/mvpose/skeleton', '/cam5/marker_tracks_fused'])
    played = [f'/cam{k}/{kind}' for k in (3, 5, 7)
              for kind in ('image_raw/compressed', 'camera_info', 'camera_pose', 'ground_truth/markers')]
    run_mvpose('bag', 'play', bag, '--topics', *played, '--wait-for-subscribers', '--delay', 1.0, '--rate', 0.2,
               timeout=180)
    code, out, err = echo.finish(timeout=150)
    assert code == 0, err
    skeletons = [d for d in yaml.safe_load_all(out) if d]
    truth = {s.stamp_ns: s.marker_centres for s in frame_sets(bag, [3])}
    assert len(skeletons) == 5
    for skeleton in skeletons:
        stamp = skeleton['header']['stamp']['sec'] * 10**9 + skeleton['header']['stamp']['nanosec']
        joints = np.array([[j['position'][a] for a in 'xyz'] for j in skeleton['joints']])
        # The markers this frame triangulated (detected in 2+ cameras; the rest are named as predicted).
        reason = skeleton['status_message']
        predicted = reason.split(': ', 1)[1].split(';')[0].split(', ') if reason.startswith('predicted') else []
        fresh = [i for i, name in enumerate(JOINT_NAMES) if name not in predicted]
        assert len(fresh) >= 3, reason   # with 3 cameras round the person many markers are seen by one only
        errors = np.linalg.norm(joints[fresh] - truth[stamp][fresh], axis=1)
        # The median: a marker given the wrong blob (an identity error, which `markers eval` counts) is
        # the tracker's accuracy, not this plumbing's.
        assert np.median(errors) < 0.02, (reason, errors.round(3))
    # Each tracker waited for its fused tracks, so the graph computed what the same code does offline.
    offline = offline_fusion(bag, (3, 5, 7))
    for skeleton in skeletons:
        stamp = skeleton['header']['stamp']['sec'] * 10**9 + skeleton['header']['stamp']['nanosec']
        joints = np.array([[j['position'][a] for a in 'xyz'] for j in skeleton['joints']])
        np.testing.assert_allclose(joints, offline[stamp], atol=1e-6)
    code, out, err = echo_fused.finish(timeout=60)
    assert code == 0, err
    fused = [d for d in yaml.safe_load_all(out) if d]
    assert len(fused) == 5 and all(len(d['x']) == 15 for d in fused)
    graph.interrupt()


def offline_fusion(bag, numbers):
    """{stamp [ns]: (15, 3) [m]} of marker_tracker + marker_skeleton run without ROS on `bag`."""
    from mvpose_nodes.ros.camera_bag import frame_sets
    from mvpose_nodes.markers.views import ViewTrackers
    fused, result = None, {}
    for frame_set in frame_sets(bag, numbers):
        labelling = None
        if fused is None:
            fused = ViewTrackers([frame_set.cameras[k] for k in numbers])
            labelling = [frame_set.markers[k] for k in numbers]
        result[frame_set.stamp_ns] = fused.track([frame_set.images[k] for k in numbers], labelling)[0]
    return result


def test_markers_eval_compares_the_three_methods(tmp_path):
    """`./mvpose markers eval` on a short marker bag prints a row per method, the fused one from the same
    code as the graph; a bag without markers is refused in one line naming it."""
    from conftest import run_mvpose
    bag = tmp_path / 'markers'
    run_mvpose('synth', '--markers', '--cameras', 3, 5, 7, '--frames', '60-63', '--resolution', '960x540', '-o', bag,
               timeout=300)
    out = run_mvpose('markers', 'eval', bag, '--pictures', tmp_path / 'pictures', timeout=300).stdout
    totals = out[out.index('  totals'):].splitlines()[1:4]
    rows = {line[:25].strip(): [float(v) for v in line[25:].replace('/', ' ').split()] for line in totals}
    assert set(rows) == {'nearest neighbour', 'regions (paper 001)', 'regions + 3D fusion'}, out
    # What the views buy: the fused 3D markers are nearer the truth than either method's own triangulation.
    visible, hidden, swaps, mean_3d, max_3d = rows['regions + 3D fusion']
    assert 0 <= visible < 5 and mean_3d < min(rows['nearest neighbour'][3], rows['regions (paper 001)'][3]), out
    # The pictures: a tile per camera, the detected markers' green dots on them.
    import cv2
    pictures = sorted((tmp_path / 'pictures').glob('markers_frame*_*.png'))
    assert [p.name.rsplit('_', 1)[-1] for p in pictures].count('worst.png') == 1 and len(pictures) == 2, out
    for picture in pictures:
        assert f'wrote {picture}' in out
        rgb = cv2.cvtColor(cv2.imread(str(picture)), cv2.COLOR_BGR2RGB)
        assert rgb.shape[1] == 3 * 560
        assert np.sum(np.all(np.abs(rgb.astype(int) - (60, 220, 60)) < 12, axis=2)) > 3 * 50
    plain = tmp_path / 'plain'
    run_mvpose('synth', '--cameras', 3, 5, '--frames', '60-60', '--resolution', '480x270', '-o', plain, timeout=300)
    result = run_mvpose('markers', 'eval', plain, check=False)
    assert result.returncode != 0
    assert f"bag '{plain}' has no ground-truth markers" in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_a_bag_whose_markers_do_not_decode_is_refused_in_one_line(tmp_path):
    """A MarkerTracks recorded with another definition (here its last bytes cut off, as an older
    MarkerTracks without blobs reads) gives a one-line error naming the bag and topic, not a traceback."""
    from rclpy.serialization import serialize_message
    from std_msgs.msg import Header
    from mvpose_nodes.io.bagfile import BagWriter
    from mvpose_nodes.ros.camera_bag import frame_sets
    from mvpose_nodes.io.bagfile import BagError
    from mvpose_nodes.ros.conversions import marker_tracks
    data = serialize_message(marker_tracks(Header(), np.zeros((15, 2)), [FLAG_DETECTED] * 15, blobs=[[1.0, 2.0]]))
    with BagWriter(tmp_path / 'old') as bag:
        bag.add_topic('/cam3/ground_truth/markers', 'mvpose_msgs/msg/MarkerTracks')
        bag.write('/cam3/ground_truth/markers', data[:-12], 0)
    with pytest.raises(BagError, match=r"mvpose_msgs/msg/MarkerTracks on /cam3/ground_truth/markers does not decode") as error:
        list(frame_sets(tmp_path / 'old'))
    assert str(tmp_path / 'old') in str(error.value) and '\n' not in str(error.value)
