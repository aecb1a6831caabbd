"""marker_tracker: one camera's images -> the 15 joint markers tracked (paper 001).

Started once per camera in its namespace (`./mvpose run marker_tracker --ros-args -r __ns:=/cam3`).
Subscribes image_raw/compressed and image_raw (rgb8/bgr8), and initial_markers (MarkerTracks): the
labelled markers of the calibration frame, as an operator labels them (for synthetic bags, remap it
to ground_truth/markers: only the message with the stamp of the first image is used). Publishes
marker_tracks (MarkerTracks, the image's header): each marker's position and whether it was detected
by colour, predicted (occluded), or lost, and all the red blobs of the image. Images that come before
the calibration frame's labelling are held (the last few) until it comes; earlier ones get no answer.
Bad images are logged once per cause and answered with STATUS_BAD_INPUT; the node keeps running.

When marker_skeleton runs (it publishes marker_tracks_fused in this namespace: the tracks of all
cameras fused in 3D and projected back here), each image waits until the fused tracks of the previous
one have come, at most `fused_wait` seconds, and the tracker continues from them (markers.correct):
identities that the other views contradict are mended, and a hidden marker starts from where the other
views see it.
"""
import time

from mvpose_msgs.msg import MarkerTracks
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from sensor_msgs.msg import CompressedImage, Image

from mvpose_nodes.markers.detection import FLAG_LOST, MARKER_NAMES
from mvpose_nodes.markers.sequencing import LABELLINGS_KEPT, QUEUED_IMAGES_KEPT, FusedTurns, LabelledStart
from mvpose_nodes.markers.tracking import MarkerTracker, NearestNeighbourTracker
from mvpose_nodes.ros.conversions import ImageError, colour_image, marker_tracks, stamp_ns, tracks_from_message
from mvpose_nodes.ros.diagnostics import NodeDiagnostics
from mvpose_nodes.ros.helpers import ReportOnce, camera_of_namespace, run_node
from mvpose_nodes.ros.params import MARKER_TRACKER, ParameterError, changed_values, declare_parameters

STREAM_DEPTH = 5
TRACKERS = {'regions': MarkerTracker, 'nearest': NearestNeighbourTracker}


class MarkerTrackerNode(ReportOnce, Node):
    def __init__(self):
        super().__init__('marker_tracker')
        self.camera = camera_of_namespace(self.get_namespace(), 'marker_tracker')
        self.values = declare_parameters(self, MARKER_TRACKER)
        self.add_on_set_parameters_callback(self.on_set_parameters)
        self.tracker = TRACKERS[self.values['method']]()
        self.start = LabelledStart()
        self.turns = FusedTurns(self.values['fused_wait'])
        self.initialised = False
        self.publisher = self.create_publisher(MarkerTracks, 'marker_tracks', STREAM_DEPTH)
        for kind, topic in ((CompressedImage, 'image_raw/compressed'), (Image, 'image_raw')):
            resolved = self.resolve_topic_name(topic)
            self.create_subscription(kind, topic, lambda message, t=resolved: self.on_image(message, t), STREAM_DEPTH)
        self.labelling_topic = self.resolve_topic_name('initial_markers')
        self.create_subscription(MarkerTracks, 'initial_markers', self.on_labelling, LABELLINGS_KEPT)
        self.fused_topic = self.resolve_topic_name('marker_tracks_fused')
        self.create_subscription(MarkerTracks, 'marker_tracks_fused', self.on_fused, STREAM_DEPTH)
        self.create_timer(0.01, self.track_queued)
        self.counts = {'images': 0, 'images tracked': 0, 'images rejected': 0}
        self.diagnostics = NodeDiagnostics(self, self.state)
        self.get_logger().info(f'camera {self.camera}: {self.values["method"]} marker tracking; waiting for the '
                               f'labelled calibration frame on {self.labelling_topic}')

    def on_set_parameters(self, changes):
        try:
            self.values = changed_values(MARKER_TRACKER, self.values, changes)
        except ParameterError as error:
            return SetParametersResult(successful=False, reason=str(error))
        self.turns.fused_wait = self.values['fused_wait']
        return SetParametersResult(successful=True)

    def on_labelling(self, message):
        """Keep the labelling until its image is there (the two topics race); initialise when it is."""
        if self.initialised:
            return
        for rgb, header in self.start.add_labelling(stamp_ns(message.header), message):
            self.process(rgb, header)

    def state(self):
        """The node's diagnostics: level, message and counters (ros/diagnostics.py)."""
        message = (f"{self.counts['images']} images, {self.counts['images tracked']} tracked"
                   + ('' if self.initialised else f'; waiting for the labelled frame on {self.labelling_topic}'))
        if self.counts['images rejected']:
            return 'warn', f"{message}, {self.counts['images rejected']} rejected", self.counts
        return 'ok', message, self.counts

    def on_image(self, message, topic):
        self.counts['images'] += 1
        try:
            rgb = colour_image(message)
        except ImageError as error:
            return self.reply(message.header, MarkerTracks.STATUS_BAD_INPUT, f'{error.kind}: {topic}', f'{topic}: {error}')
        self.process(rgb, message.header)

    def reply(self, header, status, cause, reason):
        """Publish a MarkerTracks without positions (all lost) carrying `status` and `reason` (logged once)."""
        self.report_once(cause, reason)
        self.counts['images rejected'] += 1
        count = len(MARKER_NAMES)
        self.publisher.publish(marker_tracks(header, [[0.0, 0.0]] * count, [FLAG_LOST] * count, status, reason))

    def process(self, rgb, header):
        labelled = None   # the labelled frame's own tracks: its labelling snapped to the detections
        if not self.initialised:
            stamp = stamp_ns(header)
            labelling = self.start.labelling_for(stamp, (rgb, header))
            if labelling is None:
                # No reply: the image is answered once its labelling comes (a second message of the
                # same stamp would cost the downstream synchroniser that frame).
                return self.report_once('waiting', f'no labelled calibration frame on {self.labelling_topic} for '
                                                   f'the image at {stamp} ns yet: held until it comes')
            try:
                positions, labelled_flags = tracks_from_message(labelling)
            except ValueError as error:
                self.start.reject(stamp)
                return self.reply(header, MarkerTracks.STATUS_BAD_INPUT, 'bad labelling',
                                  f'{self.labelling_topic}: {error}; dropped')
            labelled = self.tracker.initialise(rgb, positions, labelled_flags == MarkerTracks.FLAG_DETECTED)
            self.initialised = True
            self.start.started()
            self.get_logger().info(f'camera {self.camera}: initialised from the labelled frame at {stamp} ns')
        if self.turns.push((rgb, header, labelled)):
            self.report_once('queue', f'more than {QUEUED_IMAGES_KEPT} images waiting for {self.fused_topic}: '
                                      'the oldest are dropped (is fused_wait too long for this image rate?)')
        self.track_queued()

    def track_queued(self):
        """Track the queued images in turn, each once the previous one's fused tracks are in (or fused_wait
        has passed, or nothing publishes them)."""
        while (item := self.turns.next_item(time.monotonic(), self.count_publishers(self.fused_topic) > 0)):
            rgb, header, labelled = item
            positions, flags = self.tracker.track(rgb) if labelled is None else labelled
            self.publisher.publish(marker_tracks(header, positions, flags, blobs=self.tracker.detections))
            self.counts['images tracked'] += 1
            self.turns.sent(stamp_ns(header), time.monotonic())

    def on_fused(self, message):
        """The fused tracks of the last image: the tracker continues from them."""
        if not self.turns.fused(stamp_ns(message.header)):
            return   # late (fused_wait passed) or not ours to wait for
        try:
            positions, flags = tracks_from_message(message)
        except ValueError as error:
            self.report_once('bad fused', f'{self.fused_topic}: {error}; dropped')
        else:
            self.tracker.correct(positions, flags)
        self.track_queued()


def main(args=None):
    return run_node(MarkerTrackerNode, args)
