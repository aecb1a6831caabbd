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
import collections
import time

from mvpose_msgs.msg import MarkerTracks
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor
from rclpy.node import Node
from sensor_msgs.msg import CompressedImage, Image

from mvpose_nodes.tools.cli import UserError
from mvpose_nodes.markers.detection import FLAG_LOST
from mvpose_nodes.markers.tracking import MarkerTracker, NearestNeighbourTracker
from mvpose_nodes.ros.conversions import ImageError, colour_image, marker_tracks, stamp_ns, tracks_from_message
from mvpose_nodes.ros.helpers import ReportOnce, camera_of_namespace, run_node

STREAM_DEPTH = 5
LABELLINGS_KEPT = 50   # initial_markers messages kept while waiting for the image of the same stamp
WAITING_IMAGES_KEPT = 3   # images kept while waiting for the labelling of the same stamp
QUEUED_IMAGES_KEPT = 100  # images kept while waiting for the fused tracks of the previous one
TRACKERS = {'regions': MarkerTracker, 'nearest': NearestNeighbourTracker}


class MarkerTrackerNode(ReportOnce, Node):
    def __init__(self):
        super().__init__('marker_tracker')
        self.camera = camera_of_namespace(self.get_namespace(), 'marker_tracker')
        self.declare_parameter('method', 'regions', ParameterDescriptor(
            description="'regions': paper 001's region-constrained tracking; 'nearest': nearest neighbour "
                        "with constant-velocity prediction (the baseline)", additional_constraints='one of: regions, nearest'))
        method = self.get_parameter('method').value
        if method not in TRACKERS:
            raise UserError(f"parameter 'method' must be one of {', '.join(TRACKERS)}, got {method!r}")
        self.declare_parameter('fused_wait', 1.0, ParameterDescriptor(
            description='[s] longest wait of an image for the fused tracks of the previous one on marker_tracks_fused '
                        '(only while marker_skeleton publishes them); 0: never wait',
            floating_point_range=[FloatingPointRange(from_value=0.0, to_value=60.0, step=0.0)]))
        self.fused_wait = self.get_parameter('fused_wait').value
        self.tracker = TRACKERS[method]()
        self.queue = collections.deque()   # (rgb, header, the labelled frame's tracks or None), in turn
        self.awaited = None                # (stamp [ns] of the last tracks published, when) until their fusion comes
        self.initialised = False
        self.labellings = {}   # stamp [ns] -> initial_markers message
        self.waiting_images = {}   # stamp [ns] -> (rgb, header) of images seen before their labelling
        self.publisher = self.create_publisher(MarkerTracks, 'marker_tracks', STREAM_DEPTH)
        for kind, topic in ((CompressedImage, 'image_raw/compressed'), (Image, 'image_raw')):
            resolved = self.resolve_topic_name(topic)
            self.create_subscription(kind, topic, lambda message, t=resolved: self.on_image(message, t), STREAM_DEPTH)
        self.create_subscription(MarkerTracks, 'initial_markers', self.on_labelling, LABELLINGS_KEPT)
        self.fused_topic = self.resolve_topic_name('marker_tracks_fused')
        self.create_subscription(MarkerTracks, 'marker_tracks_fused', self.on_fused, STREAM_DEPTH)
        self.create_timer(0.01, self.track_queued)
        self.get_logger().info(f'camera {self.camera}: {method} marker tracking; waiting for the labelled '
                               f'calibration frame on {self.resolve_topic_name("initial_markers")}')

    def on_labelling(self, message):
        """Keep the labelling until its image is there (the two topics race); initialise when it is."""
        if self.initialised:
            return
        stamp = stamp_ns(message.header)
        self.labellings[stamp] = message
        while len(self.labellings) > LABELLINGS_KEPT:
            del self.labellings[min(self.labellings)]
        if stamp in self.waiting_images:
            waiting = sorted(self.waiting_images.items())
            self.waiting_images = {}
            for _, (rgb, header) in waiting:   # that image first, then any later one in stamp order
                if stamp_ns(header) >= stamp:
                    self.process(rgb, header)

    def on_image(self, message, topic):
        try:
            rgb = colour_image(message)
        except ImageError as error:
            return self.reply(message.header, MarkerTracks.STATUS_BAD_INPUT, f'{error.kind}: {topic}', f'{topic}: {error}')
        self.process(rgb, message.header)

    def reply(self, header, status, cause, reason):
        """Publish a MarkerTracks without positions (all lost) carrying `status` and `reason` (logged once)."""
        self.report_once(cause, reason)
        self.publisher.publish(marker_tracks(header, [[0.0, 0.0]] * 15, [FLAG_LOST] * 15, status, reason))

    def process(self, rgb, header):
        labelled = None   # the labelled frame's own tracks: its labelling snapped to the detections
        if not self.initialised:
            labelling = self.labellings.get(stamp_ns(header))
            if labelling is None:
                self.waiting_images[stamp_ns(header)] = (rgb, header)
                while len(self.waiting_images) > WAITING_IMAGES_KEPT:
                    del self.waiting_images[min(self.waiting_images)]
                # No reply: the image is answered once its labelling comes (a second message of the
                # same stamp would cost the downstream synchroniser that frame).
                return self.report_once('waiting', f'no labelled calibration frame on '
                                                   f'{self.resolve_topic_name("initial_markers")} for the image at '
                                                   f'{stamp_ns(header)} ns yet: held until it comes')
            try:
                positions, labelled_flags = tracks_from_message(labelling)
            except ValueError as error:
                del self.labellings[stamp_ns(header)]
                return self.reply(header, MarkerTracks.STATUS_BAD_INPUT, 'bad labelling',
                                  f'{self.resolve_topic_name("initial_markers")}: {error}; dropped')
            labelled = self.tracker.initialise(rgb, positions, labelled_flags == MarkerTracks.FLAG_DETECTED)
            self.initialised, self.labellings, self.waiting_images = True, {}, {}
            self.get_logger().info(f'camera {self.camera}: initialised from the labelled frame at {stamp_ns(header)} ns')
        self.queue.append((rgb, header, labelled))
        if len(self.queue) > QUEUED_IMAGES_KEPT:
            self.queue.popleft()
            self.report_once('queue', f'more than {QUEUED_IMAGES_KEPT} images waiting for {self.fused_topic}: '
                                      'the oldest are dropped (is fused_wait too long for this image rate?)')
        self.track_queued()

    def track_queued(self):
        """Track the queued images in turn, each once the previous one's fused tracks are in (or fused_wait
        has passed, or nothing publishes them)."""
        while self.queue:
            if self.awaited is not None and time.monotonic() - self.awaited[1] < self.fused_wait \
                    and self.count_publishers(self.fused_topic) > 0:
                return
            rgb, header, labelled = self.queue.popleft()
            positions, flags = self.tracker.track(rgb) if labelled is None else labelled
            self.publisher.publish(marker_tracks(header, positions, flags, blobs=self.tracker.detections))
            self.awaited = (stamp_ns(header), time.monotonic())

    def on_fused(self, message):
        """The fused tracks of the last image: the tracker continues from them."""
        if self.awaited is None or stamp_ns(message.header) != self.awaited[0]:
            return   # late (fused_wait passed) or not ours to wait for
        try:
            positions, flags = tracks_from_message(message)
        except ValueError as error:
            self.report_once('bad fused', f'{self.fused_topic}: {error}; dropped')
        else:
            self.tracker.correct(positions, flags)
        self.awaited = None
        self.track_queued()


def main(args=None):
    return run_node(MarkerTrackerNode, args)
