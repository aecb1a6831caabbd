"""The package's layers, enforced: an AST walk over every module of mvpose_nodes finds each import
(module level and inside functions) and checks it against the layer order. Pure algorithm layers
never import ROS (rclpy, messages, the ament index) nor a layer above them; no layer imports one above
it. The order, bottom to top, is the one docs and README describe."""
import ast
from pathlib import Path

import pytest

pytestmark = pytest.mark.pure

PACKAGE = Path(__file__).resolve().parent.parent / 'ros_ws' / 'src' / 'mvpose_nodes' / 'mvpose_nodes'
# The layers, numbered bottom to top (README's table): a module may import its own layer and the layers
# numbered below it, never a sibling of the same number nor a layer above.
LAYER_NUMBER = {'body': 1, 'vision': 2, 'studio': 2, 'fitting': 3, 'markers': 3, 'io': 4, 'ros': 5,
                'nodes': 6, 'tools': 6, 'app': 7}
LAYER_ORDER = tuple(LAYER_NUMBER)
PURE_LAYERS = ('body', 'vision', 'studio', 'fitting', 'markers')
# What the pure layers may not import (any submodule of these either).
ROS_MODULES = ('rclpy', 'rcl_interfaces', 'rosidl_runtime_py', 'rosidl_parser', 'ament_index_python',
               'builtin_interfaces', 'std_msgs', 'sensor_msgs', 'geometry_msgs', 'visualization_msgs',
               'diagnostic_msgs', 'mvpose_msgs')
# io reads and writes bags and message text without a node: no rclpy there.
NO_RCLPY_LAYERS = PURE_LAYERS + ('io',)


def layer_of(module):
    """The layer of a dotted mvpose_nodes module name, or None outside the package's layers."""
    parts = module.split('.')
    return parts[1] if parts[0] == 'mvpose_nodes' and len(parts) > 1 and parts[1] in LAYER_ORDER else None


def violations(package_dir=PACKAGE):
    """One line per import that breaks the layering: 'file:line: what'."""
    found = []
    for path in sorted(package_dir.rglob('*.py')):
        relative = path.relative_to(package_dir)
        if len(relative.parts) < 2:
            continue   # the package's own __init__.py
        layer = relative.parts[0]
        if layer not in LAYER_ORDER:
            found.append(f'{relative}: in no layer (known: {", ".join(LAYER_ORDER)})')
            continue
        for line, module in imported_modules_of(path, package_dir):
            root = module.split('.')[0]
            if layer in PURE_LAYERS and root in ROS_MODULES:
                found.append(f'{relative}:{line}: pure layer {layer}/ imports ROS module {module}')
            elif layer in NO_RCLPY_LAYERS and root == 'rclpy':
                found.append(f'{relative}:{line}: {layer}/ imports rclpy')
            target = layer_of(module)
            if target and target != layer and LAYER_NUMBER[target] >= LAYER_NUMBER[layer]:
                where = 'a layer above it' if LAYER_NUMBER[target] > LAYER_NUMBER[layer] else 'a sibling layer'
                found.append(f'{relative}:{line}: {layer}/ imports {module}, {where} ({target}/)')
    return found


def imported_modules_of(path, package_dir):
    """(line, dotted module name) of every import (module level or in a function) in the file at `path`
    of the package at package_dir (named mvpose_nodes); relative imports resolved, and `from X import
    Y` listed as both X and X.Y (Y may be a submodule)."""
    tree = ast.parse(path.read_text(), str(path))
    package = ['mvpose_nodes', *path.relative_to(package_dir).parts[:-1]]
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = package[:len(package) - node.level + 1] if node.level else []
            module = '.'.join(base + ([node.module] if node.module else []))
            # `from mvpose_nodes import app` imports the layer app itself
            found += [(node.lineno, f'{module}.{alias.name}') for alias in node.names] if module == 'mvpose_nodes' \
                else [(node.lineno, module)]
    return found


def test_every_module_keeps_to_its_layer():
    assert violations() == []


def test_every_module_is_in_a_layer_and_the_layers_are_the_documented_ones():
    folders = {p.name for p in PACKAGE.iterdir() if p.is_dir() and (p / '__init__.py').is_file()}
    assert folders == set(LAYER_ORDER)


@pytest.mark.parametrize('layer, source, expected', [
    ('fitting', 'import rclpy\n', 'pure layer fitting/ imports ROS module rclpy'),
    ('vision', 'def f():\n    from rclpy.node import Node\n', 'pure layer vision/ imports ROS module rclpy.node'),
    ('body', 'from sensor_msgs.msg import Image\n', 'pure layer body/ imports ROS module sensor_msgs.msg'),
    ('markers', 'from mvpose_nodes.ros import conversions\n', 'markers/ imports mvpose_nodes.ros, a layer above'),
    ('studio', 'from mvpose_nodes.app.main import main\n', 'a layer above it (app/)'),
    ('io', 'import rclpy.serialization\n', 'io/ imports rclpy'),
    ('nodes', 'from mvpose_nodes.tools.cli import UserError\n', 'nodes/ imports mvpose_nodes.tools.cli, a sibling'),
    ('markers', 'from mvpose_nodes.fitting import sync\n', 'markers/ imports mvpose_nodes.fitting, a sibling'),
    ('fitting', 'from ..vision import features\n', None),          # relative, downwards: fine
    ('vision', 'from ..fitting import objective\n', 'vision/ imports mvpose_nodes.fitting'),   # relative, upwards
])
def test_the_check_finds_an_import_that_breaks_the_layering(tmp_path, layer, source, expected):
    package = tmp_path / 'mvpose_nodes'
    for name in LAYER_ORDER:
        (package / name).mkdir(parents=True)
        (package / name / '__init__.py').write_text('')
    (package / layer / 'algorithm.py').write_text(source)
    found = violations(package)
    if expected is None:
        assert found == []
    else:
        assert len(found) == 1 and expected in found[0] and found[0].startswith(f'{layer}/algorithm.py:'), found


def test_no_folder_holds_more_than_15_modules_and_no_module_is_over_500_lines():
    for folder in [PACKAGE, *(p for p in PACKAGE.rglob('*') if p.is_dir() and p.name != '__pycache__')]:
        modules = list(folder.glob('*.py'))
        assert len(modules) <= 15, f'{folder}: {len(modules)} modules'
        for module in modules:
            lines = len(module.read_text().splitlines())
            assert lines <= 500, f'{module}: {lines} lines'
