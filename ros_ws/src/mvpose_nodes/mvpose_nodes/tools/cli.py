"""The command-line front ends' plumbing: user mistakes become one-line errors instead of tracebacks, and
the processes a front end starts end with it.

`UserError` is the front ends' own error. The layers below raise their own (a bag, a skin model, a
motion file, a parameter...); `exit_on_user_error` reports those in the same one line, exit code 2.
"""
import argparse
import contextlib
import ctypes
import signal
import sys

PR_SET_PDEATHSIG = 1   # linux/prctl.h


def end_with_parent():
    """In a child (before exec, or as a pool worker's initializer): SIGTERM it when the process that started
    it dies, however it dies (Linux prctl PR_SET_PDEATHSIG), so that a killed launch leaves no nodes behind
    in their own sessions and a killed `synth -j` or `eval suite` no workers."""
    ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)


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


def input_errors():
    """The exception types that mean bad input from the user, each raised by its own layer."""
    from mvpose_nodes.io.bagfile import BagError
    from mvpose_nodes.io.interfaces import MessageTypeError
    from mvpose_nodes.io.motion_export import ExportError
    from mvpose_nodes.ros.params import ParameterError
    from mvpose_nodes.studio.i3dpost import I3dpostError
    from mvpose_nodes.studio.mocap import MotionFileError
    from mvpose_nodes.vision.skin import SkinModelError
    return (UserError, BagError, MessageTypeError, ExportError, ParameterError, I3dpostError, MotionFileError,
            SkinModelError)


@contextlib.contextmanager
def exit_on_user_error(prog):
    """Print `prog: error: message` for bad input (input_errors) and exit 2; exit 130 quietly on Ctrl-C."""
    try:
        yield
    except KeyboardInterrupt:
        sys.exit(130)
    except Exception as error:
        if not isinstance(error, input_errors()):
            raise
        print(f'{prog}: error: {error}', file=sys.stderr)
        sys.exit(2)
