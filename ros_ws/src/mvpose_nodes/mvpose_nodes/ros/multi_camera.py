"""The plumbing of the nodes that combine several cameras (skeleton_fitter, marker_skeleton).

Parameters `cameras`, `queue_size`, `max_interval` and `camera_timeout`; per camera, the given input
topics through one approximate-time synchroniser (sync.py; a camera silent for camera_timeout is left
out until it returns), and its camera_info and camera_pose (latched) turned into a Camera once both
are there; problems logged once per cause. A subclass names its inputs and handles each frame set.
"""
from geometry_msgs.msg import PoseStamped
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo

from mvpose_nodes.tools.cli import UserError
from mvpose_nodes.ros.conversions import camera_from_messages, stamp_ns
from mvpose_nodes.ros.helpers import LATCHED, ReportOnce
from mvpose_nodes.fitting.sync import ApproximateTimeSynchronizer


class MultiCameraNode(ReportOnce, Node):
    """A node fed by synchronised per-camera topics. inputs: {relative topic name: message class},
    subscribed as /cam<K>/<name> for each configured camera; on_frame_set(frame_set) gets each
    synchronised set (sync.FrameSet: messages keyed by (camera, name), missing_groups)."""

    def __init__(self, name, inputs, what):
        super().__init__(name)
        self.declare_parameter('cameras', [3, 5, 7], ParameterDescriptor(
            description=f'i3DPost camera numbers whose {what} are combined'))
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
        channels = [(k, topic) for k in cameras for topic in inputs]
        self.sync = ApproximateTimeSynchronizer(
            channels, queue_size=self.get_parameter('queue_size').value,
            max_interval_ns=int(self.get_parameter('max_interval').value * 1e9),
            groups={channel: channel[0] for channel in channels},
            timeout_ns=int(self.get_parameter('camera_timeout').value * 1e9))
        self.calibration = {k: {} for k in cameras}
        self.cameras_known = {}   # camera number -> Camera, from its latest calibration messages
        for k in cameras:
            for topic, kind in inputs.items():
                self.create_subscription(kind, f'/cam{k}/{topic}', self.receiver(k, topic), 10)
            self.create_subscription(CameraInfo, f'/cam{k}/camera_info', self.calibration_receiver(k, 'info'), LATCHED)
            self.create_subscription(PoseStamped, f'/cam{k}/camera_pose', self.calibration_receiver(k, 'pose'), LATCHED)

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

    def receiver(self, camera, topic):
        def receive(message):
            for frame_set in self.sync.add((camera, topic), stamp_ns(message.header), message):
                self.on_frame_set(frame_set)
        return receive

    def camera(self, number):
        """The Camera of `number`, or None (logged once) while its calibration is missing or unusable."""
        camera = self.cameras_known.get(number)
        if camera is None:
            self.report_once(f'calibration {number}', f'no usable camera_info/camera_pose for camera {number}: '
                                                      'its input is not used until they arrive')
        return camera

    def on_frame_set(self, frame_set):
        raise NotImplementedError
