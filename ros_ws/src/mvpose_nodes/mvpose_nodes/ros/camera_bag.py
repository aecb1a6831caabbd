"""The multi-camera bag contract in code: topic names, frame stamps, and a writer that lays a bag
out the way every node and tool expects it (calibration latched before the first image).

Topics of camera K (i3DPost camera number 1..8):
  /cam<K>/image_raw/compressed               sensor_msgs/CompressedImage (jpeg or png)
  /cam<K>/camera_info, /cam<K>/camera_pose   sensor_msgs/CameraInfo, geometry_msgs/PoseStamped (latched)
  /cam<K>/ground_truth/labels/compressed     synthetic bags: PNG mono8 label mask (LABEL_* | SKIN_BIT)
  /cam<K>/ground_truth/markers               synthetic marker bags: mvpose_msgs/MarkerTracks, the 15 joint
                                             markers' true projections, FLAG_DETECTED where visible,
                                             FLAG_PREDICTED where hidden
and /mvpose/ground_truth (mvpose_msgs/Skeleton), once per frame in synthetic bags; marker bags also
have /mvpose/ground_truth/marker_centres (Skeleton: the 3D marker centres, on the body's surface).
Frame N of a sequence has the stamp FRAME_EPOCH_NS + N / FRAME_RATE.
"""
import re
from dataclasses import dataclass, field

from rclpy.serialization import serialize_message

from mvpose_nodes.studio.i3dpost import FRAME_RATE
from mvpose_nodes.io.bagfile import BagWriter
from mvpose_nodes.ros.conversions import calibration_messages, skeleton_message

FRAME_EPOCH_NS = 1_230_768_000_000_000_000  # stamp of frame 0 (2009-01-01, the year i3DPost was recorded)
GROUND_TRUTH_TOPIC = '/mvpose/ground_truth'
MARKER_CENTRES_TOPIC = '/mvpose/ground_truth/marker_centres'  # marker bags: 3D marker centres as a Skeleton
SKELETON_TOPIC = '/mvpose/skeleton'  # the fitted skeleton, in recorded output bags
LATCHED_QOS = {'history': 'keep_last', 'depth': 1, 'reliability': 'reliable', 'durability': 'transient_local'}
STREAM_QOS = {'history': 'keep_last', 'depth': 10, 'reliability': 'reliable', 'durability': 'volatile'}
CAMERA_TOPIC = re.compile(r'^/cam(?P<camera>\d+)/(?P<kind>camera_info|camera_pose|image_raw(/compressed)?'
                          r'|ground_truth/labels/compressed|ground_truth/markers)$')


def frame_stamp_ns(frame_number):
    return FRAME_EPOCH_NS + round(frame_number * 1e9 / FRAME_RATE)


def frame_number_of(stamp_ns):
    return round((stamp_ns - FRAME_EPOCH_NS) * FRAME_RATE / 1e9)


def camera_topics(number):
    """The bag contract's topics of camera `number`."""
    base = f'/cam{number}'
    return {'image': f'{base}/image_raw/compressed', 'info': f'{base}/camera_info', 'pose': f'{base}/camera_pose',
            'labels': f'{base}/ground_truth/labels/compressed', 'markers': f'{base}/ground_truth/markers'}


class CameraBagWriter:
    """A BagWriter for frames of `cameras` (the calibration the bag states) starting at `first_frame`;
    `markers` adds the ground-truth marker topics (with ground_truth)."""

    def __init__(self, path, cameras, first_frame, ground_truth=False, markers=False):
        self.bag = BagWriter(path)
        first_stamp = frame_stamp_ns(first_frame)
        for camera in cameras:
            topics = camera_topics(camera.number)
            self.bag.add_topic(topics['info'], 'sensor_msgs/msg/CameraInfo', [LATCHED_QOS])
            self.bag.add_topic(topics['pose'], 'geometry_msgs/msg/PoseStamped', [LATCHED_QOS])
            self.bag.add_topic(topics['image'], 'sensor_msgs/msg/CompressedImage', [STREAM_QOS])
            if ground_truth:
                self.bag.add_topic(topics['labels'], 'sensor_msgs/msg/CompressedImage', [STREAM_QOS])
            if ground_truth and markers:
                self.bag.add_topic(topics['markers'], 'mvpose_msgs/msg/MarkerTracks', [STREAM_QOS])
            info, pose = calibration_messages(camera, first_stamp)
            self.bag.write(topics['info'], serialize_message(info), first_stamp - 1_000_000)  # before any image
            self.bag.write(topics['pose'], serialize_message(pose), first_stamp - 1_000_000)
        if ground_truth:
            self.bag.add_topic(GROUND_TRUTH_TOPIC, 'mvpose_msgs/msg/Skeleton', [STREAM_QOS])
            if markers:
                self.bag.add_topic(MARKER_CENTRES_TOPIC, 'mvpose_msgs/msg/Skeleton', [STREAM_QOS])

    def write_image(self, camera_number, frame_number, cdr, kind='image'):
        """Store a serialised CompressedImage of camera `camera_number` ('image' or 'labels')."""
        self.bag.write(camera_topics(camera_number)[kind], cdr, frame_stamp_ns(frame_number))

    def write_ground_truth(self, frame_number, joints):
        stamp = frame_stamp_ns(frame_number)
        self.bag.write(GROUND_TRUTH_TOPIC, serialize_message(skeleton_message(joints, stamp)), stamp)

    def write_marker_centres(self, frame_number, centres):
        """The 3D marker centres (15, 3) [m] of a frame, as a Skeleton on MARKER_CENTRES_TOPIC."""
        stamp = frame_stamp_ns(frame_number)
        self.bag.write(MARKER_CENTRES_TOPIC, serialize_message(skeleton_message(centres, stamp)), stamp)

    def write_markers(self, camera_number, frame_number, cdr):
        """Store a serialised MarkerTracks (rosconv.marker_tracks) of camera `camera_number`."""
        self.bag.write(camera_topics(camera_number)['markers'], cdr, frame_stamp_ns(frame_number))

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.bag.close()


@dataclass
class FrameSet:
    """All cameras of one frame of a bag: RGB images, ground-truth label masks (synthetic bags),
    ground-truth markers (marker bags: camera -> (true projections (15, 2) [px], visible (15,) bool)),
    the cameras as the bag calibrates them, and the skeletons' joints (15, 3) [m] by topic
    (ground truth, marker centres in marker bags and, in recorded output, the fitted skeleton)."""
    frame: int
    stamp_ns: int
    images: dict = field(default_factory=dict)
    labels: dict = field(default_factory=dict)
    markers: dict = field(default_factory=dict)
    cameras: dict = field(default_factory=dict)
    skeletons: dict = field(default_factory=dict)

    @property
    def truth(self):
        return self.skeletons.get(GROUND_TRUTH_TOPIC)

    @property
    def marker_centres(self):
        """The markers' true 3D centres (15, 3) [m] (marker bags), or None."""
        return self.skeletons.get(MARKER_CENTRES_TOPIC)


def cameras_in(bag_path, wanted=None):
    """The numbers of the cameras whose images a bag holds (/cam<K>/image_raw or image_raw/compressed),
    sorted. BagError (one line) when it holds none, or when `wanted` (e.g. a command's --cameras) names one
    it lacks."""
    from mvpose_nodes.io.bagfile import BagError, BagReader
    present = sorted({int(m['camera']) for name in BagReader(bag_path).topics
                      if (m := CAMERA_TOPIC.match(name)) and m['kind'].startswith('image_raw')})
    if not present:
        raise BagError(f"bag '{bag_path}' has no camera images (no /cam<K>/image_raw or /cam<K>/image_raw/compressed)")
    missing = sorted(set(wanted or ()) - set(present))
    if missing:
        raise BagError(f"--cameras: bag '{bag_path}' has no images of camera {', '.join(map(str, missing))} "
                       f"(it has cameras {' '.join(map(str, present))})")
    return present


def frame_sets(bag_path, cameras=None):
    """Yield the FrameSets of a bag of this contract in stamp order (cameras: numbers to keep, None = all)."""
    from rclpy.serialization import deserialize_message
    from mvpose_nodes.io.bagfile import BagError, BagReader
    from mvpose_nodes.io.interfaces import message_class
    from mvpose_nodes.markers.detection import FLAG_DETECTED
    from mvpose_nodes.ros.conversions import (camera_from_messages, image_from_compressed, image_from_raw,
                                      joints_from_skeleton, stamp_ns, tracks_from_message)
    bag = BagReader(bag_path)
    calibration, pending = {}, {}
    wanted = None if cameras is None else {int(k) for k in cameras}
    for info, _, data in bag.messages():
        match = CAMERA_TOPIC.match(info.name)
        number = int(match['camera']) if match else None
        if number is not None and wanted is not None and number not in wanted:
            continue
        try:
            message = deserialize_message(data, message_class(info.type))
        except Exception as error:   # rclpy raises its RMWError: the bytes do not fit this build's type
            raise BagError(f"bag '{bag_path}': a {info.type} on {info.name} does not decode with this "
                            f"workspace's {info.type} (recorded with an older definition? make the bag again): "
                            f"{str(error).splitlines()[0]}") from None
        if match and match['kind'] in ('camera_info', 'camera_pose'):
            calibration.setdefault(number, {})[match['kind']] = message
            continue
        if not (match or info.name in (GROUND_TRUTH_TOPIC, SKELETON_TOPIC, MARKER_CENTRES_TOPIC)):
            continue
        stamp = stamp_ns(message.header)
        frame = pending.setdefault(stamp, FrameSet(frame_number_of(stamp), stamp))
        try:
            if not match:
                frame.skeletons[info.name] = joints_from_skeleton(message)
            elif match['kind'] == 'ground_truth/labels/compressed':
                frame.labels[number] = image_from_compressed(message)
            elif match['kind'] == 'ground_truth/markers':
                positions, flags = tracks_from_message(message)
                frame.markers[number] = positions, flags == FLAG_DETECTED   # visible
            elif match['kind'] in ('image_raw/compressed', 'image_raw'):
                frame.images[number] = image_from_compressed(message) if match['kind'].endswith('compressed') \
                    else image_from_raw(message)
                parts = calibration.get(number, {})
                if len(parts) < 2:
                    raise BagError(f"bag '{bag_path}': camera {number} has no camera_info/camera_pose before its images")
                frame.cameras[number] = camera_from_messages(number, parts['camera_info'], parts['camera_pose'])
        except BagError:
            raise
        except ValueError as error:
            raise BagError(f"bag '{bag_path}': {info.name}: {error}") from None
        for earlier in [s for s in pending if s < stamp]:  # a frame is complete once a later one starts
            yield pending.pop(earlier)
    for stamp in sorted(pending):
        yield pending.pop(stamp)
