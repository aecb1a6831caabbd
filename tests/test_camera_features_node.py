"""The camera_features node over DDS: a small generated bag played into it, features out with the
source stamps; bad input logged, answered with a status, and survived. Its one-line errors when it
cannot start: test_front_door.py."""
import time

import numpy as np
import pytest
import rclpy
from common import Publisher, run_mvpose, spin_for, spin_until
from mvpose_msgs.msg import LabelledContour, SkinEllipseArray
from rclpy.qos import DurabilityPolicy, QoSProfile
from sensor_msgs.msg import CameraInfo, CompressedImage, Image
from std_msgs.msg import Header

from mvpose_nodes.ros.camera_bag import frame_stamp_ns
from mvpose_nodes.ros.conversions import image_from_compressed, set_stamp, stamp_ns

pytestmark = pytest.mark.dds

FRAMES = (60, 62)
OUTPUTS = {'silhouette': Image, 'silhouette/compressed': CompressedImage, 'skin_ellipses': SkinEllipseArray,
           'labelled_contour': LabelledContour}


@pytest.fixture(scope='module')
def small_bag(synth_bag):
    return synth_bag('--cameras', 3, '--frames', f'{FRAMES[0]}-{FRAMES[1]}', '--resolution', '640x360')


@pytest.fixture
def features_node(background):
    node = background('run', 'camera_features', '--ros-args', '-r', '__ns:=/cam3')
    yield node
    code, _, err = node.interrupt()
    assert code == 0, err


class Listener:
    """This test process's subscriptions to the node's outputs."""

    def __init__(self):
        self.node = rclpy.create_node('features_listener')
        self.received = {name: [] for name in OUTPUTS}
        for name, kind in OUTPUTS.items():
            self.node.create_subscription(kind, f'/cam3/{name}', self.received[name].append, 50)

    def wait_for_node(self):
        """Until the node's publishers are matched here (what is published before that is lost)."""
        spin_until(self.node, lambda: all(self.node.count_publishers(f'/cam3/{name}') for name in OUTPUTS), 60,
                   "camera_features' publishers")
        spin_for(self.node, 0.5)

    def close(self):
        self.node.destroy_node()


def test_node_publishes_every_feature_with_the_source_stamps(small_bag, features_node, ros_context):
    listener = Listener()
    try:
        listener.wait_for_node()
        run_mvpose('bag', 'play', small_bag, '--topics', '/cam3/image_raw/compressed', '/cam3/camera_info',
                   '--wait-for-subscribers', timeout=120)
        frames = FRAMES[1] - FRAMES[0] + 1
        spin_until(listener.node, lambda: all(len(v) >= frames for v in listener.received.values()), 60,
                   f'{frames} messages on each output')
    finally:
        listener.close()
    expected = [frame_stamp_ns(n) for n in range(FRAMES[0], FRAMES[1] + 1)]
    for name, messages in listener.received.items():
        assert [stamp_ns(m.header) for m in messages] == expected, name
        assert all(m.header.frame_id == 'cam3_optical_frame' for m in messages)
    silhouette = listener.received['silhouette'][0]
    assert (silhouette.width, silhouette.height, silhouette.encoding) == (640, 360, 'mono8')
    assert set(np.frombuffer(bytes(silhouette.data), np.uint8)) == {0, 255}
    compressed = listener.received['silhouette/compressed'][0]
    assert compressed.format == 'mono8; png compressed mono8' and len(compressed.data) < len(silhouette.data) / 20
    assert np.array_equal(image_from_compressed(compressed),
                          np.frombuffer(bytes(silhouette.data), np.uint8).reshape(360, 640)), 'lossless'
    contour = listener.received['labelled_contour'][0]
    assert contour.status == LabelledContour.STATUS_OK and len(contour.x) == len(contour.labels) > 100
    ellipses = listener.received['skin_ellipses'][0]
    assert ellipses.status == SkinEllipseArray.STATUS_OK and ellipses.ellipses
    assert {k.name for k in ellipses.keypoints} >= {'head', 'neck'}


def test_with_a_requester_the_node_announces_every_image_and_computes_only_the_requested(
        small_bag, features_node, ros_context):
    """Issue 14: while something publishes frame_request (the skeleton_fitter), each image is only
    announced on frame_available; features come for the stamps requested, the older held images are
    skipped and counted, and a request for an image not held is not answered."""
    from diagnostic_msgs.msg import DiagnosticArray
    listener = Listener()
    announced, diagnostics = [], []
    listener.node.create_subscription(Header, '/cam3/frame_available', announced.append, 50)
    listener.node.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append, 50)
    requests = Publisher(listener.node, Header, '/cam3/frame_request', 10)
    stamps = [frame_stamp_ns(n) for n in range(FRAMES[0], FRAMES[1] + 1)]

    def request(stamp):
        requests.publish(set_stamp(Header(), stamp, 'cam3_optical_frame'))
    try:
        listener.wait_for_node()
        requests.wait_for_subscribers()
        spin_for(listener.node, 1.0)   # the node sees its requester
        run_mvpose('bag', 'play', small_bag, '--topics', '/cam3/image_raw/compressed', '/cam3/camera_info',
                   '--wait-for-subscribers', timeout=120)
        spin_until(listener.node, lambda: len(announced) == len(stamps), 30, 'every image announced')
        spin_for(listener.node, 1.0)
        assert listener.received['labelled_contour'] == [], 'no features before a request'
        request(stamps[1])
        spin_until(listener.node, lambda: listener.received['labelled_contour'], 30, 'the requested features')
        request(stamps[0])   # passed over when stamps[1] was requested: no longer held
        spin_for(listener.node, 1.0)
        spin_until(listener.node, lambda: any(v.key == 'images not requested' and v.value == '1'
                                              for array in diagnostics for status in array.status
                                              for v in status.values), 10, 'one image counted as not requested')
    finally:
        listener.close()
    assert [stamp_ns(m) for m in announced] == stamps
    assert all(m.frame_id == 'cam3_optical_frame' for m in announced)
    for name in ('labelled_contour', 'skin_ellipses'):
        assert [stamp_ns(m.header) for m in listener.received[name]] == [stamps[1]], name
    assert listener.received['labelled_contour'][0].status == LabelledContour.STATUS_OK


def test_bad_input_is_answered_with_a_status_and_the_node_keeps_running(features_node, ros_context):
    listener = Listener()
    node = listener.node
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    info_publisher = Publisher(node, CameraInfo, '/cam3/camera_info', latched)
    image_publisher = Publisher(node, Image, '/cam3/image_raw', 10)
    try:
        listener.wait_for_node()
        image_publisher.wait_for_subscribers(timeout=60)
        info_publisher.publish(CameraInfo(width=64, height=48), timeout=60)
        time.sleep(0.5)
        bad_encoding = Image(width=64, height=48, encoding='mono16', step=128, data=bytes(64 * 48 * 2))
        wrong_size = Image(width=32, height=24, encoding='rgb8', step=96, data=bytes(32 * 24 * 3))
        empty_scene = Image(width=64, height=48, encoding='rgb8', step=192,
                            data=np.full((48, 64, 3), (60, 100, 200), np.uint8).tobytes())
        for stamp, message in enumerate((bad_encoding, wrong_size, empty_scene, bad_encoding)):
            message.header.stamp.sec = stamp + 1
            image_publisher.publish(message)
        spin_until(node, lambda: len(listener.received['labelled_contour']) >= 4, 60, '4 labelled contours')
    finally:
        listener.close()
    statuses = [(m.header.stamp.sec, m.status) for m in listener.received['labelled_contour']]
    assert statuses == [(1, LabelledContour.STATUS_BAD_INPUT), (2, LabelledContour.STATUS_BAD_INPUT),
                        (3, LabelledContour.STATUS_NO_PERSON), (4, LabelledContour.STATUS_BAD_INPUT)]
    assert 'mono16' in listener.received['skin_ellipses'][0].status_message
    assert '32×24' in listener.received['skin_ellipses'][1].status_message
