"""The camera_features node over DDS: a small generated bag played into it, features out with the
source stamps; bad input logged, answered with a status, and survived."""
import time

import numpy as np
import pytest
import rclpy
from conftest import assert_one_line_error, run_mvpose
from mvpose_msgs.msg import LabelledContour, SkinEllipseArray
from rclpy.qos import DurabilityPolicy, QoSProfile
from sensor_msgs.msg import CameraInfo, Image

from mvpose_nodes.ros.camera_bag import frame_stamp_ns
from mvpose_nodes.ros.conversions import stamp_ns

FRAMES = (60, 62)
OUTPUTS = {'silhouette': Image, 'skin_ellipses': SkinEllipseArray, 'labelled_contour': LabelledContour}


@pytest.fixture(scope='module')
def small_bag(tmp_path_factory):
    bag = tmp_path_factory.mktemp('node') / 'cam3'
    run_mvpose('synth', '--cameras', 3, '--frames', f'{FRAMES[0]}-{FRAMES[1]}', '--resolution', '640x360',
               '-o', bag, timeout=300)
    return bag


@pytest.fixture
def features_node(background):
    node = background('run', 'camera_features', '--ros-args', '-r', '__ns:=/cam3')
    yield node
    code, _, err = node.interrupt()
    assert code == 0, err


class Listener:
    """This test process's subscriptions to the node's three outputs."""

    def __init__(self):
        self.node = rclpy.create_node('features_listener')
        self.received = {name: [] for name in OUTPUTS}
        for name, kind in OUTPUTS.items():
            self.node.create_subscription(kind, f'/cam3/{name}', self.received[name].append, 50)

    def wait_for_node(self):
        """Until the node's publishers are matched here (what is published before that is lost)."""
        self.spin_until(lambda: all(self.node.count_publishers(f'/cam3/{name}') for name in OUTPUTS))
        self.spin_until(lambda: False, timeout=0.5)

    def spin_until(self, condition, timeout=60):
        deadline = time.monotonic() + timeout
        while not condition() and time.monotonic() < deadline:
            rclpy.spin_once(self.node, timeout_sec=0.05)

    def close(self):
        self.node.destroy_node()


def test_node_publishes_all_three_features_with_the_source_stamps(small_bag, features_node, ros_context):
    listener = Listener()
    try:
        listener.wait_for_node()
        run_mvpose('bag', 'play', small_bag, '--topics', '/cam3/image_raw/compressed', '/cam3/camera_info',
                   '--wait-for-subscribers', '--delay', 0.5, timeout=120)
        frames = FRAMES[1] - FRAMES[0] + 1
        listener.spin_until(lambda: all(len(v) >= frames for v in listener.received.values()))
    finally:
        listener.close()
    expected = [frame_stamp_ns(n) for n in range(FRAMES[0], FRAMES[1] + 1)]
    for name, messages in listener.received.items():
        assert [stamp_ns(m.header) for m in messages] == expected, name
        assert all(m.header.frame_id == 'cam3_optical_frame' for m in messages)
    silhouette = listener.received['silhouette'][0]
    assert (silhouette.width, silhouette.height, silhouette.encoding) == (640, 360, 'mono8')
    assert set(np.frombuffer(bytes(silhouette.data), np.uint8)) == {0, 255}
    contour = listener.received['labelled_contour'][0]
    assert contour.status == LabelledContour.STATUS_OK and len(contour.x) == len(contour.labels) > 100
    ellipses = listener.received['skin_ellipses'][0]
    assert ellipses.status == SkinEllipseArray.STATUS_OK and ellipses.ellipses
    assert {k.name for k in ellipses.keypoints} >= {'head', 'neck'}


def test_bad_input_is_answered_with_a_status_and_the_node_keeps_running(features_node, ros_context):
    listener = Listener()
    node = listener.node
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    info_publisher = node.create_publisher(CameraInfo, '/cam3/camera_info', latched)
    image_publisher = node.create_publisher(Image, '/cam3/image_raw', 10)
    try:
        listener.wait_for_node()
        listener.spin_until(lambda: image_publisher.get_subscription_count() > 0)
        info_publisher.publish(CameraInfo(width=64, height=48))
        time.sleep(0.5)
        bad_encoding = Image(width=64, height=48, encoding='mono16', step=128, data=bytes(64 * 48 * 2))
        wrong_size = Image(width=32, height=24, encoding='rgb8', step=96, data=bytes(32 * 24 * 3))
        empty_scene = Image(width=64, height=48, encoding='rgb8', step=192,
                            data=np.full((48, 64, 3), (60, 100, 200), np.uint8).tobytes())
        for stamp, message in enumerate((bad_encoding, wrong_size, empty_scene, bad_encoding)):
            message.header.stamp.sec = stamp + 1
            image_publisher.publish(message)
        listener.spin_until(lambda: len(listener.received['labelled_contour']) >= 4)
    finally:
        listener.close()
    statuses = [(m.header.stamp.sec, m.status) for m in listener.received['labelled_contour']]
    assert statuses == [(1, LabelledContour.STATUS_BAD_INPUT), (2, LabelledContour.STATUS_BAD_INPUT),
                        (3, LabelledContour.STATUS_NO_PERSON), (4, LabelledContour.STATUS_BAD_INPUT)]
    assert 'mono16' in listener.received['skin_ellipses'][0].status_message
    assert '32×24' in listener.received['skin_ellipses'][1].status_message


def test_node_outside_a_camera_namespace_is_a_one_line_error():
    result = run_mvpose('run', 'camera_features', check=False, timeout=60)
    assert_one_line_error(result, '/cam<K>')


def test_bad_parameter_is_a_one_line_error():
    result = run_mvpose('run', 'camera_features', '--ros-args', '-r', '__ns:=/cam3', '-p', 'sleeves:=medium',
                        check=False, timeout=60)
    assert_one_line_error(result, 'sleeves')
