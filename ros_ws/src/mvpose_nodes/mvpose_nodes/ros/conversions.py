"""Conversions between ROS messages and the plain data of the algorithm modules, in one place:
calibration (CameraInfo + PoseStamped <-> Camera), images (Image / CompressedImage <-> RGB
arrays), camera features (features.Features -> silhouette, SkinEllipseArray, LabelledContour),
skeletons (Skeleton <-> joint arrays), and stamps. Errors in incoming messages raise
ValueError with a one-line reason, for the caller to log with the topic's name.
"""
import cv2
import numpy as np
from geometry_msgs.msg import Pose, PoseStamped
from mvpose_msgs.msg import (FitStage, Keypoint2D, LabelledContour, MarkerTracks, Skeleton, SkinEllipse,
                             SkinEllipseArray)
from sensor_msgs.msg import CameraInfo, CompressedImage, Image
from std_msgs.msg import Header

from mvpose_nodes.body.model import JOINT_NAMES, joint_orientations
from mvpose_nodes.body.camera import Camera
from mvpose_nodes.vision.features import MAX_IMAGE_PIXELS, MIN_IMAGE_SIDE
from mvpose_nodes.vision.decoding import decode_image

WORLD_FRAME = 'world'


def stamp_ns(header):
    return header.stamp.sec * 10**9 + header.stamp.nanosec


def set_stamp(header, nanoseconds, frame_id):
    header.stamp.sec, header.stamp.nanosec = divmod(int(nanoseconds), 10**9)
    header.frame_id = frame_id
    return header


def optical_frame(camera_number):
    return f'cam{camera_number}_optical_frame'


def calibration_messages(camera, nanoseconds):
    """(CameraInfo, PoseStamped) of a Camera: intrinsics and plumb_bob distortion, and the optical
    frame's pose in `world`."""
    info = CameraInfo(width=camera.width, height=camera.height, distortion_model='plumb_bob')
    set_stamp(info.header, nanoseconds, optical_frame(camera.number))
    info.d = [float(v) for v in camera.D]
    info.k = camera.K.ravel().tolist()
    info.r = np.eye(3).ravel().tolist()
    info.p = np.column_stack([camera.K, np.zeros(3)]).ravel().tolist()
    pose = PoseStamped()
    set_stamp(pose.header, nanoseconds, WORLD_FRAME)
    position, orientation = camera.pose()
    pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = map(float, position)
    (pose.pose.orientation.x, pose.pose.orientation.y, pose.pose.orientation.z,
     pose.pose.orientation.w) = map(float, orientation)
    return info, pose


def camera_from_messages(camera_number, info, pose):
    """The Camera of a camera_info and camera_pose pair; ValueError when they are unusable."""
    K = np.array(info.k, dtype=float).reshape(3, 3)
    if info.width <= 0 or info.height <= 0:
        raise ValueError(f'camera_info has no image size ({info.width}×{info.height})')
    if not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise ValueError('camera_info K is not a valid intrinsic matrix')
    if info.distortion_model not in ('plumb_bob', '') and any(info.d):
        raise ValueError(f"distortion model '{info.distortion_model}' is not supported (plumb_bob only)")
    D = np.zeros(5)
    D[:min(5, len(info.d))] = list(info.d)[:5]
    if pose.header.frame_id != WORLD_FRAME:
        raise ValueError(f"camera_pose frame_id is '{pose.header.frame_id}', expected '{WORLD_FRAME}'")
    p, q = pose.pose.position, pose.pose.orientation
    position, orientation = np.array([p.x, p.y, p.z]), np.array([q.x, q.y, q.z, q.w])
    if not (np.all(np.isfinite(position)) and np.all(np.isfinite(orientation)) and np.linalg.norm(orientation) > 0.5):
        raise ValueError('camera_pose is not a finite pose with a unit quaternion')
    if not np.all(np.isfinite(D)):
        raise ValueError('camera_info D is not finite')
    return Camera.from_pose(camera_number, info.width, info.height, K, position, orientation / np.linalg.norm(orientation), D)


def compressed_image(rgb, camera_number, nanoseconds, image_format='jpeg', jpeg_quality=90):
    """CompressedImage of an RGB uint8 (H, W, 3) image, `format` as image_transport writes it."""
    extension, parameters = ('.jpg', [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality]) if image_format == 'jpeg' \
        else ('.png', [cv2.IMWRITE_PNG_COMPRESSION, 1])
    ok, data = cv2.imencode(extension, cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), parameters)
    message = CompressedImage(format=f'rgb8; {image_format} compressed bgr8', data=data.tobytes())
    set_stamp(message.header, nanoseconds, optical_frame(camera_number))
    return message


def compressed_labels(labels, camera_number, nanoseconds):
    """CompressedImage (lossless PNG, mono8) of a ground-truth label mask (H, W) uint8."""
    message = png_mono(labels, Header(), compression=3)
    set_stamp(message.header, nanoseconds, optical_frame(camera_number))
    return message


def png_mono(mask, header, compression=None):
    """CompressedImage, format 'mono8; png compressed mono8' (image_transport's), of a (H, W) uint8 array
    with `header`: lossless, and a 0/255 1080p silhouette is 5–10 kB instead of 2 MB (about 5 ms to encode
    at OpenCV's default compression)."""
    parameters = [] if compression is None else [cv2.IMWRITE_PNG_COMPRESSION, compression]
    ok, data = cv2.imencode('.png', np.ascontiguousarray(mask, np.uint8), parameters)
    return CompressedImage(header=header, format='mono8; png compressed mono8', data=data.tobytes())


def image_from_compressed(message):
    """RGB uint8 (H, W, 3), or mono8 (H, W) for a mono8 image, of a CompressedImage; ValueError if undecodable."""
    mono = message.format.startswith('mono8')
    if not len(message.data):
        raise ValueError(f"CompressedImage has no data (format '{message.format}')")
    decoded = decode_image(message.data, mono)
    if decoded is None:
        raise ValueError(f"CompressedImage data does not decode (format '{message.format}')")
    return decoded


def image_from_raw(message):
    """RGB uint8 (H, W, 3) of a sensor_msgs/Image in rgb8 or bgr8; ValueError otherwise."""
    if message.encoding not in ('rgb8', 'bgr8'):
        raise ValueError(f"image encoding '{message.encoding}' is not supported (rgb8 or bgr8)")
    if message.step < 3 * message.width or len(message.data) < message.step * message.height:
        raise ValueError(f'image data ({len(message.data)} bytes) is shorter than {message.height} rows '
                         f'of {message.step} bytes')
    rows = np.frombuffer(bytes(message.data), np.uint8)[:message.step * message.height].reshape(message.height, message.step)
    image = rows[:, :3 * message.width].reshape(message.height, message.width, 3)
    return image[..., ::-1].copy() if message.encoding == 'bgr8' else image.copy()


class ImageError(ValueError):
    """An image message that gives no colour image: `kind` ('undecodable', 'mono', 'encoding' or 'size') and
    `size` (width, height) [px] as far as known ((0, 0) when nothing decoded)."""

    def __init__(self, text, kind, size=(0, 0)):
        super().__init__(text)
        self.kind, self.size = kind, tuple(size)


def encoded_size(data):
    """(width, height) [px] read from the header of PNG or JPEG bytes (PNG's IHDR; JPEG's start-of-frame
    segment, ITU-T T.81 B.2.2), or None when the header does not say: lets an image too large to take be
    refused before decoding it (an 8000×8000 JPEG of 1 MB decodes to 192 MB in about half a second)."""
    if data[:8] == b'\x89PNG\r\n\x1a\n' and len(data) >= 24:
        return int.from_bytes(data[16:20], 'big'), int.from_bytes(data[20:24], 'big')
    if data[:2] != b'\xff\xd8':
        return None
    at = 2
    while at + 9 <= len(data) and data[at] == 0xFF:
        marker = data[at + 1]
        if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):   # SOFn, not DHT, JPG, DAC
            return int.from_bytes(data[at + 7:at + 9], 'big'), int.from_bytes(data[at + 5:at + 7], 'big')
        at += 2 if marker == 0xFF or 0xD0 <= marker <= 0xD7 else 2 + int.from_bytes(data[at + 2:at + 4], 'big')
    return None


def check_image_size(width, height):
    """ImageError unless a (width, height) [px] image is one the features take (vision.features:
    MIN_IMAGE_SIDE, MAX_IMAGE_PIXELS)."""
    if min(width, height) < MIN_IMAGE_SIDE or width * height > MAX_IMAGE_PIXELS:
        raise ImageError(f'image is {width}×{height}: the features take {MIN_IMAGE_SIDE} px a side or more and '
                         f'{MAX_IMAGE_PIXELS / 1e6:g} Mpx at most', 'size', (width, height))


def colour_image(message):
    """RGB uint8 (H, W, 3) of a CompressedImage or an rgb8/bgr8 Image of a size the features take
    (check_image_size; a compressed image's size is checked from its header before decoding);
    ImageError otherwise."""
    if isinstance(message, CompressedImage):
        size = encoded_size(bytes(message.data[:65536]))
        if size is not None:
            check_image_size(*size)
        try:
            rgb = image_from_compressed(message)
        except ValueError as error:
            raise ImageError(str(error), 'undecodable') from None
        if rgb.ndim != 3:
            raise ImageError(f'format {message.format!r} is not a colour image', 'mono', rgb.shape[::-1])
    else:
        try:
            rgb = image_from_raw(message)
        except ValueError as error:
            raise ImageError(str(error), 'encoding', (message.width, message.height)) from None
    check_image_size(rgb.shape[1], rgb.shape[0])
    return rgb


def mono_image(mask, header):
    """sensor_msgs/Image mono8 of a (H, W) uint8 array with the given header."""
    return Image(header=header, height=mask.shape[0], width=mask.shape[1], encoding='mono8', is_bigendian=0,
                 step=mask.shape[1], data=np.ascontiguousarray(mask, np.uint8).tobytes())


def skeleton_message(joints, nanoseconds, **fields):
    """Skeleton with the 15 joints (15, 3) [m] and their frames (body_model.joint_orientations)."""
    message = Skeleton(joint_names=list(JOINT_NAMES), **fields)
    set_stamp(message.header, nanoseconds, WORLD_FRAME)
    for position, orientation in zip(joints, joint_orientations(joints)):
        pose = Pose()
        pose.position.x, pose.position.y, pose.position.z = map(float, position)
        pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = map(float, orientation)
        message.joints.append(pose)
    return message


def joints_from_skeleton(message):
    """Joint positions (15, 3) [m] of a Skeleton, in JOINT_NAMES order whatever order it uses."""
    index = {name: i for i, name in enumerate(message.joint_names)}
    missing = [name for name in JOINT_NAMES if name not in index]
    if missing or len(message.joints) != len(message.joint_names):
        raise ValueError(f"Skeleton lacks joints {missing}" if missing else 'Skeleton joints and names differ in length')
    return np.array([[message.joints[index[n]].position.x, message.joints[index[n]].position.y,
                      message.joints[index[n]].position.z] for n in JOINT_NAMES])


def keypoint_message(name, keypoint):
    return Keypoint2D(name=name, x=float(keypoint.x), y=float(keypoint.y), confidence=float(keypoint.confidence),
                      visible=bool(keypoint.visible))


def feature_messages(features, header, status_message=''):
    """(SkinEllipseArray, LabelledContour) of features.Features, with `header` (the silhouette: png_mono
    and mono_image of features.silhouette as 0/255)."""
    status = SkinEllipseArray.STATUS_OK if features.person else SkinEllipseArray.STATUS_NO_PERSON
    message = status_message
    if not message and not features.person:
        message = 'no person in the image'
    elif not message and features.other_people:
        message = f'{features.other_people} more person-sized region(s) in view: the largest is taken for the person'
    ellipses = SkinEllipseArray(header=header, status=status, status_message=message,
                                face_visibility=float(features.frontness))
    for e in features.ellipses:
        ellipses.ellipses.append(SkinEllipse(
            center_x=float(e.center[0]), center_y=float(e.center[1]), semi_major=float(e.semi_major),
            semi_minor=float(e.semi_minor), angle=float(e.angle), major_end_a=keypoint_message('end_a', e.end_a),
            major_end_b=keypoint_message('end_b', e.end_b), area=int(e.area), role=int(e.role), side=int(e.side),
            confidence=float(e.confidence)))
    skin_names = ('head', 'neck', 'left_wrist', 'right_wrist', 'left_elbow', 'right_elbow')
    silhouette_names = ('root', 'left_ankle', 'right_ankle', 'left_knee', 'right_knee')
    ellipses.keypoints = [keypoint_message(n, features.keypoints[n]) for n in skin_names if n in features.keypoints]
    contour = LabelledContour(header=header, status=status, status_message=message)
    contour.keypoints = [keypoint_message(n, features.keypoints[n]) for n in silhouette_names
                         if n in features.keypoints]
    if features.contour is not None and len(features.contour.points):
        contour.x = features.contour.points[:, 0].astype(np.uint16).tolist()
        contour.y = features.contour.points[:, 1].astype(np.uint16).tolist()
        contour.labels = features.contour.labels.tobytes()
        contour.sides = features.contour.sides.tobytes()
    return ellipses, contour


def empty_feature_messages(header, status, reason):
    """(SkinEllipseArray, LabelledContour) that say why there are no features (status STATUS_NO_PERSON or
    STATUS_BAD_INPUT)."""
    return (SkinEllipseArray(header=header, status=status, status_message=reason),
            LabelledContour(header=header, status=status, status_message=reason))


def rgb_image(rgb, header):
    """sensor_msgs/Image rgb8 of an RGB uint8 (H, W, 3) array."""
    return Image(header=header, height=rgb.shape[0], width=rgb.shape[1], encoding='rgb8', is_bigendian=0,
                 step=3 * rgb.shape[1], data=np.ascontiguousarray(rgb).tobytes())


def stage_messages(stages):
    """FitStage messages of fitter.StageResult objects."""
    return [FitStage(name=s.name, cost=float(s.cost), evaluations=int(s.evaluations), cameras=list(s.cameras),
                     fitted=bool(s.fitted)) for s in stages]


def contour_from_message(message):
    """contour.ContourLabels of a LabelledContour message (no landmarks)."""
    from mvpose_nodes.vision.contour import ContourLabels
    if not (len(message.x) == len(message.y) == len(message.labels) == len(message.sides)):
        raise ValueError('LabelledContour x, y, labels and sides differ in length')
    points = np.column_stack([np.asarray(message.x, np.int32), np.asarray(message.y, np.int32)]).reshape(-1, 2)
    return ContourLabels(points, np.frombuffer(bytes(message.labels), np.uint8),
                         np.frombuffer(bytes(message.sides), np.uint8), {})


def keypoints_from_messages(*messages):
    """{name: (x, y, confidence)} of the visible keypoints of SkinEllipseArray / LabelledContour messages."""
    return {k.name: (k.x, k.y, k.confidence) for m in messages for k in m.keypoints if k.visible}


def joint_state(parameters, header):
    from sensor_msgs.msg import JointState
    from mvpose_nodes.body.model import PARAMETER_NAMES
    return JointState(header=header, name=list(PARAMETER_NAMES), position=[float(v) for v in parameters])


def skeleton_markers(joints, header, status):
    """visualization_msgs/MarkerArray of a skeleton: a sphere per joint and a line per bone, in `world`."""
    from geometry_msgs.msg import Point
    from visualization_msgs.msg import Marker, MarkerArray
    from mvpose_nodes.body.model import BONES
    colour = {Skeleton.STATUS_OK: (0.2, 0.9, 0.2), Skeleton.STATUS_INITIALISING: (0.2, 0.6, 1.0),
              Skeleton.STATUS_DEGRADED: (1.0, 0.7, 0.1)}.get(status, (1.0, 0.2, 0.2))
    spheres = Marker(header=header, ns='mvpose_joints', id=0, type=Marker.SPHERE_LIST, action=Marker.ADD)
    lines = Marker(header=header, ns='mvpose_bones', id=1, type=Marker.LINE_LIST, action=Marker.ADD)
    spheres.scale.x = spheres.scale.y = spheres.scale.z = 0.06
    lines.scale.x = 0.02
    for marker in (spheres, lines):
        marker.pose.orientation.w = 1.0
        marker.color.r, marker.color.g, marker.color.b = colour
        marker.color.a = 1.0
    spheres.points = [Point(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in joints]
    index = {name: i for i, name in enumerate(JOINT_NAMES)}
    lines.points = [spheres.points[index[name]] for bone in BONES for name in bone]
    return MarkerArray(markers=[spheres, lines])


def marker_tracks(header, positions, flags, status=MarkerTracks.STATUS_OK, status_message='', blobs=()):
    """MarkerTracks of the 15 markers: positions (15, 2) [px] (x, y), flags (15,) FLAG_*, and the image's red
    blobs (N, 2) [px]; `header` kept."""
    positions = np.asarray(positions, dtype=float).reshape(len(JOINT_NAMES), 2)
    blobs = np.asarray(blobs, dtype=float).reshape(-1, 2)
    return MarkerTracks(header=header, status=status, status_message=status_message, names=list(JOINT_NAMES),
                        x=positions[:, 0].tolist(), y=positions[:, 1].tolist(),
                        flags=[int(flag) for flag in np.asarray(flags).reshape(len(JOINT_NAMES))],
                        blob_x=blobs[:, 0].tolist(), blob_y=blobs[:, 1].tolist())


def tracks_from_message(message):
    """(positions (15, 2) float64 [px], flags (15,) uint8) of a MarkerTracks in JOINT_NAMES order;
    ValueError when it lacks markers or its arrays disagree."""
    count = len(message.names)
    if not (len(message.x) == len(message.y) == len(message.flags) == count):
        raise ValueError('MarkerTracks names, x, y and flags differ in length')
    index = {name: i for i, name in enumerate(message.names)}
    missing = [name for name in JOINT_NAMES if name not in index]
    if missing:
        raise ValueError(f'MarkerTracks lacks markers {missing}')
    order = [index[name] for name in JOINT_NAMES]
    positions = np.column_stack([np.asarray(message.x, float)[order], np.asarray(message.y, float)[order]])
    flags = np.asarray(message.flags, np.uint8)[order]
    if not np.all(np.isfinite(positions[flags != MarkerTracks.FLAG_LOST])):
        raise ValueError('MarkerTracks has a marker that is not lost but not finite')
    return positions, flags


def blobs_from_message(message):
    """(N, 2) float64 [px]: a MarkerTracks' red blobs; ValueError when blob_x and blob_y disagree or are not finite."""
    if len(message.blob_x) != len(message.blob_y):
        raise ValueError('MarkerTracks blob_x and blob_y differ in length')
    blobs = np.column_stack([np.asarray(message.blob_x, float), np.asarray(message.blob_y, float)])
    if not np.all(np.isfinite(blobs)):
        raise ValueError('MarkerTracks has a blob that is not finite')
    return blobs
