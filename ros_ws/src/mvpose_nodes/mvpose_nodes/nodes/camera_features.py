"""camera_features: one camera's images -> silhouette, skin ellipses and labelled contour (paper 000 Sec. 3).

Started once per camera in its namespace, which gives the camera number:
    ./mvpose run camera_features --ros-args -r __ns:=/cam3
Subscribes image_raw/compressed and image_raw (rgb8/bgr8), and camera_info (to check image sizes);
publishes skin_ellipses, labelled_contour, the silhouette (mono8 0/255) as silhouette/compressed (PNG)
and silhouette (sensor_msgs/Image; 2 MB at 1080p), and with publish_overlay features_overlay, each with
the source image's header unchanged. The silhouettes are made only while something subscribes to them.
While a skeleton_fitter asks for frames on frame_request (std_msgs/Header: the stamp of the image it
wants) and follow_requests is on, the node keeps the newest images undecoded, announces each one's header
on frame_available, and computes features only for the images asked for; the others are skipped
(counted). Every camera then skips the same frames, so a graph slower than the cameras loses whole frame
sets and no camera works on one that will not be fitted.
Its state and CPU per stage (decode, features, conversion, publish) go to /diagnostics once a second. Bad input (undecodable or wrongly
encoded images, sizes that disagree with camera_info, no person) is logged once per cause and
answered with empty features carrying a status; the node keeps running.
"""
import collections

import cv2
import numpy as np
from mvpose_msgs.msg import LabelledContour, SkinEllipseArray
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, CompressedImage, Image
from std_msgs.msg import Header

from mvpose_nodes.ros.conversions import (ImageError, colour_image, empty_feature_messages, feature_messages, mono_image,
                                          png_mono, rgb_image, stamp_ns)
from mvpose_nodes.ros.diagnostics import NodeDiagnostics, StageClock
from mvpose_nodes.ros.helpers import LATCHED, ReportOnce, camera_of_namespace, run_node
from mvpose_nodes.ros.params import (CAMERA_FEATURES, ParameterError, changed_values, declare_parameters,
                                     default_skin_model_path, feature_settings_from)
from mvpose_nodes.vision.features import FeatureExtractor, draw_features
from mvpose_nodes.vision.silhouette import BackgroundLearner
from mvpose_nodes.vision.skin import SkinModel, SkinModelError, warm_up

STREAM_DEPTH = 5
# Images kept for the fitter's requests: 0.4 s at 25 fps, far longer than a request takes to follow the
# announcement of its image (a DDS round trip and the fitter's executor).
HELD_IMAGES = 10


class CameraFeaturesNode(ReportOnce, Node):
    def __init__(self):
        super().__init__('camera_features')
        self.camera = camera_of_namespace(self.get_namespace(), 'camera_features')
        self.values = declare_parameters(self, CAMERA_FEATURES)
        cv2.setNumThreads(self.values['opencv_threads'] or -1)   # OpenCV: a negative count is its default
        warm_up()
        self.extractor = self.make_extractor(self.values)
        self.background = BackgroundLearner(self.values['background_frames'])
        self.add_on_set_parameters_callback(self.on_set_parameters)
        self.camera_info = None
        self.silhouette_publisher = self.create_publisher(Image, 'silhouette', STREAM_DEPTH)
        self.compressed_silhouette_publisher = self.create_publisher(CompressedImage, 'silhouette/compressed',
                                                                     STREAM_DEPTH)
        self.ellipses_publisher = self.create_publisher(SkinEllipseArray, 'skin_ellipses', STREAM_DEPTH)
        self.contour_publisher = self.create_publisher(LabelledContour, 'labelled_contour', STREAM_DEPTH)
        self.overlay_publisher = self.create_publisher(Image, 'features_overlay', STREAM_DEPTH)
        for kind, topic in ((CompressedImage, 'image_raw/compressed'), (Image, 'image_raw')):
            resolved = self.resolve_topic_name(topic)
            self.create_subscription(kind, topic, lambda message, t=resolved: self.on_image(message, t), STREAM_DEPTH)
        self.create_subscription(CameraInfo, 'camera_info', self.on_camera_info, LATCHED)
        self.request_topic = self.resolve_topic_name('frame_request')
        self.available_publisher = self.create_publisher(Header, 'frame_available', STREAM_DEPTH)
        self.create_subscription(Header, 'frame_request', self.on_request, STREAM_DEPTH)
        self.held = collections.OrderedDict()   # stamp [ns] -> (image message, its topic), oldest first
        self.clock = StageClock()   # CPU per stage: decode, features, conversion, publish
        self.counts = {'images': 0, 'images with a person': 0, 'images rejected': 0, 'images not requested': 0,
                       'features nobody subscribed to': 0}
        self.last_problem = ''
        self.diagnostics = NodeDiagnostics(self, self.state, [self.clock])
        self.get_logger().info(f'camera {self.camera}: {self.values["silhouette_method"]} silhouettes, '
                               f'skin model {self.values["skin_model"] or default_skin_model_path()}')

    def make_extractor(self, values):
        path = values['skin_model'] or default_skin_model_path()
        return FeatureExtractor(feature_settings_from(values), SkinModel.load(path))

    def on_set_parameters(self, changes):
        try:
            values = changed_values(CAMERA_FEATURES, self.values, changes)
            self.extractor = self.make_extractor(values)
        except (ParameterError, SkinModelError) as error:
            return SetParametersResult(successful=False, reason=str(error))
        self.values = values
        self.background = BackgroundLearner(values['background_frames'])
        return SetParametersResult(successful=True)

    def on_camera_info(self, message):
        if message.width <= 0 or message.height <= 0:
            self.report_once('bad camera_info', f'{self.resolve_topic_name("camera_info")}: no image size '
                                                f'({message.width}×{message.height}); sizes are not checked')
            return
        self.camera_info = message

    def on_image(self, message, topic):
        self.counts['images'] += 1
        if not self.following_requests():
            return self.compute(message, topic)
        self.held[stamp_ns(message.header)] = (message, topic)
        while len(self.held) > HELD_IMAGES:
            self.held.popitem(last=False)
            self.counts['images not requested'] += 1
        self.available_publisher.publish(message.header)

    def following_requests(self):
        """Whether images wait for requests: follow_requests is on, something publishes frame_request and
        has matched frame_available (an announcement that nobody hears would never be requested), and no
        background is still to be learned (that needs every image)."""
        learning = self.values['silhouette_method'] == 'background' and self.extractor.background is None
        return (self.values['follow_requests'] and not learning and self.count_publishers(self.request_topic) > 0
                and self.available_publisher.get_subscription_count() > 0)

    def on_request(self, header):
        """Features of the held image stamped as `header`; the older held images are skipped (the fitter
        asks for the newest set it can fit, so it will not ask for them)."""
        stamp = stamp_ns(header)
        if stamp not in self.held:
            return self.report_once('request miss', f'{self.request_topic}: no image stamped {stamp} ns is held '
                                                    f'(the newest {HELD_IMAGES} are); not answered (logged once)')
        while True:
            held_stamp, (message, topic) = self.held.popitem(last=False)
            if held_stamp == stamp:
                return self.compute(message, topic)
            self.counts['images not requested'] += 1

    def compute(self, message, topic):
        """Decode one image message and publish its features."""
        try:
            with self.clock('decode'):
                rgb = colour_image(message)
        except ImageError as error:
            return self.reject(message.header, *error.size, f'{error.kind}: {topic}', f'{topic}: {error}')
        try:
            self.process(rgb, message.header, topic)
        except Exception as error:   # a bug must not stop the camera: say it, answer with a status, go on
            self.reject(message.header, rgb.shape[1], rgb.shape[0], f'failure: {topic}',
                        f'{topic}: features failed ({type(error).__name__}: {error})')

    def reject(self, header, width, height, cause, reason):
        self.counts['images rejected'] += 1
        self.last_problem = reason
        self.report_once(cause, f'{reason}; publishing empty features with STATUS_BAD_INPUT')
        self.publish(np.zeros((max(height, 0), max(width, 0)), bool), header,
                     *empty_feature_messages(header, LabelledContour.STATUS_BAD_INPUT, reason))

    def process(self, rgb, header, topic):
        height, width = rgb.shape[:2]
        if self.camera_info is None:
            self.report_once('no camera_info', f'no camera_info on {self.resolve_topic_name("camera_info")} yet: '
                                               'image sizes are not checked until it arrives')
        elif (self.camera_info.width, self.camera_info.height) != (width, height):
            return self.reject(header, width, height, f'size: {topic}',
                               f'{topic}: image is {width}×{height} but camera_info says '
                               f'{self.camera_info.width}×{self.camera_info.height}')
        if self.values['silhouette_method'] == 'background' and self.extractor.background is None:
            self.extractor.background = self.background.add(rgb)
            if self.extractor.background is None:
                return self.reject(header, width, height, 'learning', 'learning the background from the first '
                                   f"{self.values['background_frames']} frames (no person expected in them)")
            return
        with self.clock('features'):
            features = self.extractor(rgb)
        if not features.person:
            self.report_once('no person', f'{topic}: no person found (publishing empty features, '
                                          'STATUS_NO_PERSON; logged once)')
        else:
            self.counts['images with a person'] += 1
        with self.clock('conversion'):
            messages = feature_messages(features, header)
        self.publish(features.silhouette, header, *messages)
        if self.values['publish_overlay']:
            self.overlay_publisher.publish(rgb_image(draw_features(rgb, features), header))

    def publish(self, silhouette, header, ellipses, contour):
        """silhouette: (H, W) bool, the person's pixels."""
        # The silhouettes are for people and tools to look at (the fitter reads the contour): made only
        # while something subscribes, as image_transport publishes.
        wanted = [(publisher, make) for publisher, make in (
            (self.compressed_silhouette_publisher, png_mono), (self.silhouette_publisher, mono_image))
            if publisher.get_subscription_count()]
        with self.clock('conversion'):
            mask = silhouette.astype(np.uint8) * 255 if wanted else None
            silhouettes = [(publisher, make(mask, header)) for publisher, make in wanted]
        if not (wanted or self.ellipses_publisher.get_subscription_count()
                or self.contour_publisher.get_subscription_count()):
            self.counts['features nobody subscribed to'] += 1   # lost, but not silently: on /diagnostics
        with self.clock('publish'):
            for publisher, message in silhouettes:
                publisher.publish(message)
            self.ellipses_publisher.publish(ellipses)
            self.contour_publisher.publish(contour)

    def state(self):
        """The node's diagnostics: level, message and counters (ros/diagnostics.py)."""
        counts = self.counts
        if not counts['images']:
            return 'ok', 'no image yet', counts
        message = f"{counts['images']} images, {counts['images with a person']} with a person"
        if counts['images not requested']:
            message += f", {counts['images not requested']} not requested by the fitter (skipped)"
        if counts['features nobody subscribed to']:
            message += f", the features of {counts['features nobody subscribed to']} published with no subscriber"
        if counts['images rejected']:
            return 'warn', f"{message}, {counts['images rejected']} rejected (last: {self.last_problem})", counts
        return 'ok', message, counts


def main(args=None):
    return run_node(CameraFeaturesNode, args)
