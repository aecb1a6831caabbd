"""The plumbing of the nodes that combine several cameras (skeleton_fitter, marker_skeleton).

Parameters (ros/params.py: multi_camera_parameters) `cameras`, `queue_size`, `max_interval` and
`camera_timeout`, with the node's own; per camera, the given input topics through one
approximate-time synchroniser (fitting/sync.py; a camera silent for camera_timeout is left
out until it returns), and its camera_info and camera_pose (latched) turned into a Camera once both
are there; problems logged once per cause. A subclass names its inputs and handles each frame set.
"""
import time

from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo

from mvpose_nodes.fitting.sync import ApproximateTimeSynchronizer, HeldSets
from mvpose_nodes.ros.conversions import camera_from_messages, stamp_ns
from mvpose_nodes.ros.diagnostics import StageClock
from mvpose_nodes.ros.helpers import LATCHED, ReportOnce
from mvpose_nodes.ros.params import declare_parameters


class MultiCameraNode(ReportOnce, Node):
    """A node fed by synchronised per-camera topics. inputs: {relative topic name: message class},
    subscribed as /cam<K>/<name> for each configured camera; parameters: the node's table
    (ros/params.py, starting with multi_camera_parameters), declared here, values in self.values;
    on_frame_set(frame_set) gets each synchronised set (fitting.sync.SyncedSet: messages keyed by
    (camera, name), missing_groups), after its cameras' calibration (or calibration_wait); synchronised(frame_set)
    as soon as it is synchronised."""

    def __init__(self, name, inputs, parameters):
        super().__init__(name)
        self.values = declare_parameters(self, parameters)
        self.clock = StageClock()   # CPU per stage (ros/diagnostics.py): 'sync' here, the subclass's own
        self.cameras = cameras = self.values['cameras']
        self.sync = self.synchronizer(inputs)
        self.calibration = {k: {} for k in cameras}
        self.cameras_known = {}   # camera number -> Camera, from its latest calibration messages
        # Frame sets that come before a camera's calibration wait for it (calibration_wait), in order.
        self.held = HeldSets(self.values['calibration_wait'])
        self.given_up = set()     # cameras whose calibration a frame set stopped waiting for
        # When the input stops (a bag's end), the last frame sets are still in the synchroniser, waiting
        # for messages that would prove them complete: flushed once nothing has come for camera_timeout.
        # time.monotonic() of the newest input message since the last flush (a subclass's own inputs count
        # too: the skeleton_fitter's frame announcements)
        self.last_input = None
        self.create_timer(0.1, self.flush_when_idle)   # also releases the sets whose calibration wait is over
        for k in cameras:
            for topic, kind in inputs.items():
                self.create_subscription(kind, f'/cam{k}/{topic}', self.receiver(k, topic), 10)
            self.create_subscription(CameraInfo, f'/cam{k}/camera_info', self.calibration_receiver(k, 'info'), LATCHED)
            self.create_subscription(PoseStamped, f'/cam{k}/camera_pose', self.calibration_receiver(k, 'pose'), LATCHED)

    def synchronizer(self, topics):
        """An ApproximateTimeSynchronizer of the configured cameras' `topics` (channels (camera, topic), a
        camera's topics one group) with the node's queue_size, max_interval and camera_timeout; a
        topic whose stamps go back (a bag played again) starts it afresh (the topics arrive in stamp order)."""
        channels = [(k, topic) for k in self.cameras for topic in topics]
        return ApproximateTimeSynchronizer(channels, queue_size=self.values['queue_size'],
                                           max_interval_ns=int(self.values['max_interval'] * 1e9),
                                           groups={channel: channel[0] for channel in channels},
                                           timeout_ns=int(self.values['camera_timeout'] * 1e9),
                                           restart_ns=0)

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
                self.given_up.discard(camera)
                self.release_held()
        return receive

    def receiver(self, camera, topic):
        def receive(message):
            self.last_input = time.monotonic()
            restarts = self.sync.restarts
            with self.clock('sync'):
                self.hold(self.sync.add((camera, topic), stamp_ns(message.header), message))
            if self.sync.restarts != restarts:
                self.get_logger().info(f'/cam{camera}/{topic} went back in time (a bag played again?): '
                                       'synchronising afresh')
            self.release_held()
        return receive

    def flush_when_idle(self):
        """Once no input has come for camera_timeout [s] of wall time, the frame sets the synchroniser still
        holds (ApproximateTimeSynchronizer.flush), then end_of_input for the subclass's own; and the held
        sets released (release_held: calibration_wait runs out without input too)."""
        if self.last_input is not None and time.monotonic() - self.last_input > self.values['camera_timeout']:
            self.last_input = None
            with self.clock('sync'):
                self.hold(self.sync.flush())
            self.end_of_input()
        self.release_held()

    def hold(self, frame_sets):
        """Synchronised frame sets in, held until their calibration is in (release_held)."""
        for frame_set in frame_sets:
            self.synchronised(frame_set)
            self.held.add(frame_set, time.monotonic())

    def synchronised(self, frame_set):
        """Called as each frame set is synchronised, before it waits for calibration (on_frame_set comes after)."""

    def end_of_input(self):
        """Called when the input has stopped (flush_when_idle): flush any synchroniser of the subclass's own."""

    def awaited_cameras(self, frame_set):
        """The cameras of a frame set whose calibration has not come (and is still waited for)."""
        present = {camera for camera, _ in frame_set.messages}
        return {k for k in present if len(self.calibration[k]) < 2 and k not in self.given_up}

    def release_held(self):
        """Handle the held frame sets whose calibration is in, or that waited calibration_wait."""
        for frame_set in self.held.release(time.monotonic(), lambda s: not self.awaited_cameras(s)):
            missing = self.awaited_cameras(frame_set)
            if missing:
                self.given_up |= missing
                self.report_once('calibration wait', f'no camera_info/camera_pose for camera(s) {sorted(missing)} '
                                                     f"within calibration_wait ({self.held.wait:g} s): going on "
                                                     'without them until they come')
            self.on_frame_set(frame_set)

    def camera(self, number):
        """The Camera of `number`, or None (logged once) while its calibration is missing or unusable."""
        camera = self.cameras_known.get(number)
        if camera is None:
            self.report_once(f'calibration {number}', f'no usable camera_info/camera_pose for camera {number}: '
                                                      'its input is not used until they arrive')
        return camera

    def on_frame_set(self, frame_set):
        raise NotImplementedError
