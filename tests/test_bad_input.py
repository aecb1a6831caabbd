"""The bad-input corpus (issue 15; the README's table "Bad input" lists it with what happens): images a
camera should never send, calibration that cannot be used, a calibration that changes mid-run, a
message type that is not the topic's, and bags that are empty, have no cameras, lack the cameras asked
for, or whose metadata disagrees with their MCAP. Each gives a status or a one-line error naming the
topic, file or parameter; nothing crashes; the good input around it is still used.

Elsewhere (and in the table): a person leaving the view (STATUS_NO_PERSON: test_camera_features_node.py; seen by one camera
only, STATUS_LOST: test_skeleton_fitter_node.py), NaN calibration and malformed contours at the fitter
(test_skeleton_fitter_node.py), truncated and non-MCAP bags (test_bag_tools.py, test_front_door.py)."""
import shutil
import time

import cv2
import numpy as np
import pytest
import rclpy
import yaml
from common import ROOT, Publisher, assert_one_line_error, run_mvpose, spin_for, spin_until
from mvpose_msgs.msg import LabelledContour, Skeleton
from rclpy.qos import DurabilityPolicy, QoSProfile
from sensor_msgs.msg import CameraInfo, CompressedImage, Image
from std_msgs.msg import String
from test_skeleton_fitter_node import CAMERAS, FEATURES, feeding_node, rendered_features  # noqa: F401 (fixture)

from mvpose_nodes.body.camera import studio_rig
from mvpose_nodes.ros.camera_bag import frame_stamp_ns
from mvpose_nodes.ros.conversions import (ImageError, calibration_messages, colour_image, compressed_image,
                                          encoded_size, feature_messages, optical_frame, set_stamp, stamp_ns)
from mvpose_nodes.ros.helpers import LATCHED

GOOD_SIZE = (64, 48)   # (width, height) [px] of the corpus' camera


def raw(width, height, encoding, bytes_per_pixel, data=None):
    step = width * bytes_per_pixel
    return Image(width=width, height=height, encoding=encoding, step=step,
                 data=bytes(step * height) if data is None else data)


def jpeg(shape, grey=False):
    ok, data = cv2.imencode('.jpg', np.full(shape, 120, np.uint8))
    return CompressedImage(format='mono8; jpeg compressed mono8' if grey else 'rgb8; jpeg compressed bgr8',
                           data=data.tobytes())


def half(message):
    return CompressedImage(format=message.format, data=bytes(message.data[:len(message.data) // 2]))


# name -> (image message, ImageError kind, a fragment of its text)
IMAGE_CORPUS = {
    'empty Image': (Image(encoding='rgb8'), 'size', 'image is 0×0'),
    'empty CompressedImage': (CompressedImage(format='jpeg'), 'undecodable', 'has no data'),
    '1×1': (raw(1, 1, 'rgb8', 3), 'size', 'image is 1×1'),
    '8000×8000 JPEG': (jpeg((8000, 8000, 3)), 'size', 'image is 8000×8000'),
    'grey (mono8) Image': (raw(64, 48, 'mono8', 1), 'encoding', "'mono8' is not supported"),
    'grey JPEG': (jpeg((48, 64), grey=True), 'mono', 'is not a colour image'),
    '16-bit (rgb16) Image': (raw(64, 48, 'rgb16', 6), 'encoding', "'rgb16' is not supported"),
    '16-bit grey (mono16) Image': (raw(64, 48, 'mono16', 2), 'encoding', "'mono16' is not supported"),
    'JPEG cut in half': (half(jpeg((48, 64, 3))), 'undecodable', 'does not decode'),
    'rows shorter than the width': (raw(64, 48, 'rgb8', 3, data=bytes(100)), 'encoding', 'is shorter than'),
}


@pytest.mark.pure
@pytest.mark.parametrize('name', IMAGE_CORPUS)
def test_a_bad_image_is_refused_with_its_cause(name):
    message, kind, fragment = IMAGE_CORPUS[name]
    with pytest.raises(ImageError, match=fragment) as caught:
        colour_image(message)
    assert caught.value.kind == kind


def calibration(k=3, focal=None, quaternion=None):
    """camera_info and camera_pose of studio camera k at 960×540, with the focal lengths or the
    orientation (x, y, z, w) replaced when given."""
    camera = studio_rig((960, 540), cameras=[k])[0]
    info, pose = calibration_messages(camera, frame_stamp_ns(60))
    if focal is not None:
        k_matrix = list(info.k)
        k_matrix[0] = k_matrix[4] = focal
        info.k = k_matrix
    if quaternion is not None:
        o = pose.pose.orientation
        o.x, o.y, o.z, o.w = quaternion
    return info, pose


@pytest.mark.pure
@pytest.mark.parametrize('case', ['zero focal length', 'NaN focal length', 'inf focal length',
                                  'zero quaternion'])
def test_unusable_calibration_is_refused_with_its_cause(case):
    from mvpose_nodes.ros.conversions import camera_from_messages
    broken = {'zero focal length': dict(focal=0.0), 'NaN focal length': dict(focal=float('nan')),
              'inf focal length': dict(focal=float('inf')), 'zero quaternion': dict(quaternion=(0, 0, 0, 0))}[case]
    fragment = 'unit quaternion' if 'quaternion' in case else 'not a valid intrinsic matrix'
    with pytest.raises(ValueError, match=fragment):
        camera_from_messages(3, *calibration(**broken))


@pytest.mark.pure
@pytest.mark.parametrize('extension, parameters', [('.jpg', []), ('.jpg', [cv2.IMWRITE_JPEG_PROGRESSIVE, 1]),
                                                   ('.png', [])])
def test_a_compressed_image_size_is_read_from_its_header(extension, parameters):
    """The size an image decodes to, read from its header alone (so an oversized one is refused before
    decoding); None for bytes that are neither PNG nor JPEG or end before saying."""
    rng = np.random.default_rng(0)
    for shape in ((48, 64, 3), (1080, 1920, 3), (37, 101)):
        ok, data = cv2.imencode(extension, rng.integers(0, 256, shape, np.uint8), parameters)
        assert encoded_size(data.tobytes()) == (shape[1], shape[0])
        assert encoded_size(data.tobytes()[:20]) is None
    assert encoded_size(b'not an image') is None


@pytest.mark.pure
def test_a_non_unit_quaternion_is_normalised():
    """A camera_pose whose quaternion is twice a unit one (a rounding or a scaling bug upstream) gives
    the same camera as the unit one: rotations are what quaternions of any length stand for."""
    from mvpose_nodes.ros.conversions import camera_from_messages
    info, pose = calibration()
    o = pose.pose.orientation
    unit = camera_from_messages(3, info, pose)
    doubled = camera_from_messages(3, *calibration(quaternion=(2 * o.x, 2 * o.y, 2 * o.z, 2 * o.w)))
    np.testing.assert_allclose(doubled.R, unit.R, atol=1e-12)


@pytest.mark.dds
@pytest.mark.timeout(180)
def test_camera_features_answers_the_image_corpus_and_keeps_working(background, ros_context):
    """Over DDS: the corpus sent to a camera_features node as image_raw and image_raw/compressed, each bad
    image followed by a good one: every bad one is answered STATUS_BAD_INPUT naming its topic, every good
    one is processed; a publisher of the wrong type on image_raw is logged with its type; the node stops
    cleanly."""
    features = background('run', 'camera_features', '--ros-args', '-r', '__ns:=/cam3')
    node = rclpy.create_node('corpus_sender')
    contours = []
    node.create_subscription(LabelledContour, '/cam3/labelled_contour', contours.append, 100)
    raw_publisher = Publisher(node, Image, '/cam3/image_raw', 100)
    compressed_publisher = Publisher(node, CompressedImage, '/cam3/image_raw/compressed', 100)
    good = compressed_image(np.full((GOOD_SIZE[1], GOOD_SIZE[0], 3), (60, 100, 200), np.uint8), 3, 0)
    sent = []   # (stamp [s], topic or None for a good image)
    try:
        Publisher(node, CameraInfo, '/cam3/camera_info', QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)) \
            .publish(CameraInfo(width=GOOD_SIZE[0], height=GOOD_SIZE[1]), timeout=60)
        raw_publisher.wait_for_subscribers(timeout=60)
        compressed_publisher.wait_for_subscribers(timeout=60)
        # A good image, again until its contour comes back: then both directions are matched on both sides.
        good.header.stamp.sec = 1000
        deadline = time.monotonic() + 60
        while not contours and time.monotonic() < deadline:
            compressed_publisher.publisher.publish(good)
            spin_for(node, 0.5)
        assert contours, 'no contour came back within 60 s'
        # One image at a time, each sent when the one before is answered: the node keeps the newest
        # STREAM_DEPTH images of a stream, as a camera wants, so a burst faster than it could be cut.
        for name, (message, _, _) in IMAGE_CORPUS.items():
            publisher = compressed_publisher if isinstance(message, CompressedImage) else raw_publisher
            for image, topic in ((message, publisher.topic), (good, None)):
                stamp = image.header.stamp.sec = len(sent) + 1
                (compressed_publisher if image is good else publisher).publisher.publish(image)
                sent.append((stamp, topic, name))
                spin_until(node, lambda: stamp in {m.header.stamp.sec for m in contours}, 30,
                           f'the labelled contour of {"a good image" if topic is None else name} (stamp {stamp} s)')
        # Another process: one participant cannot have two types on a topic.
        wrong_type = background('topic', 'pub', '/cam3/image_raw', 'std_msgs/msg/String', '{data: not an image}',
                                '--rate', 2)
        spin_until(node, lambda: any(info.topic_type == 'std_msgs/msg/String'
                                     for info in node.get_publishers_info_by_topic('/cam3/image_raw')), 60,
                   'the String publisher in the graph')
        spin_for(node, 2.5)   # two diagnostics periods: the node notices it
    finally:
        node.destroy_node()
    wrong_type.interrupt()
    code, _, err = features.interrupt()
    assert code == 0, err
    by_stamp = {m.header.stamp.sec: m for m in contours}
    for stamp, topic, name in sent:
        answer = by_stamp[stamp]
        if topic is None:
            assert answer.status == LabelledContour.STATUS_NO_PERSON, (name, answer.status_message)
        else:
            assert answer.status == LabelledContour.STATUS_BAD_INPUT and topic in answer.status_message, \
                (name, answer.status_message)
    assert '/cam3/image_raw: a publisher of std_msgs/msg/String (not sensor_msgs/msg/Image)' in err, err


@pytest.mark.dds
@pytest.mark.timeout(180)
def test_calibration_changing_mid_run_is_followed(rendered_features, background, ros_context):  # noqa: F811
    """Over DDS: camera 5's calibration replaced mid-run by an unusable one (zero focal length) and then by
    the good one again: the fitter logs it, goes on without camera 5 (STATUS_LOST: one camera left) and
    uses it again once its calibration is good."""
    fitter = background('run', 'skeleton_fitter', '--ros-args', '-p', f'cameras:={list(CAMERAS)}',
                        '-p', 'request_frames:=false')
    node, received, publishers = feeding_node('calibration_changer')
    stamps = [frame_stamp_ns(60 + i) for i in range(3)]
    try:
        calibration_publishers = {}
        for k, (camera, _) in rendered_features.items():
            for message, topic in zip(calibration_messages(camera, stamps[0]), ('camera_info', 'camera_pose')):
                calibration_publishers[(k, topic)] = Publisher(node, type(message), f'/cam{k}/{topic}', LATCHED)
                calibration_publishers[(k, topic)].publish(message, subscribers=0)
        for publisher in publishers.values():
            publisher.wait_for_subscribers(timeout=30)
        good_info, _ = calibration_messages(rendered_features[5][0], stamps[0])
        broken_info, _ = calibration_messages(rendered_features[5][0], stamps[0])
        broken_info.k = [0.0] * 9
        for stamp, info in zip(stamps, (None, broken_info, good_info)):
            if info is not None:
                calibration_publishers[(5, 'camera_info')].publish(info, subscribers=0)
                spin_for(node, 0.5)
            for k, (camera, features) in rendered_features.items():
                header = set_stamp(Image().header, stamp, optical_frame(k))
                for topic, message in zip(FEATURES, feature_messages(features, header)):
                    publishers[(k, topic)].publisher.publish(message)
            spin_until(node, lambda: any(stamp_ns(m.header) == stamp for m in received), 60,
                       f'a skeleton stamped {stamp}')
    finally:
        node.destroy_node()
    first, broken, mended = (next(m for m in received if stamp_ns(m.header) == s) for s in stamps)
    assert first.status == Skeleton.STATUS_INITIALISING
    assert broken.status == Skeleton.STATUS_LOST, broken.status_message
    assert mended.status in (Skeleton.STATUS_OK, Skeleton.STATUS_INITIALISING), mended.status_message
    code, _, err = fitter.interrupt()
    assert code == 0, err
    assert '/cam5 calibration unusable: camera_info K is not a valid intrinsic matrix' in err, err


# ---- bags ---------------------------------------------------------------------------------------

@pytest.fixture(scope='module')
def odd_bags(tmp_path_factory, synth_bag):
    """{name: path}: an empty bag, a bag with no cameras, and a camera bag whose metadata.yaml lists a
    topic its MCAP lacks and miscounts its messages."""
    from rclpy.serialization import serialize_message

    from mvpose_nodes.io.bagfile import BagWriter
    folder = tmp_path_factory.mktemp('odd_bags')
    with BagWriter(folder / 'empty'):
        pass
    with BagWriter(folder / 'no_cameras') as bag:
        bag.add_topic('/chatter', 'std_msgs/msg/String', [])
        bag.write('/chatter', serialize_message(String(data='hello')), 1)
    shutil.copytree(synth_bag('--cameras', 3, 5, 7, '--frames', '70-74', '--resolution', '960x540'),
                    folder / 'disagreeing')
    metadata_path = folder / 'disagreeing' / 'metadata.yaml'
    metadata = yaml.safe_load(metadata_path.read_text())
    information = metadata['rosbag2_bagfile_information']
    information['message_count'] += 7
    information['topics_with_message_count'][0]['topic_metadata']['name'] = '/cam9/image_raw/compressed'
    metadata_path.write_text(yaml.safe_dump(metadata))
    return {name: folder / name for name in ('empty', 'no_cameras', 'disagreeing')}


@pytest.mark.cli
@pytest.mark.parametrize('name', ['empty', 'no_cameras'])
def test_fitting_a_bag_without_cameras_is_a_one_line_error(odd_bags, tmp_path, name):
    result = run_mvpose('fit', odd_bags[name], '-o', tmp_path / 'out', check=False)
    assert_one_line_error(result, str(odd_bags[name]), 'has no camera images')
    info = run_mvpose('bag', 'info', odd_bags[name])   # the bag itself is fine to look at
    assert 'Messages:' in info.stdout


@pytest.mark.cli
def test_cameras_the_bag_lacks_are_a_one_line_error(odd_bags, tmp_path):
    result = run_mvpose('fit', odd_bags['disagreeing'], '--cameras', 3, 4, '-o', tmp_path / 'out', check=False)
    assert_one_line_error(result, '--cameras', 'has no images of camera 4', 'it has cameras 3 5 7')


@pytest.mark.cli
def test_metadata_that_disagrees_with_the_mcap_is_said_and_the_mcap_is_followed(odd_bags):
    info = run_mvpose('bag', 'info', odd_bags['disagreeing']).stdout
    warning = next(line for line in info.splitlines() if line.startswith('Warning:'))
    assert 'metadata.yaml disagrees with the MCAP' in warning
    assert '/cam9/image_raw/compressed: listed, not in the MCAP' in warning
    assert 'message_count' in warning
    assert 'Topic: /cam9' not in info and 'Messages:          41' in info   # the MCAP's figures
    played = run_mvpose('bag', 'play', odd_bags['disagreeing'], '--topics', '/cam3/camera_pose', '--settle', 0)
    assert 'disagrees with its MCAP, which is played' in played.stderr
    assert '[play] published 1 messages' in played.stderr


@pytest.mark.cli
def test_player_of_an_empty_bag_publishes_nothing_and_says_so(odd_bags):
    played = run_mvpose('bag', 'play', odd_bags['empty'], '--settle', 0)
    assert '[play] published 0 messages on 0 topics' in played.stderr


@pytest.mark.pure
def test_every_case_is_named_in_the_readme():
    """The README's table lists the corpus."""
    readme = (ROOT / 'README.md').read_text()
    table = readme[readme.index('### Bad input'):]
    for name in [*IMAGE_CORPUS, 'zero focal length', 'NaN focal length', 'inf focal length', 'zero quaternion',
                 'non-unit quaternion', 'calibration changing mid-run', 'wrong message type', 'empty bag',
                 'bag with no cameras', 'metadata disagreeing with the MCAP', '--cameras the bag lacks',
                 'two people in view', 'a person leaving the view']:
        assert name in table, name


@pytest.mark.pure
def test_two_people_in_view_the_largest_is_taken_and_it_is_said(cmu_walk):
    """Two people in one camera's view (two renders of the walk, side by side, the nearer one larger): the
    features follow the larger one, and the messages say that another person-sized region was left out."""
    from mvpose_nodes.ros.params import default_skin_model_path
    from mvpose_nodes.studio import scene
    from mvpose_nodes.vision.features import FeatureExtractor, FeatureSettings
    from mvpose_nodes.vision.skin import SkinModel
    camera = studio_rig((960, 540), cameras=[3])[0]
    view = scene.prepare_camera(camera)
    renderings = []
    for center in ((0.0, 0.0), (1.2, -1.2)):
        motion = cmu_walk.placed(center=center, heading=0.8)
        i = len(motion.joints) // 2
        pose = scene.BodyPose(motion.joints[i], motion.toes[i], motion.hand_tips[i], motion.head_forward[i])
        renderings.append(scene.render(view, pose, scene.Appearance()))
    first, second = renderings
    second_only = (second.labels > 0) & (first.labels == 0)
    both = scene.Rendering(np.where(second_only[..., None], second.rgb, first.rgb),
                           np.where(second_only, second.labels, first.labels))
    rgb, _ = scene.Realism().finish(both, view, camera.number, 0, 0)
    alone, _ = scene.Realism().finish(first, view, camera.number, 0, 0)
    extractor = FeatureExtractor(FeatureSettings(), SkinModel.load(default_skin_model_path()))
    features = extractor(rgb)
    assert features.person and features.other_people == 1
    largest = first if (first.labels > 0).sum() > (second.labels > 0).sum() else second
    assert (features.silhouette & (largest.labels > 0)).sum() > 0.9 * features.silhouette.sum()
    assert extractor(alone).other_people == 0
    header = Image().header
    _, contour = feature_messages(features, header)
    assert contour.status == LabelledContour.STATUS_OK
    assert '1 more person-sized region(s) in view' in contour.status_message
