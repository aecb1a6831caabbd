"""Shared set-up of the mvpose tests: an isolated DDS domain on loopback, and helpers that run
the real command-line tools as separate processes."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
FRONT_DOOR = ROOT / 'mvpose'

if 'MVPOSE_ROOT' not in os.environ:
    pytest.exit('run the tests through the front door: ./mvpose test', returncode=4)

# No DDS traffic leaves the machine in any test, and the tests do not see (or disturb) other
# ROS graphs on it: a domain of their own, chosen per run.
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ['ROS_DOMAIN_ID'] = str(1 + os.getpid() % 100)


def mvpose_command(*args):
    """The command line of `./mvpose ARGS` as a user types it."""
    return [str(FRONT_DOOR), *map(str, args)]


def run_mvpose(*args, timeout=60, check=True):
    """Run `./mvpose ARGS` to completion; the CompletedProcess (text output captured)."""
    result = subprocess.run(mvpose_command(*args), capture_output=True, text=True, timeout=timeout, cwd=ROOT)
    if check and result.returncode != 0:
        raise AssertionError(f'./mvpose {" ".join(map(str, args))} exited {result.returncode}:\n'
                             f'{result.stdout}\n{result.stderr}')
    return result


class Background:
    """A `./mvpose ARGS` process running beside the test; stopped with SIGINT like Ctrl-C."""

    def __init__(self, *args):
        self.args = args
        self.process = subprocess.Popen(mvpose_command(*args), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                        text=True, cwd=ROOT, start_new_session=True)

    def wait_for_stderr_line(self, fragment, timeout=20):
        """Block until the process writes a stderr line containing `fragment`; all lines so far."""
        lines = []
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            line = self.process.stderr.readline()
            if not line and self.process.poll() is not None:
                break
            lines.append(line)
            if fragment in line:
                return lines
        raise AssertionError(f'no stderr line with {fragment!r} from {self.args}: {lines}')

    def finish(self, timeout=30):
        """Wait for the process to end by itself; (returncode, stdout, stderr)."""
        out, err = self.process.communicate(timeout=timeout)
        return self.process.returncode, out, err

    def interrupt(self, timeout=30):
        """Ctrl-C, then wait; (returncode, stdout, stderr)."""
        if self.process.poll() is None:
            os.killpg(self.process.pid, signal.SIGINT)
        return self.finish(timeout)

    def kill(self, grace=10):
        """Ctrl-C first (a launch then stops its nodes, which run in sessions of their own), then SIGKILL."""
        if self.process.poll() is None:
            os.killpg(self.process.pid, signal.SIGINT)
            try:
                self.process.communicate(timeout=grace)
            except subprocess.TimeoutExpired:
                os.killpg(self.process.pid, signal.SIGKILL)
                self.process.communicate()


@pytest.fixture
def background():
    """Start `./mvpose ARGS` processes in the background; any still running are killed at the end."""
    started = []

    def start(*args):
        started.append(Background(*args))
        return started[-1]
    yield start
    for process in started:
        process.kill()


@pytest.fixture(scope='session')
def ros_context():
    """rclpy initialised once for the tests that talk over DDS from the test process itself."""
    import rclpy
    rclpy.init()
    yield
    rclpy.try_shutdown()


def assert_one_line_error(result, *fragments):
    """A user error: non-zero exit, exactly one line on stderr naming the problem, no traceback."""
    assert result.returncode != 0, result
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, f'expected one error line, got:\n{result.stderr}'
    assert 'Traceback' not in result.stderr + result.stdout
    for fragment in fragments:
        assert fragment in lines[0], f'{fragment!r} not in {lines[0]!r}'


sys.path.insert(0, str(Path(__file__).resolve().parent))
