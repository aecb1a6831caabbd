"""skeleton_fitter: the cameras' features -> the fitted 15-joint skeleton (paper 000 Sec. 4–6, paper 004).

For each configured camera it subscribes /cam<K>/silhouette, /cam<K>/skin_ellipses and
/cam<K>/labelled_contour (through an approximate-time synchroniser: sync.py) and the camera's
camera_info and camera_pose. Every synchronised frame set is fitted (fitter.py) and published as
/mvpose/skeleton (mvpose_msgs/Skeleton: joint poses, the 29 parameters, the six stages), the 29
parameters as /mvpose/joint_states (sensor_msgs/JointState), and /mvpose/skeleton_markers
(visualization_msgs/MarkerArray in `world`, for RViz and Foxglove). A camera whose features stop is
left out after camera_timeout (status DEGRADED) and rejoins when they come back.
"""
from geometry_msgs.msg import PoseStamped
from mvpose_msgs.msg import LabelledContour, Skeleton, SkinEllipseArray
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image, JointState
from visualization_msgs.msg import MarkerArray

from mvpose_nodes.body_model import PARAMETER_NAMES
from mvpose_nodes.errors import UserError
from mvpose_nodes.fitter import SkeletonFitter, view_from_features
from mvpose_nodes.rosconv import (camera_from_messages, contour_from_message, joint_state, keypoints_from_messages,
                                  skeleton_markers, skeleton_message, stage_messages, stamp_ns)
from mvpose_nodes.rosutil import LATCHED, run_node
from mvpose_nodes.sync import ApproximateTimeSynchronizer

FEATURES = {'silhouette': Image, 'skin_ellipses': SkinEllipseArray, 'labelled_contour': LabelledContour}


class SkeletonFitterNode(Node):
    def __init__(self):
        super().__init__('skeleton_fitter')
        self.declare_parameter('cameras', [3, 5, 7], ParameterDescriptor(
            description='i3DPost camera numbers whose features are fitted (each needs a camera_features in /cam<K>)'))
        self.declare_parameter('queue_size', 10, ParameterDescriptor(
            description='messages kept per input topic while frame sets are matched',
            integer_range=[IntegerRange(from_value=1, to_value=1000, step=1)]))
        self.declare_parameter('max_interval', 0.02, ParameterDescriptor(
            description='[s] largest stamp spread within one frame set',
            floating_point_range=[FloatingPointRange(from_value=0.0, to_value=10.0, step=0.0)]))
        self.declare_parameter('camera_timeout', 1.0, ParameterDescriptor(
            description='[s] of input time after which a silent camera is left out (status DEGRADED)',
            floating_point_range=[FloatingPointRange(from_value=0.01, to_value=60.0, step=0.0)]))
        cameras = list(self.get_parameter('cameras').value)
        if not cameras or len(set(cameras)) != len(cameras) or any(not 1 <= k <= 99 for k in cameras):
            raise UserError(f"parameter 'cameras' must list distinct camera numbers, got {cameras}")
        self.cameras = cameras
        channels = [(k, name) for k in cameras for name in FEATURES]
        self.sync = ApproximateTimeSynchronizer(
            channels, queue_size=self.get_parameter('queue_size').value,
            max_interval_ns=int(self.get_parameter('max_interval').value * 1e9),
            groups={channel: channel[0] for channel in channels},
            timeout_ns=int(self.get_parameter('camera_timeout').value * 1e9))
        self.calibration = {k: {} for k in cameras}
        self.cameras_known = {}   # camera number -> Camera, from its latest calibration messages
        self.fitter = SkeletonFitter()
        self.reported = set()
        for k in cameras:
            for name, kind in FEATURES.items():
                self.create_subscription(kind, f'/cam{k}/{name}', self.receiver(k, name), 10)
            self.create_subscription(CameraInfo, f'/cam{k}/camera_info', self.calibration_receiver(k, 'info'), LATCHED)
            self.create_subscription(PoseStamped, f'/cam{k}/camera_pose', self.calibration_receiver(k, 'pose'), LATCHED)
        self.skeleton_publisher = self.create_publisher(Skeleton, '/mvpose/skeleton', LATCHED)
        self.joint_state_publisher = self.create_publisher(JointState, '/mvpose/joint_states', 10)
        self.marker_publisher = self.create_publisher(MarkerArray, '/mvpose/skeleton_markers', 10)
        self.get_logger().info(f'fitting cameras {cameras}')

    def report_once(self, cause, text):
        if cause not in self.reported:
            self.reported.add(cause)
            self.get_logger().warning(text)

    def calibration_receiver(self, camera, kind):
        """Keep the camera's messages; once both are there, its Camera (converted once, not per frame)."""
        def receive(message):
            parts = self.calibration[camera]
            parts[kind] = message
            if 'info' in parts and 'pose' in parts:
                try:
                    self.cameras_known[camera] = camera_from_messages(camera, parts['info'], parts['pose'])
                except ValueError as error:
                    self.cameras_known.pop(camera, None)
                    self.report_once(f'bad calibration {camera}', f'/cam{camera} calibration unusable: {error}')
        return receive

    def receiver(self, camera, name):
        def receive(message):
            for frame_set in self.sync.add((camera, name), stamp_ns(message.header), message):
                self.fit(frame_set)
        return receive

    def camera(self, number):
        camera = self.cameras_known.get(number)
        if camera is None:
            self.report_once(f'calibration {number}', f'no usable camera_info/camera_pose for camera {number}: '
                                                      'its features are not used until they arrive')
        return camera

    def fit(self, frame_set):
        views = []
        for number in self.cameras:
            if (number, 'labelled_contour') not in frame_set.messages:
                continue
            camera = self.camera(number)
            ellipses = frame_set.messages[(number, 'skin_ellipses')]
            contour = frame_set.messages[(number, 'labelled_contour')]
            if camera is None or contour.status != LabelledContour.STATUS_OK:
                continue
            try:
                labels = contour_from_message(contour)
            except ValueError as error:
                self.report_once(f'contour {number}', f'/cam{number}/labelled_contour: {error}; dropped')
                continue
            views.append(view_from_features(camera, keypoints_from_messages(ellipses, contour), labels,
                                            ellipses.face_visibility))
        stamp = frame_set.stamp_ns
        if len(views) < 2:
            self.report_once('few views', f'fewer than 2 cameras with a person at {stamp} ns: no fit '
                                          '(logged once; the node keeps waiting)')
            return
        try:
            fit = self.fitter.fit(stamp / 1e9, views)
        except ValueError as error:
            self.report_once('fit', f'no fit at {stamp} ns: {error}')
            return
        used = {v.camera.number for v in views}
        degraded = bool(frame_set.missing_groups) or used != set(self.cameras) or not all(s.fitted for s in fit.stages)
        status = (Skeleton.STATUS_INITIALISING if fit.initialised
                  else Skeleton.STATUS_DEGRADED if degraded else Skeleton.STATUS_OK)
        reason = f'cameras used: {sorted(used)}' if degraded else ''
        message = skeleton_message(fit.joints, stamp, parameter_names=list(PARAMETER_NAMES),
                                   parameters=fit.parameters.tolist(), stages=stage_messages(fit.stages),
                                   status=status, status_message=reason, fit_time=fit.seconds)
        self.skeleton_publisher.publish(message)
        self.joint_state_publisher.publish(joint_state(fit.parameters, message.header))
        self.marker_publisher.publish(skeleton_markers(fit.joints, message.header, status))


def main(args=None):
    return run_node(SkeletonFitterNode, args)
