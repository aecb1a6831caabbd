"""The skeleton_fitter node over DDS, fed features computed here from rendered studio views: a frame set
that two cameras see is fitted; one that only one camera sees gets STATUS_LOST with the last pose."""
import math
import time

import numpy as np
import pytest
import rclpy
from mvpose_msgs.msg import LabelledContour, Skeleton, SkinEllipseArray
from sensor_msgs.msg import Image

from mvpose_nodes.body.camera import studio_rig
from mvpose_nodes.ros.camera_bag import frame_stamp_ns
from mvpose_nodes.ros.conversions import (calibration_messages, empty_feature_messages, feature_messages,
                                          joints_from_skeleton, optical_frame, set_stamp, stamp_ns)
from mvpose_nodes.ros.helpers import LATCHED, wait_for_acknowledgements
from mvpose_nodes.ros.params import default_skin_model_path
from mvpose_nodes.studio import scene
from mvpose_nodes.studio.mocap import cmu_clip, load_bvh, retarget
from mvpose_nodes.vision.features import FeatureExtractor, FeatureSettings
from mvpose_nodes.vision.skin import SkinModel

pytestmark = pytest.mark.dds

CAMERAS = (3, 5)
FEATURES = {'silhouette': Image, 'skin_ellipses': SkinEllipseArray, 'labelled_contour': LabelledContour}


@pytest.fixture(scope='module')
def rendered_features():
    """{camera: (Camera, features.Features)} of one walking frame seen by cameras 3 and 5 at 960×540."""
    motion = retarget(load_bvh(cmu_clip('07_01'))).placed(heading=math.radians(45))
    i = len(motion.joints) // 2
    pose = scene.BodyPose(motion.joints[i], motion.toes[i], motion.hand_tips[i], motion.head_forward[i])
    extractor = FeatureExtractor(FeatureSettings(), SkinModel.load(default_skin_model_path()))
    found = {}
    for camera in studio_rig((960, 540), cameras=list(CAMERAS)):
        view = scene.prepare_camera(camera)
        shadow = scene.shadow_map(scene.body_primitives(pose, scene.Appearance()), pose.joints[0, :2])
        rendering = scene.render(view, pose, scene.Appearance(), shadow, pose.joints[0, :2])
        rgb, _ = scene.Realism().finish(rendering, view, camera.number, 0, 0)
        found[camera.number] = camera, extractor(rgb)
    return found


def spin_until(node, condition, timeout, what):
    deadline = time.monotonic() + timeout
    while not condition() and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.05)
    assert condition(), f'timed out after {timeout} s waiting for {what}'


def test_a_frame_set_seen_by_one_camera_gets_status_lost_with_the_last_pose(rendered_features, background,
                                                                              ros_context):
    fitter = background('run', 'skeleton_fitter', '--ros-args', '-p', f'cameras:={list(CAMERAS)}')
    node = rclpy.create_node('fitter_feeder')
    received = []
    node.create_subscription(Skeleton, '/mvpose/skeleton', received.append, LATCHED)
    publishers = {(k, topic): node.create_publisher(kind, f'/cam{k}/{topic}', 10)
                  for k in CAMERAS for topic, kind in FEATURES.items()}
    try:
        spin_until(node, lambda: all(p.get_subscription_count() for p in publishers.values()), 30,
                   'skeleton_fitter to subscribe to the features')
        first, second = frame_stamp_ns(60), frame_stamp_ns(61)
        calibration = []
        for k, (camera, _) in rendered_features.items():
            for message, topic in zip(calibration_messages(camera, first), ('camera_info', 'camera_pose')):
                calibration.append(node.create_publisher(type(message), f'/cam{k}/{topic}', LATCHED))
                calibration[-1].publish(message)
        spin_until(node, lambda: all(p.get_subscription_count() for p in calibration), 30, 'calibration subscribers')
        wait_for_acknowledgements(calibration, timeout_sec=10.0)
        time.sleep(0.5)   # acknowledged by the fitter's DDS reader: let its executor take them before features
        for stamp in (first, second):
            for k, (camera, features) in rendered_features.items():
                header = Image().header
                set_stamp(header, stamp, optical_frame(k))
                if stamp == second and k == CAMERAS[1]:   # the person has left camera 5's view
                    messages = empty_feature_messages(header, camera.width, camera.height,
                                                      LabelledContour.STATUS_NO_PERSON, 'no person in the image')
                else:
                    messages = feature_messages(features, header)
                for topic, message in zip(FEATURES, messages):
                    publishers[(k, topic)].publish(message)
            spin_until(node, lambda: any(stamp_ns(m.header) == stamp for m in received), 60,
                       f'a skeleton stamped {stamp}')
    finally:
        node.destroy_node()
    fitted, lost = (next(m for m in received if stamp_ns(m.header) == s) for s in (first, second))
    assert fitted.status == Skeleton.STATUS_INITIALISING
    assert lost.status == Skeleton.STATUS_LOST and 'fewer than 2 cameras' in lost.status_message
    np.testing.assert_allclose(joints_from_skeleton(lost), joints_from_skeleton(fitted), atol=1e-9)
    code, _, err = fitter.interrupt()
    assert code == 0, err
