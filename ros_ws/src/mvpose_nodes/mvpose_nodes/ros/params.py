"""Every node's parameters in one place, and the one mechanism that declares and checks them.

A node's parameters are a table of `Parameter`s (name, default, description, range or choices).
`declare_parameters(node, table)` declares each with a ParameterDescriptor (so `ros2 param describe`
shows the description and range) and checks the values it got; `load_parameters(path, table)` reads
and checks the same names from a ROS params YAML for the offline tools. The defaults here are the
ones in config/<executable>.yaml (a test keeps them equal). The skeleton fitter's tuning constants
come from fitting.settings.FitterSettings, whose fields carry their own description and range.
"""
from dataclasses import dataclass, fields
from pathlib import Path

import yaml
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

from mvpose_nodes.fitting.settings import SETTING_FIELDS, FitterSettings
from mvpose_nodes.vision.features import FeatureSettings

PACKAGE = 'mvpose_nodes'
SKIN_MODEL_FILE = 'skin_model.npz'   # the package's skin model, in share/mvpose_nodes/data


class ParameterError(ValueError):
    """A parameter value, params file or node namespace that the node cannot run with; one line."""


@dataclass(frozen=True)
class Parameter:
    name: str
    default: object         # its type is the parameter's type; a list means an integer array
    description: str
    choices: tuple = ()
    range: tuple = ()       # (low, high) for numbers, for each element of an array
    distinct: bool = False  # an array whose elements must differ
    read_only: bool = False  # read when the node starts; `ros2 param set` cannot change it


def descriptor(parameter):
    """The ParameterDescriptor of a Parameter: description, range, choices, read-only."""
    result = ParameterDescriptor(description=parameter.description, read_only=parameter.read_only)
    if parameter.choices:
        result.additional_constraints = f"one of: {', '.join(parameter.choices)}"
    if parameter.range and isinstance(parameter.default, int) and not isinstance(parameter.default, bool):
        result.integer_range = [IntegerRange(from_value=parameter.range[0], to_value=parameter.range[1], step=1)]
    elif parameter.range and isinstance(parameter.default, float):
        result.floating_point_range = [FloatingPointRange(from_value=float(parameter.range[0]),
                                                          to_value=float(parameter.range[1]), step=0.0)]
    elif parameter.range:
        result.additional_constraints = f'each in [{parameter.range[0]}, {parameter.range[1]}]' + (
            ', all different' if parameter.distinct else '')
    return result


def check(parameter, value):
    """Why `value` is not acceptable for `parameter`, or None."""
    default = parameter.default
    if isinstance(default, list):
        if not isinstance(value, (list, tuple)) or not value or any(type(v) is not int for v in value):
            return f"parameter '{parameter.name}' must be a non-empty list of integers, got {value!r}"
        if parameter.distinct and len(set(value)) != len(value):
            return f"parameter '{parameter.name}' must list distinct values, got {list(value)}"
        low, high = parameter.range or (min(value), max(value))
        if not all(low <= v <= high for v in value):
            return f"parameter '{parameter.name}' must have every value in [{low}, {high}], got {list(value)}"
        return None
    if type(value) is not type(default) and not (isinstance(default, float) and type(value) is int):
        return f"parameter '{parameter.name}' must be a {type(default).__name__}, got {value!r}"
    if parameter.choices and value not in parameter.choices:
        return f"parameter '{parameter.name}' must be one of {', '.join(parameter.choices)}, got {value!r}"
    if parameter.range and not parameter.range[0] <= value <= parameter.range[1]:
        return f"parameter '{parameter.name}' must be in [{parameter.range[0]}, {parameter.range[1]}], got {value!r}"
    return None


def declare_parameters(node, table):
    """Declare every Parameter of `table` on the rclpy `node`; {name: value} as given (lists for arrays).
    ParameterError naming every unacceptable value."""
    for parameter in table:
        node.declare_parameter(parameter.name, parameter.default, descriptor(parameter))
    values = {}
    for parameter in table:
        value = node.get_parameter(parameter.name).value
        values[parameter.name] = list(value) if isinstance(parameter.default, list) else value
    problems = [problem for p in table if (problem := check(p, values[p.name]))]
    if problems:
        raise ParameterError('; '.join(problems))
    return values


def changed_values(table, values, changes):
    """{name: value} after `ros2 param set` changes (rclpy Parameters) to the names of `table`, or a
    ParameterError saying why one is refused."""
    known = {p.name: p for p in table}
    updated = dict(values)
    for change in changes:
        if change.name not in known:
            continue
        problem = check(known[change.name], change.value)
        if problem:
            raise ParameterError(problem)
        updated[change.name] = change.value
    return updated


def package_share():
    """share/mvpose_nodes of the installed package."""
    from ament_index_python.packages import get_package_share_directory
    return Path(get_package_share_directory(PACKAGE))


def default_skin_model_path():
    """The skin model shipped with the package (share/mvpose_nodes/data/skin_model.npz)."""
    return package_share() / 'data' / SKIN_MODEL_FILE


def load_parameters(path, table, executable):
    """{name: value} of a ROS params YAML for `executable`'s `table` (path None: the package's
    config/<executable>.yaml), checked; the table's defaults for the names it does not set."""
    path = Path(path) if path else package_share() / 'config' / f'{executable}.yaml'
    try:
        document = yaml.safe_load(path.read_text())
        values = next(iter(document.values()))['ros__parameters']
    except FileNotFoundError:
        raise ParameterError(f'{path}: no such parameters file') from None
    except (yaml.YAMLError, AttributeError, KeyError, TypeError, StopIteration):
        raise ParameterError(f'{path}: not a ROS params file (NODE: ros__parameters: {{...}})') from None
    known = {p.name: p for p in table}
    for name, value in values.items():
        if name not in known:
            raise ParameterError(f"{path}: unknown parameter '{name}' (known: {', '.join(known)})")
        problem = check(known[name], value)
        if problem:
            raise ParameterError(f'{path}: {problem}')
    return {**{p.name: p.default for p in table}, **values}


# ---------------------------------------------------------------- camera_features (paper 000 Sec. 3)

CAMERA_FEATURES = (
    Parameter('silhouette_method', 'chroma', "background subtraction: 'chroma' (blue screen, as i3DPost) or "
              "'background' (per-pixel model learned from the first background_frames frames, then kept up to date)",
              choices=('chroma', 'background')),
    Parameter('blueness_threshold', FeatureSettings.blueness_threshold,
              'chroma key: a pixel is blue screen when b - max(r, g) exceeds this [DN]', range=(0, 255)),
    Parameter('background_frames', 25, "'background' method: person-free frames that build the model first",
              range=(1, 10000)),
    Parameter('min_person_fraction', FeatureSettings.min_person_fraction,
              'smallest blob taken for a person, as a share of the image area', range=(0.0, 0.5)),
    Parameter('skin_model', '', "skin colour model (.npz from `./mvpose skin train`); '' = the package's",),
    Parameter('skin_threshold', FeatureSettings.skin_threshold,
              'log-likelihood ratio L = log(H/h) above which a pixel is skin (paper 000 Eq. 1)', range=(-20.0, 20.0)),
    Parameter('skin_min_area_fraction', FeatureSettings.skin_min_area_fraction,
              'smallest skin region, as a share of the image area', range=(0.0, 0.1)),
    Parameter('sleeves', FeatureSettings.sleeves, "clothing assumption for the arms' skin: 'short' (forearm ellipses "
              "give elbow and hand), 'long' (hand only) or 'auto' (decided per region from its elongation)",
              choices=('auto', 'short', 'long')),
    Parameter('person_rows', FeatureSettings.person_rows,
              "[px] a person's box at least twice this many rows high is keyed at full resolution, then its "
              "features are computed at half resolution (each pixel the mean of 2 × 2) and given in the full "
              "image's pixels: at 1080p 250 halves the features' CPU, but on the suite it swapped left and right "
              "more often (docs/method.md); 0 (the default): always at full resolution", range=(0, 10000)),
    Parameter('publish_overlay', False, 'also publish features_overlay: the image with every feature drawn on'),
    Parameter('follow_requests', True, 'while a skeleton_fitter asks for frames on frame_request, announce each '
              "image's stamp on frame_available and compute features only for the images it asks for, as every "
              'camera does: a graph slower than the cameras then skips whole frame sets before any features are '
              'computed; false: features of every image'),
    Parameter('opencv_threads', 1, "OpenCV's worker threads in this node: 1, as the graph runs a process per camera "
              "beside the fitter and OpenCV's own threads only add switching (`./mvpose bench` on 2 cores: 11.4-12.3 "
              '-> 12.5-12.8 frame sets/s); 0: OpenCV\'s default, one per core (a camera with a host to itself)',
              range=(0, 256), read_only=True),
)
FEATURE_SETTING_NAMES = {f.name for f in fields(FeatureSettings)}


def feature_settings_from(values):
    """The vision.features.FeatureSettings of camera_features parameter values {name: value}."""
    return FeatureSettings(**{name: value for name, value in values.items() if name in FEATURE_SETTING_NAMES})


def load_feature_settings(path=None):
    """FeatureSettings of a camera_features params YAML (None: the package's defaults)."""
    return feature_settings_from(load_parameters(path, CAMERA_FEATURES, 'camera_features'))


# ---------------------------------------------------------------- marker_tracker (paper 001)

MARKER_TRACKER = (
    Parameter('method', 'regions', "'regions': paper 001's region-constrained tracking; 'nearest': nearest "
              "neighbour with constant-velocity prediction (the baseline)", choices=('regions', 'nearest'),
              read_only=True),
    Parameter('fused_wait', 1.0, '[s] longest wait of an image for the fused tracks of the previous one on '
              'marker_tracks_fused (only while marker_skeleton publishes them); 0: never wait', range=(0.0, 60.0)),
)


# ---------------------------------------------------------------- nodes that combine cameras

def multi_camera_parameters(what):
    """The parameters of a node that synchronises several cameras' `what` (ros/multi_camera.py)."""
    return (
        Parameter('cameras', [3, 5, 7], f'i3DPost camera numbers whose {what} are combined', range=(1, 99),
                  distinct=True, read_only=True),
        Parameter('queue_size', 10, 'messages kept per input topic while frame sets are matched',
                  range=(1, 1000), read_only=True),
        Parameter('max_interval', 0.02, '[s] largest stamp spread within one frame set', range=(0.0, 10.0),
                  read_only=True),
        Parameter('camera_timeout', 1.0, '[s] of input time after which a silent camera is left out '
                  '(status DEGRADED); after this much wall time without input the last frame sets are '
                  'flushed (a bag\'s end)', range=(0.01, 60.0), read_only=True),
        Parameter('calibration_wait', 2.0, '[s] longest a frame set waits for a camera\'s camera_info and '
                  'camera_pose that have not come yet (then it goes on without that camera)', range=(0.0, 60.0),
                  read_only=True),
    )


SKELETON_FITTER = multi_camera_parameters(
    'features are fitted (each needs a camera_features in /cam<K>)') + (
    Parameter('pending_frame_sets', 1, 'frame sets that may wait while the fitter is busy, before each of its two '
              'stages (distance maps, fit); when one more comes, the oldest waiting is skipped, so the fit keeps to the newest (real time). 0: none is skipped, '
              'every frame set is fitted in order (offline replays; the wait can grow)', range=(0, 1000),
              read_only=True),
    Parameter('request_frames', True, "ask the cameras for each frame set it will fit (/cam<K>/frame_request, the "
              "newest set announced on /cam<K>/frame_available once nothing waits before its stages), so that the "
              "cameras skip the frames it would skip (their follow_requests); a request unanswered for "
              "camera_timeout wall seconds is given up", read_only=True),
    Parameter('request_overlap', 1, "with request_frames: how many of the fitter's two stages (distance maps, "
              "fit), counted from the last, may still be busy with earlier sets when it asks for the next (none "
              "while a start is fitted, which takes several fits' time): 2 asks as soon as a set is taken (the "
              "most sets fitted), 0 only once both are idle (the lowest latency "
              "when the cameras and the fitter share few cores), 1 while the last set is fitted "
              "(`./mvpose bench --rate 1.0` on 2 cores: 52 %, 42 % and 46-50 % of the sets fitted, 95th "
              "percentile latency 310, 155 and 200 ms)", range=(0, 2), read_only=True),
    Parameter('fit_threads', 2, "threads that fit the body's labellings side by side while they are compared (a "
              "start's eight, a probe's two), and otherwise a stage's searches from its several starts (the same "
              "results as one): on 2 cores the default bag's fits offline 2150 -> 1800 ms, a start's first fit "
              '370 -> 290 ms (docs/method.md); 1: one after the other', range=(1, 64), read_only=True),) + tuple(
    Parameter(f.name, f.default, f.metadata['description'], range=f.metadata['range'], read_only=True)
    for f in SETTING_FIELDS)
MARKER_SKELETON = multi_camera_parameters('marker tracks are fused in 3D (each needs a marker_tracker in /cam<K>)')


def fitter_settings_from(values):
    """The fitting.settings.FitterSettings of skeleton_fitter parameter values {name: value}."""
    return FitterSettings(**{f.name: type(f.default)(values[f.name]) for f in SETTING_FIELDS})
