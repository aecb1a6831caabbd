"""One run of the whole mvpose graph on a camera bag over DDS (what `demo` and `bench` share).

The launch file's nodes (three camera_features and the skeleton_fitter, launch/mvpose.launch.yaml) run
as separate processes, supervised by launcher.Launch, their output going to a log file; `bag play`
replays the bag's images, calibration and ground truth once every subscriber downstream is connected;
a viewer node in this process receives /mvpose/skeleton and /mvpose/ground_truth, reports each fitted
frame, and the run records both to an output bag.
"""
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from mvpose_nodes.tools.cli import UserError

FEATURE_TOPICS = ('skin_ellipses', 'labelled_contour')   # the fitter's inputs
GRAPH_CAMERAS = (3, 5, 7)        # the defaults of launch/mvpose.launch.yaml
ALL_CAMERAS = tuple(range(1, 9))  # launch/mvpose8.launch.yaml's
CONNECT_TIMEOUT = 60.0           # [s] for every node to start and every topic to connect
QUIET_AFTER_PLAYBACK = 10.0      # [s] of no new skeleton after playback ends: the graph is done


@dataclass
class GraphRun:
    """What one run saw: skeletons {stamp_ns: Skeleton} fitted and true, the number of frame sets
    played, the wall time of the playback and of the whole run [s], and the nodes' log."""
    fitted: dict = field(default_factory=dict)
    truth: dict = field(default_factory=dict)
    frame_sets: int = 0
    playback_seconds: float = 0.0
    seconds: float = 0.0
    log: Path = None


def launch_file(cameras=GRAPH_CAMERAS):
    """The launch file of the checkout that runs with a node for each of `cameras`: launch/mvpose.launch.yaml
    (its defaults, GRAPH_CAMERAS) or launch/mvpose8.launch.yaml (ALL_CAMERAS)."""
    from mvpose_nodes.app.main import repository_root
    name = {GRAPH_CAMERAS: 'mvpose.launch.yaml', ALL_CAMERAS: 'mvpose8.launch.yaml'}[tuple(cameras)]
    return repository_root() / 'ros_ws' / 'src' / 'mvpose_nodes' / 'launch' / name


def run_graph(bag, log_path, rate=1.0, on_skeleton=None):
    """Run the graph on `bag` (its cameras GRAPH_CAMERAS) and return a GraphRun.

    rate: playback speed (1 = the bag's 25 frames per second); on_skeleton(message, run): called for
    each fitted skeleton as it arrives. Raises UserError when the graph does not come up.
    """
    import rclpy
    from mvpose_msgs.msg import Skeleton
    from mvpose_nodes.io.bagfile import BagReader
    from mvpose_nodes.ros.camera_bag import GROUND_TRUTH_TOPIC, SKELETON_TOPIC, cameras_in
    from mvpose_nodes.tools.launch import Launch, load_launch_file
    from mvpose_nodes.ros.conversions import stamp_ns
    from mvpose_nodes.ros.helpers import EVERY_SKELETON, StopSignal
    cameras_in(bag, GRAPH_CAMERAS)

    reader = BagReader(bag)
    images = [f'/cam{k}/image_raw/compressed' for k in GRAPH_CAMERAS]
    played = images + [f'/cam{k}/{kind}' for k in GRAPH_CAMERAS for kind in ('camera_info', 'camera_pose')]
    if GROUND_TRUTH_TOPIC in reader.topics:
        played.append(GROUND_TRUTH_TOPIC)
    run = GraphRun(frame_sets=reader.topics[images[0]].message_count, log=Path(log_path))
    run.log.parent.mkdir(parents=True, exist_ok=True)
    started = time.monotonic()
    playback_start = None
    with open(run.log, 'w') as log, StopSignal() as stop:
        launch = Launch(load_launch_file(launch_file()), output=log)
        node = rclpy.create_node('mvpose_graph_viewer')

        def fitted(message):
            if message.status == Skeleton.STATUS_LOST:
                return   # no fit for this frame set: the last pose repeated
            stamp = stamp_ns(message.header)
            run.fitted[stamp] = message
            if on_skeleton:
                on_skeleton(message, run)
        node.create_subscription(Skeleton, SKELETON_TOPIC, fitted, EVERY_SKELETON)
        node.create_subscription(Skeleton, GROUND_TRUTH_TOPIC,
                                 lambda message: run.truth.__setitem__(stamp_ns(message.header), message), 100)
        try:
            launch.start()
            wait_for_connections(node, launch, stop, run.log)
            player = subprocess.Popen([sys.executable, '-m', 'mvpose_nodes.app.main', 'bag', 'play', str(bag),
                                       '--topics', *played, '--wait-for-subscribers', '--rate', str(rate)],
                                      stdout=log, stderr=subprocess.STDOUT)
            playback_start = time.monotonic()
            last_seen, count = time.monotonic(), 0
            while not stop.stopped:
                rclpy.spin_once(node, timeout_sec=0.1)
                if len(run.fitted) != count:
                    last_seen, count = time.monotonic(), len(run.fitted)
                if player.poll() is not None:
                    if not run.playback_seconds:
                        run.playback_seconds = time.monotonic() - playback_start
                    if count >= run.frame_sets or time.monotonic() - max(last_seen, playback_start
                                                                        + run.playback_seconds) > QUIET_AFTER_PLAYBACK:
                        break
                if launch.wait(timeout=0) is not None:
                    raise UserError(f'a node of the graph stopped (exit code {launch.exit_code}); see {run.log}')
            if player.poll() is None:
                player.terminate()
            elif player.returncode:
                raise UserError(f'bag play failed (exit code {player.returncode}); see {run.log}')
        finally:
            node.destroy_node()
            launch.stop()
    run.seconds = time.monotonic() - started
    return run


def graph_inputs(cameras):
    """The (node, topic) subscriptions of the markerless graph of `cameras` that must have matched their
    publishers before frame sets can flow: the fitter's features and announcements, each camera's requests."""
    return ([('/skeleton_fitter', f'/cam{k}/{topic}') for k in cameras
             for topic in ('skin_ellipses', 'labelled_contour', 'frame_available')]
            + [(f'/cam{k}/camera_features', f'/cam{k}/frame_request') for k in cameras])


def wait_for_connections(node, launch, stop, log, cameras=GRAPH_CAMERAS):
    """Until the graph of `cameras` is connected: every subscription of graph_inputs has matched (as the
    nodes say on /diagnostics: MatchedEndpoints) and so have `node`'s own subscriptions of the graph's
    outputs (/mvpose/skeleton, labelled contours); the player waits for its own subscribers only. UserError
    naming `log` (the nodes' log) and what has not matched when a node stops or CONNECT_TIMEOUT passes."""
    import rclpy
    from mvpose_nodes.ros.camera_bag import SKELETON_TOPIC
    from mvpose_nodes.ros.diagnostics import MatchedEndpoints
    endpoints = MatchedEndpoints(node)
    wanted = graph_inputs(cameras)
    own = [subscription for subscription in node.subscriptions
           if subscription.topic_name == SKELETON_TOPIC or subscription.topic_name.endswith('/labelled_contour')]
    deadline = time.monotonic() + CONNECT_TIMEOUT
    while not stop.stopped:
        missing = endpoints.missing(wanted)
        missing += [f'{subscription.topic_name} -> this process' for subscription in own
                    if not subscription.get_publisher_count()]
        if not missing:
            return
        if launch.wait(timeout=0) is not None:
            raise UserError(f'a node of the graph stopped while starting (exit code {launch.exit_code}); see {log}')
        if time.monotonic() > deadline:
            raise UserError(f'the graph did not connect within {CONNECT_TIMEOUT:.0f} s (not matched: '
                            f'{", ".join(missing)}); see {log}')
        rclpy.spin_once(node, timeout_sec=0.1)


def write_run_bag(run, path):
    """Record the run's fitted and true skeletons to a rosbag2 MCAP bag at `path`."""
    from rclpy.serialization import serialize_message
    from mvpose_nodes.io.bagfile import BagWriter
    from mvpose_nodes.ros.camera_bag import GROUND_TRUTH_TOPIC, SKELETON_TOPIC, STREAM_QOS
    with BagWriter(path) as out:
        for topic, messages in ((SKELETON_TOPIC, run.fitted), (GROUND_TRUTH_TOPIC, run.truth)):
            if messages:
                out.add_topic(topic, 'mvpose_msgs/msg/Skeleton', [STREAM_QOS])
                for stamp in sorted(messages):
                    out.write(topic, serialize_message(messages[stamp]), stamp)
