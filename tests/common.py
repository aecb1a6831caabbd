"""Plain helpers of the mvpose tests (fixtures are in conftest.py): the ./mvpose commands run as a user
runs them, and, for the tests that talk over DDS themselves, spinning a node until something holds,
publishing once subscribers matched, and waiting for the graph to connect.

Importing this module imports no ROS package (rclpy is imported where it is used), so the pure tier and
the publisher scripts that tests start in other processes can use it too."""
import os
import signal
import subprocess
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
FRONT_DOOR = ROOT / 'mvpose'


# ---- the front door as separate processes ------------------------------------------------------

def mvpose_command(*args):
    """The command line of `./mvpose ARGS` as a user types it."""
    return [str(FRONT_DOOR), *map(str, args)]


def fault_handler_environment():
    """This process's environment (as the fixtures set it) with Python's faulthandler on, which prints every
    thread's stack on SIGABRT: how a test learns where a process hung."""
    return {**os.environ, 'PYTHONFAULTHANDLER': '1'}


def run_mvpose(*args, timeout=60, check=True):
    """Run `./mvpose ARGS` to completion; the CompletedProcess (text output captured). A process still
    running after `timeout` [s] fails the test with the Python stacks of its threads (see stacks_of_hung)."""
    process = subprocess.Popen(mvpose_command(*args), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               cwd=ROOT, env=fault_handler_environment())
    try:
        stdout, stderr = process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        raise AssertionError(f'./mvpose {" ".join(map(str, args))} did not end within {timeout} s; '
                             f'{stacks_of_hung(process)}') from None
    result = subprocess.CompletedProcess(process.args, process.returncode, stdout, stderr)
    if check and result.returncode != 0:
        raise AssertionError(f'./mvpose {" ".join(map(str, args))} exited {result.returncode}:\n'
                             f'{result.stdout}\n{result.stderr}')
    return result


def stacks_of_hung(process):
    """End a process that hangs with SIGABRT, which Python's faulthandler (enabled in its environment)
    answers by printing every thread's stack: its output so far and those stacks, to say where it hung."""
    process.send_signal(signal.SIGABRT)
    try:
        stdout, stderr = process.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        process.kill()
        stdout, stderr = process.communicate()
    last_lines = '\n'.join(stdout.splitlines()[-20:])  # a chatty tool's output would hide the stacks
    return f'the last lines of its output and the stacks of its threads:\n{last_lines}\n{stderr}'


class Background:
    """A `./mvpose ARGS` process running beside the test; stopped with SIGINT like Ctrl-C."""

    def __init__(self, *args, prefix=(), environment=None):
        """`prefix`: a command that runs the rest (e.g. `ip netns exec NS`); `environment`: variables set on
        top of this process's."""
        self.args = args
        self.process = subprocess.Popen([*prefix, *mvpose_command(*args)], stdout=subprocess.PIPE,
                                        stderr=subprocess.PIPE, text=True, cwd=ROOT, start_new_session=True,
                                        env={**fault_handler_environment(), **(environment or {})})

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
        try:
            out, err = self.process.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            raise AssertionError(f'./mvpose {" ".join(map(str, self.args))} did not end within {timeout} s; '
                                 f'{stacks_of_hung(self.process)}') from None
        return self.process.returncode, out, err

    def interrupt(self, timeout=30):
        """Ctrl-C, then wait; (returncode, stdout, stderr)."""
        if self.process.poll() is None:
            os.killpg(self.process.pid, signal.SIGINT)
        return self.finish(timeout)

    def kill(self, grace=None):
        """Ctrl-C first (a launch then stops its nodes, which run in sessions of their own), then SIGKILL after
        `grace` [s]; by default longer than a launch's own escalation (SIGINT, SIGTERM, then SIGKILL to a node
        still running): a launcher killed as it is about to kill a node slow to stop left that node running."""
        if grace is None:
            from mvpose_nodes.tools.launch import SIGINT_TIMEOUT, SIGTERM_TIMEOUT
            grace = SIGINT_TIMEOUT + SIGTERM_TIMEOUT + 5.0
        if self.process.poll() is None:
            os.killpg(self.process.pid, signal.SIGINT)
            try:
                self.process.communicate(timeout=grace)
            except subprocess.TimeoutExpired:
                os.killpg(self.process.pid, signal.SIGKILL)
                self.process.communicate()


def assert_one_line_error(result, *fragments):
    """A user error: non-zero exit, exactly one line on stderr naming the problem, no traceback."""
    assert result.returncode != 0, result
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, f'expected one error line, got:\n{result.stderr}'
    assert 'Traceback' not in result.stderr + result.stdout
    for fragment in fragments:
        assert fragment in lines[0], f'{fragment!r} not in {lines[0]!r}'


# ---- DDS from the test process (rclpy initialised: the ros_context fixture, or rclpy.init()) -----

def spin_until(node, condition, timeout, what):
    """Spin `node` until `condition()` holds; fails naming `what` was awaited when `timeout` [s] passes first."""
    import rclpy
    deadline = time.monotonic() + timeout
    while not condition() and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.05)
    assert condition(), f'timed out after {timeout} s waiting for {what}'


def spin_for(node, seconds):
    """Spin `node` for `seconds`, taking whatever arrives meanwhile."""
    import rclpy
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=min(0.05, max(deadline - time.monotonic(), 0.0)))


class Publisher:
    """Publishes from the test process on one topic with a given QoS (a depth, or a QoSProfile), once the
    wanted number of subscriptions matched: what a volatile publisher sends before that is lost."""

    def __init__(self, node, message_type, topic, qos=10):
        self.node, self.topic = node, topic
        self.publisher = node.create_publisher(message_type, topic, qos)

    def wait_for_subscribers(self, count=1, timeout=30):
        """Spin the node until `count` subscriptions matched this publisher."""
        spin_until(self.node, lambda: self.publisher.get_subscription_count() >= count, timeout,
                   f'{count} subscriber(s) on {self.topic}')
        return self

    def publish(self, *messages, subscribers=1, timeout=30, interval=0.0):
        """Wait for `subscribers` matched subscriptions, then publish `messages`, `interval` [s] apart."""
        self.wait_for_subscribers(subscribers, timeout)
        for index, message in enumerate(messages):
            if index and interval:
                time.sleep(interval)
            self.publisher.publish(message)
        return self

    def wait_for_acknowledgements(self, timeout=5):
        """Until every reliable subscriber acknowledged what was published (or `timeout` [s]): before a
        publishing process exits. True when all were acknowledged."""
        from rclpy.duration import Duration
        return self.publisher.wait_for_all_acked(Duration(seconds=timeout))


def wait_for_graph(inputs=(), outputs=(), timeout=60):
    """Until the nodes' subscriptions `inputs` have matched a publisher and their publishers `outputs` a
    subscription ((fully qualified node name, topic) pairs; an output may add the count wanted), as the nodes
    say on /diagnostics (ros.diagnostics.MatchedEndpoints): connected, not only discovered. The player waits
    for its own subscribers only, not for the nodes downstream of them."""
    import rclpy
    from mvpose_nodes.ros.diagnostics import MatchedEndpoints
    node = rclpy.create_node('graph_watcher')
    endpoints = MatchedEndpoints(node)
    try:
        deadline = time.monotonic() + timeout
        while (missing := endpoints.missing(inputs, outputs)) and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.1)
        assert not missing, f'the graph did not connect within {timeout} s: not matched: {", ".join(missing)}'
    finally:
        node.destroy_node()


# The graph of launch/mvpose.launch.yaml: its cameras, and what a player gives them (not the ground truth).
GRAPH_LAUNCH_FILE = 'ros_ws/src/mvpose_nodes/launch/mvpose.launch.yaml'
GRAPH_CAMERAS = (3, 5, 7)
# A bag rate the whole graph keeps up with on 2 cores, a start's first frame sets included: while a start's
# labellings of the body are compared (fitting/hypotheses.py) each frame set is fitted up to 8 times, 0.5-0.7 s.
GRAPH_RATE = 0.05
GRAPH_INPUTS = [f'/cam{k}/{name}' for k in GRAPH_CAMERAS for name in ('image_raw/compressed', 'camera_info', 'camera_pose')]
SKELETON_OUT = ('/skeleton_fitter', '/mvpose/skeleton')   # an output of wait_for_graph: someone receives it


class SkeletonRecorder:
    """/mvpose/skeleton as it comes, in this process (make it before starting what publishes, so that it
    misses none): `received` holds (time.monotonic() of arrival, stamp [ns], status, status_message),
    `joints` {stamp [ns]: (15, 3) [m]}."""

    def __init__(self, name='skeleton_recorder'):
        import rclpy
        from mvpose_msgs.msg import Skeleton
        from rclpy.qos import DurabilityPolicy, QoSProfile
        self.node = rclpy.create_node(name)
        self.received = []
        self.joints = {}
        # Deep enough to keep every skeleton while the test is not spinning; transient-local as offered.
        self.node.create_subscription(Skeleton, '/mvpose/skeleton', self.take,
                                      QoSProfile(depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL))

    def take(self, message):
        stamp = message.header.stamp.sec * 10**9 + message.header.stamp.nanosec
        self.received.append((time.monotonic(), stamp, message.status, message.status_message))
        from mvpose_nodes.ros.conversions import joints_from_skeleton
        self.joints[stamp] = joints_from_skeleton(message)

    def spin_for(self, seconds):
        spin_for(self.node, seconds)

    def spin_until_count(self, count, timeout):
        spin_until(self.node, lambda: len(self.received) >= count, timeout, f'{count} skeletons')

    def stamps(self):
        return [stamp for _, stamp, _, _ in self.received]

    def close(self):
        self.node.destroy_node()


FITTED_KEYPOINTS = ('root', 'neck', 'head', 'left_wrist', 'right_wrist', 'left_elbow', 'right_elbow', 'left_ankle',
                    'right_ankle', 'left_knee', 'right_knee')


def rendered_views(motion, cameras, frames):
    """Per frame of `frames` (indices of motion, a studio BodyMotion): (truth joints (15, 3) [m], [fitter.View]),
    each view with the keypoints projected from the truth (those inside the image) and the outline of the
    studio's true mask."""
    from mvpose_nodes.body.model import JOINT_NAMES
    from mvpose_nodes.fitting.views import View
    from mvpose_nodes.fitting.objective import outline_of
    from mvpose_nodes.fitting.stage_search import KEYPOINT_JOINT
    from mvpose_nodes.studio import scene
    from mvpose_nodes.vision.contour import outer_contour
    prepared = [scene.prepare_camera(camera) for camera in cameras]
    found = []
    for i in frames:
        truth = motion.joints[i]
        pose = scene.BodyPose(truth, motion.toes[i], motion.hand_tips[i], motion.head_forward[i])
        views = []
        for camera, view in zip(cameras, prepared):
            pixels, _ = camera.project(truth)
            keypoints = {n: (*pixels[JOINT_NAMES.index(KEYPOINT_JOINT.get(n, n))], 1.0) for n in FITTED_KEYPOINTS}
            keypoints = {n: k for n, k in keypoints.items()   # as the features: none outside the image
                         if 0 <= k[0] < camera.width and 0 <= k[1] < camera.height}
            outline = outline_of(outer_contour(scene.render(view, pose, scene.Appearance()).labels > 0))
            views.append(View(camera, None, keypoints, outline=outline))
        found.append((truth, views))
    return found
