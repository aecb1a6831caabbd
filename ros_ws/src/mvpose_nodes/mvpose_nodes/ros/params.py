"""The camera_features parameters in one place: name, default, range and description, shared by the
node (which declares them) and the offline tools (which read the same params YAML)."""
from dataclasses import dataclass, fields
from pathlib import Path

import yaml

from mvpose_nodes.tools.cli import UserError
from mvpose_nodes.vision.features import FeatureSettings


@dataclass(frozen=True)
class Parameter:
    name: str
    default: object
    description: str
    choices: tuple = ()
    range: tuple = ()     # (low, high) for numbers


PARAMETERS = (
    Parameter('silhouette_method', 'chroma', "background subtraction: 'chroma' (blue screen, as i3DPost) or "
              "'background' (per-pixel model learned from the first background_frames frames, then kept up to date)",
              choices=('chroma', 'background')),
    Parameter('blueness_threshold', 25, 'chroma key: a pixel is blue screen when b - max(r, g) exceeds this [DN]',
              range=(0, 255)),
    Parameter('background_frames', 25, "'background' method: person-free frames that build the model first",
              range=(1, 10000)),
    Parameter('min_person_fraction', 0.001, 'smallest blob taken for a person, as a share of the image area',
              range=(0.0, 0.5)),
    Parameter('skin_model', '', "skin colour model (.npz from `./mvpose skin train`); '' = the package's",),
    Parameter('skin_threshold', 1.0, 'log-likelihood ratio L = log(H/h) above which a pixel is skin (paper 000 '
              'Eq. 1)', range=(-20.0, 20.0)),
    Parameter('skin_min_area_fraction', 0.00003, 'smallest skin region, as a share of the image area',
              range=(0.0, 0.1)),
    Parameter('sleeves', 'auto', "clothing assumption for the arms' skin: 'short' (forearm ellipses give elbow and "
              "hand), 'long' (hand only) or 'auto' (decided per region from its elongation)",
              choices=('auto', 'short', 'long')),
    Parameter('publish_overlay', False, 'also publish features_overlay: the image with every feature drawn on'),
)
SETTINGS_FIELDS = {f.name for f in fields(FeatureSettings)}


def default_params_path():
    from ament_index_python.packages import get_package_share_directory
    return Path(get_package_share_directory('mvpose_nodes')) / 'config' / 'camera_features.yaml'


def load_parameters(path=None):
    """{name: value} of a ROS params YAML for camera_features (None: the package's defaults), checked."""
    path = Path(path) if path else default_params_path()
    try:
        document = yaml.safe_load(path.read_text())
        values = next(iter(document.values()))['ros__parameters']
    except FileNotFoundError:
        raise UserError(f'{path}: no such parameters file') from None
    except (yaml.YAMLError, AttributeError, KeyError, TypeError, StopIteration):
        raise UserError(f'{path}: not a ROS params file (NODE: ros__parameters: {{...}})') from None
    known = {p.name: p for p in PARAMETERS}
    for name, value in values.items():
        if name not in known:
            raise UserError(f"{path}: unknown parameter '{name}' (known: {', '.join(known)})")
        problem = check(known[name], value)
        if problem:
            raise UserError(f'{path}: {problem}')
    return {**{p.name: p.default for p in PARAMETERS}, **values}


def check(parameter, value):
    """Why `value` is not acceptable for `parameter`, or None."""
    if type(value) is not type(parameter.default) and not (isinstance(parameter.default, float)
                                                           and isinstance(value, int)):
        return f"parameter '{parameter.name}' must be a {type(parameter.default).__name__}, got {value!r}"
    if parameter.choices and value not in parameter.choices:
        return f"parameter '{parameter.name}' must be one of {', '.join(parameter.choices)}, got {value!r}"
    if parameter.range and not parameter.range[0] <= value <= parameter.range[1]:
        return f"parameter '{parameter.name}' must be in [{parameter.range[0]}, {parameter.range[1]}], got {value!r}"
    return None


def settings_from(values):
    return FeatureSettings(**{name: value for name, value in values.items() if name in SETTINGS_FIELDS})


def load_settings(path=None):
    return settings_from(load_parameters(path))
