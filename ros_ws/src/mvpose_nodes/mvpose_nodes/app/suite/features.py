"""What the suite's cases look like to the fitter: each case's motion placed in the studio, every camera's
image rendered at its jittered instant and put through JPEG, the camera_features pipeline and its
messages, serialised and read back as they cross DDS (`eval suite`, app/suite/__init__.py), and the folder cache
of those messages (--features-cache). Apart from the suite's tables so that the cache's key, the code
that makes the features (FEATURE_SOURCES), does not change with them.
"""
import hashlib
import math
import pickle
import sys
from pathlib import Path

import numpy as np

# What makes a case's feature messages, beside the case itself: the package's folders and modules (relative
# to it) whose change invalidates --features-cache.
FEATURE_SOURCES = ('studio', 'vision', 'body', 'ros/conversions.py', 'app/suite/features.py')


def case_motion(case):
    """The case's BodyMotion window (frames, at 25 fps) placed at its centre and heading."""
    from mvpose_nodes.studio.catalogue import load_motion
    return placed_window(load_motion(case.motion, height=case.height), case, case.frames)


def placed_window(motion, case, frames):
    """`frames` frames of the BodyMotion `motion` from the case's start, placed at its centre and heading."""
    window = motion.select(motion.first_frame + case.start, motion.first_frame + case.start + frames - 1)
    return window.placed(center=case.centre, heading=case.heading)


def pose_at(motion, position):
    """scene.BodyPose at a fractional frame index `position` (linear between frames, clamped)."""
    from mvpose_nodes.studio import scene
    position = float(np.clip(position, 0, len(motion.joints) - 1))
    low = int(math.floor(position))
    high, weight = min(low + 1, len(motion.joints) - 1), position - low

    def at(values):
        return (1 - weight) * values[low] + weight * values[high]
    forward = at(motion.head_forward)
    return scene.BodyPose(at(motion.joints), at(motion.toes), at(motion.hand_tips), forward / np.linalg.norm(forward))


def render_camera(case, view, motion, index):
    """One camera's image of frame `index`, at its jittered instant: RGB (H, W, 3) uint8 through JPEG, and its
    ground-truth labels (H, W) uint8 (scene.Rendering.labels: body part, SKIN_BIT on skin)."""
    import cv2
    from mvpose_nodes.studio import scene
    from mvpose_nodes.studio.i3dpost import FRAME_RATE
    from mvpose_nodes.vision.decoding import decode_image
    number = view.camera.number
    pose = pose_at(motion, index + case.jitter[case.cameras.index(number)] * FRAME_RATE)
    shadow, centre = scene.floor_shadow(pose, case.appearance) if case.shadows else (None, None)
    rendering = scene.render(view, pose, case.appearance, shadow, centre)
    rgb, _ = case.realism.finish(rendering, view, number, case.seed, index)
    ok, data = cv2.imencode('.jpg', cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, case.jpeg_quality])
    return decode_image(data), rendering.labels


def case_features(case, motion, cache=None):
    """Per frame set of the case: (stamp [ns], {camera: (SkinEllipseArray, LabelledContour)}), each image
    rendered and put through the camera_features pipeline and its messages, serialised and read back as the
    skeleton_fitter receives them over DDS (the float32 fields rounded); read from the folder `cache` if it
    has them for this case and code (cache_key), else computed and, with a cache, written there."""
    from rclpy.serialization import deserialize_message, serialize_message
    from std_msgs.msg import Header
    from mvpose_msgs.msg import LabelledContour, SkinEllipseArray
    from mvpose_nodes.ros.camera_bag import frame_stamp_ns
    from mvpose_nodes.ros.conversions import feature_messages, optical_frame, set_stamp
    from mvpose_nodes.ros.params import default_skin_model_path
    from mvpose_nodes.studio import scene
    from mvpose_nodes.vision.features import FeatureExtractor, FeatureSettings
    from mvpose_nodes.vision.skin import SkinModel

    path = None if cache is None else Path(cache) / f'{cache_key(case, default_skin_model_path())}.pkl'
    serialised = None   # per frame set: (stamp, {camera: (ellipses, contour) serialised})
    if path is not None and path.is_file():
        try:
            serialised = pickle.loads(path.read_bytes())
        except (pickle.UnpicklingError, EOFError, ValueError) as error:   # computed again and written anew
            print(f'[suite] {path}: unreadable ({error}); computing the features again', file=sys.stderr)
    if serialised is None:
        cameras = {c.number: c for c in case.rig if c.number in case.cameras}
        views = [scene.prepare_camera(cameras[k], texture_seed=k) for k in case.cameras]
        skin = SkinModel.load(default_skin_model_path())
        extractors = {k: FeatureExtractor(FeatureSettings(), skin) for k in case.cameras}
        serialised = []
        for index in range(len(motion.joints)):
            stamp, messages = frame_stamp_ns(index), {}
            for view in views:
                number = view.camera.number
                header = set_stamp(Header(), stamp, optical_frame(number))
                features = extractors[number](render_camera(case, view, motion, index)[0])
                messages[number] = tuple(map(serialize_message, feature_messages(features, header)))
            serialised.append((stamp, messages))
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            partial = path.with_suffix('.partial')
            partial.write_bytes(pickle.dumps(serialised))
            partial.replace(path)   # a run stopped while writing leaves no half file under the key
    return [(stamp, {number: (deserialize_message(ellipses, SkinEllipseArray),
                              deserialize_message(contour, LabelledContour))
                     for number, (ellipses, contour) in messages.items()}) for stamp, messages in serialised]


def cache_key(case, skin_model_path):
    """SHA-256 (hex) of the case, the skin model and the FEATURE_SOURCES of this package."""
    package = Path(__file__).resolve().parents[2]   # mvpose_nodes/, which FEATURE_SOURCES are relative to
    digest = hashlib.sha256(pickle.dumps(case, protocol=4))
    digest.update(Path(skin_model_path).read_bytes())
    for source in FEATURE_SOURCES:
        for file in sorted((package / source).rglob('*.py')) if (package / source).is_dir() else [package / source]:
            digest.update(file.relative_to(package).as_posix().encode() + file.read_bytes())
    return digest.hexdigest()
