"""The subcommands of ./mvpose, run inside the built environment.

./mvpose (the front door at the top of the repository) sets up .venv and
ros_ws/install, sources ros_ws/install/local_setup.bash and then runs
`python -m mvpose_nodes.app.main ARGS`. Tools that are also ROS executables
(bag, topic, launch) keep their own argument parsers; this module only
routes to them, so `./mvpose bag play X` and `ros2 run mvpose_nodes bag play X`
behave the same.
"""
import importlib
import os
import shutil
import sys
from pathlib import Path

from mvpose_nodes.tools.cli import ArgumentParser, UserError, exit_on_user_error
from mvpose_nodes.tools.launch import package_executable

PACKAGE = 'mvpose_nodes'

# Subcommands that hand the rest of the command line to another tool's own parser.
ROUTED_TOOLS = {
    'bag': ('mvpose_nodes.tools.bag', 'record, play or inspect rosbag2 MCAP bags'),
    'topic': ('mvpose_nodes.tools.topic', 'echo, list, measure or publish live topics'),
    'doctor': ('mvpose_nodes.tools.doctor', "DDS settings, the graph's nodes by host, topics with their bandwidth"),
    'launch': ('mvpose_nodes.tools.launch', 'start the nodes of a launch YAML file as separate processes'),
    'demo': ('mvpose_nodes.app.demo', 'replay a bag through the graph and show the skeleton (README command 1)'),
    'synth': ('mvpose_nodes.app.synth', 'make an i3DPost-like multi-camera bag with exact ground truth'),
    'preview': ('mvpose_nodes.app.preview', 'contact sheet of every camera of a bag at one frame, skeleton drawn on'),
    'import-i3dpost': ('mvpose_nodes.app.import_i3dpost', 'turn i3DPost dataset frames and calibration into a bag'),
    'features': ('mvpose_nodes.app.features', 'evaluate or benchmark the camera-feature pipeline on a bag'),
    'skin': ('mvpose_nodes.app.skin', 'train the skin colour model'),
    'fit': ('mvpose_nodes.app.fit', 'fit the skeleton to a camera bag offline and record it'),
    'eval': ('mvpose_nodes.app.fit', 'fitted skeleton against ground truth: paper 000 Table 2 layout'),
    'markers': ('mvpose_nodes.app.markers', 'marker mode (paper 001): tracking evaluated against a synthetic marker bag'),
    'export': ('mvpose_nodes.app.export', 'fitted motion of a recorded bag as CSV, JSON or BVH'),
    'bench': ('mvpose_nodes.app.bench', 'end-to-end throughput and latency of the graph over DDS'),
    'soak': ('mvpose_nodes.app.bench', 'loop a bag through the graph: memory, latency drift and drops over a long run'),
}


def repository_root():
    """The checkout that ./mvpose runs from (MVPOSE_ROOT is set by the front door)."""
    root = os.environ.get('MVPOSE_ROOT')
    if not root:
        raise UserError('MVPOSE_ROOT is not set: run this through ./mvpose at the top of the repository')
    return Path(root)


def build_parser():
    """The top-level parser: its help, and one-line errors for unknown commands. The commands
    themselves take the rest of the command line as it is (see main)."""
    parser = ArgumentParser(
        prog='./mvpose', keep_ros_args=True,  # `run` passes them on
        description='mvpose: markerless multi-camera 3D human motion capture on ROS 2 Jazzy. '
                    'Every call first makes sure .venv and ros_ws are set up (cheap when nothing changed).')
    commands = parser.add_subparsers(dest='command', metavar='COMMAND', required=True)
    for name, (_, summary) in ROUTED_TOOLS.items():
        commands.add_parser(name, help=summary)
    commands.add_parser('test', help='run the test suite (pytest; extra arguments go to pytest, e.g. -k bag)')
    run = commands.add_parser('run', help='run a node or tool of mvpose_nodes, like `ros2 run mvpose_nodes`',
                              description='Run EXECUTABLE of mvpose_nodes with the rest of the command line, '
                                          'e.g. ./mvpose run camera_features --ros-args -r __ns:=/cam3')
    run.add_argument('executable')
    run.add_argument('args', nargs='*', help='arguments for the executable (e.g. --ros-args ...)')
    execute = commands.add_parser('exec', help='run any command inside the built environment',
                                  description='Run CMD with .venv and ros_ws/install on the environment, '
                                              'e.g. ./mvpose exec python -c "import rclpy"')
    execute.add_argument('cmd', nargs='+', metavar='CMD')
    return parser, commands.choices


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    parser, commands = build_parser()
    if not argv or argv[0] not in commands:
        parser.parse_args(argv)  # prints the help, or a one-line error naming the unknown command
    command, rest = argv[0], argv[1:]
    asks_help = rest[:1] in (['-h'], ['--help'])
    with exit_on_user_error(f'./mvpose {command}'):
        if command in ROUTED_TOOLS:
            module = importlib.import_module(ROUTED_TOOLS[command][0])
            entry = getattr(module, f'{command}_main', None) or module.main
            return entry(rest, prog=f'./mvpose {command}')
        if command == 'test':
            os.chdir(repository_root())
            # The whole suite unless the user names tests (paths or node ids) to run.
            names_tests = any(not a.startswith('-') and os.path.exists(a.split('::')[0]) for a in rest)
            command_line = [sys.executable, '-m', 'pytest', *([] if names_tests else ['tests']), *rest]
            os.execv(sys.executable, command_line)
        if not rest or asks_help:
            commands[command].parse_args(rest)  # help, or the one-line error for the missing argument
        if command == 'run':
            path = package_executable(PACKAGE, rest[0])
            if path is None:
                known = sorted(p.name for prefix in filter(None, os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep))
                               for p in Path(prefix, 'lib', PACKAGE).glob('*') if os.access(p, os.X_OK))
                raise UserError(f"no executable '{rest[0]}' in package {PACKAGE} (it has: {', '.join(known)})")
            os.execv(path, [str(path), *rest[1:]])
        if command == 'exec':
            if shutil.which(rest[0]) is None:
                raise UserError(f"command not found: '{rest[0]}'")
            os.execvp(rest[0], rest)
    return 0


if __name__ == '__main__':
    sys.exit(main())
