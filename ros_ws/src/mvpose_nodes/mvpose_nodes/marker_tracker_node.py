"""marker_tracker: one camera's images -> the 15 joint markers tracked (paper 001).

Started once per camera in its namespace (`./mvpose run marker_tracker --ros-args -r __ns:=/cam3`).
Subscribes image_raw/compressed and image_raw (rgb8/bgr8), and initial_markers (MarkerTracks): the
labelled markers of the calibration frame, as an operator labels them (for synthetic bags, remap it
to ground_truth/markers: only the message with the stamp of the first image is used). Publishes
marker_tracks (MarkerTracks, the image's header): each marker's position and whether it was detected
by colour, predicted (occluded), or lost. Images that come before the calibration frame's labelling
are held (the last few) until it comes; earlier ones get no answer. Bad images are logged once per cause and answered with
STATUS_BAD_INPUT; the node keeps running.
"""
from mvpose_msgs.msg import MarkerTracks
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from sensor_msgs.msg import CompressedImage, Image

from mvpose_nodes.errors import UserError
from mvpose_nodes.markers import FLAG_LOST, MarkerTracker, NearestNeighbourTracker
from mvpose_nodes.rosconv import ImageError, colour_image, marker_tracks, stamp_ns, tracks_from_message
from mvpose_nodes.rosutil import ReportOnce, camera_of_namespace, run_node

STREAM_DEPTH = 5
LABELLINGS_KEPT = 50   # initial_markers messages kept while waiting for the image of the same stamp
WAITING_IMAGES_KEPT = 3   # images kept while waiting for the labelling of the same stamp
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
        self.tracker = TRACKERS[method]()
        self.initialised = False
        self.labellings = {}   # stamp [ns] -> initial_markers message
        self.waiting_images = {}   # stamp [ns] -> (rgb, header) of images seen before their labelling
        self.publisher = self.create_publisher(MarkerTracks, 'marker_tracks', STREAM_DEPTH)
        for kind, topic in ((CompressedImage, 'image_raw/compressed'), (Image, 'image_raw')):
            resolved = self.resolve_topic_name(topic)
            self.create_subscription(kind, topic, lambda message, t=resolved: self.on_image(message, t), STREAM_DEPTH)
        self.create_subscription(MarkerTracks, 'initial_markers', self.on_labelling, LABELLINGS_KEPT)
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
            self.tracker.initialise(rgb, positions, labelled_flags == MarkerTracks.FLAG_DETECTED)
            self.initialised, self.labellings, self.waiting_images = True, {}, {}
            self.get_logger().info(f'camera {self.camera}: initialised from the labelled frame at {stamp_ns(header)} ns')
        positions, flags = self.tracker.track(rgb)
        self.publisher.publish(marker_tracks(header, positions, flags))


def main(args=None):
    return run_node(MarkerTrackerNode, args)
