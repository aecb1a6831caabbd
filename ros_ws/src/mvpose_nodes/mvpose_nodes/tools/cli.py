"""One place that turns user mistakes into one-line errors instead of tracebacks."""
import argparse
import contextlib
import sys


class UserError(Exception):
    """Bad input from the user (file, topic, type, parameter): reported in one line, exit code 2."""


def without_ros_args(argv):
    """argv less its ROS sections (`--ros-args ... [--]`), which rclpy.init reads from sys.argv itself."""
    kept, in_ros_section = [], False
    for word in argv:
        if word == '--ros-args':
            in_ros_section = True
        elif in_ros_section and word == '--':
            in_ros_section = False
        elif not in_ros_section:
            kept.append(word)
    return kept


class ArgumentParser(argparse.ArgumentParser):
    """argparse with a one-line error (`prog: error: ... (see --help)`) instead of usage + error,
    and that leaves ROS arguments to rclpy (so `ros2 run mvpose_nodes bag ... --ros-args ...` works)."""

    def __init__(self, *args, keep_ros_args=False, **kwargs):
        super().__init__(*args, **kwargs)
        self.keep_ros_args = keep_ros_args

    def parse_args(self, args=None, namespace=None):
        args = sys.argv[1:] if args is None else args
        return super().parse_args(args if self.keep_ros_args else without_ros_args(args), namespace)

    def error(self, message):
        self.exit(2, f'{self.prog}: error: {message} (see {self.prog} --help)\n')


@contextlib.contextmanager
def exit_on_user_error(prog):
    """Print `prog: error: message` for a UserError and exit 2; exit 130 quietly on Ctrl-C."""
    try:
        yield
    except UserError as error:
        print(f'{prog}: error: {error}', file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        sys.exit(130)
