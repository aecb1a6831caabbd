"""Messages between separate processes over DDS (loopback only), through rclpy and the topic tools."""
import re
import subprocess
import sys
from pathlib import Path

import pytest
import rclpy
import yaml
from common import Publisher, run_mvpose, spin_for, spin_until
from mvpose_msgs.msg import Skeleton
from samples import sample_skeleton

from mvpose_nodes.io.msgdict import message_to_yaml, set_message_fields
from mvpose_nodes.ros.helpers import EVERY_SKELETON, LATCHED
from mvpose_nodes.tools.topic import rate_statistics

pytestmark = pytest.mark.dds

TOPIC = '/test/dds_skeleton'

PUBLISHER_SCRIPT = f'''
import sys
sys.path.insert(0, {str(Path(__file__).parent)!r})
import rclpy
from mvpose_msgs.msg import Skeleton
from common import Publisher
from samples import sample_skeleton
rclpy.init()
node = rclpy.create_node('dds_test_publisher')
publisher = Publisher(node, Skeleton, {TOPIC!r}, 10).wait_for_subscribers(timeout=30)
publisher.publish(*(sample_skeleton(seed) for seed in (11, 12, 13)))
publisher.wait_for_acknowledgements()
'''


def test_skeleton_from_another_process_arrives_intact(tmp_path, ros_context):
    script = tmp_path / 'publish.py'
    script.write_text(PUBLISHER_SCRIPT)
    node = rclpy.create_node('dds_test_subscriber')
    received = []
    node.create_subscription(Skeleton, TOPIC, received.append, 10)
    publisher = subprocess.Popen([sys.executable, script], stderr=subprocess.PIPE, text=True)
    try:
        # (or the publisher failed: its stderr below)
        spin_until(node, lambda: len(received) == 3 or publisher.poll() not in (None, 0), 60, f'3 skeletons on {TOPIC}')
        assert publisher.wait(timeout=30) == 0, publisher.stderr.read()
    finally:
        publisher.kill()
        node.destroy_node()
    assert received == [sample_skeleton(seed) for seed in (11, 12, 13)]


def test_a_reader_of_every_skeleton_keeps_those_its_executor_has_not_taken(ros_context):
    """The bench's, the soak's and the demo's subscription (EVERY_SKELETON) to skeletons published as the
    skeleton_fitter publishes them (LATCHED): 20 published while the reader's executor is busy (not spinning)
    are all taken once it spins, in order. A LATCHED reader, as the bench used to be, keeps only the newest."""
    node = rclpy.create_node('dds_test_every_skeleton')
    try:
        every, newest = [], []
        node.create_subscription(Skeleton, TOPIC, every.append, EVERY_SKELETON)
        node.create_subscription(Skeleton, TOPIC, newest.append, LATCHED)
        skeletons = [sample_skeleton(seed) for seed in range(20)]
        publisher = Publisher(node, Skeleton, TOPIC, LATCHED).publish(*skeletons, subscribers=2)
        assert publisher.wait_for_acknowledgements(timeout=30)   # in both readers' histories, none taken yet
        spin_until(node, lambda: len(every) == 20, 30, f'20 skeletons on {TOPIC}')
        spin_for(node, 0.5)
    finally:
        node.destroy_node()
    assert every == skeletons
    assert newest == skeletons[-1:]


def test_topic_pub_to_topic_echo(background):
    sent = sample_skeleton(21)
    echo = background('topic', 'echo', TOPIC, '--once', '--timeout', 60)
    run_mvpose('topic', 'pub', TOPIC, 'mvpose_msgs/msg/Skeleton', message_to_yaml(sent, flow_style=True), '--once')
    code, out, err = echo.finish(timeout=60)
    assert code == 0, err
    assert set_message_fields(Skeleton(), yaml.safe_load(out.split('\n---')[0])) == sent


def test_echo_field_and_csv(background):
    sent = sample_skeleton(22)
    field = background('topic', 'echo', TOPIC, '--once', '--field', 'joints.8.position', '--timeout', 60)
    csv = background('topic', 'echo', TOPIC, '--once', '--field', 'stages.0', '--csv', '--timeout', 60)
    run_mvpose('topic', 'pub', TOPIC, 'mvpose_msgs/msg/Skeleton', message_to_yaml(sent, flow_style=True),
               '--once', '-w', 2)
    code, out, err = field.finish(timeout=60)
    head = sent.joints[8].position
    assert code == 0 and yaml.safe_load(out.split('\n---')[0]) == {'x': head.x, 'y': head.y, 'z': head.z}, err
    code, out, err = csv.finish(timeout=60)
    stage = sent.stages[0]
    assert code == 0, err
    assert out.splitlines()[0] == f'{stage.name},{stage.cost!r},{stage.evaluations},3,5,7,{stage.fitted}'


def test_topic_list_shows_types_and_hz_measures(background):
    publisher = background('topic', 'pub', '/test/ticks', 'std_msgs/msg/String', '{data: tick}', '--rate', 20)
    listing = run_mvpose('topic', 'list', '-t', '--spin-time', 3).stdout
    assert '/test/ticks [std_msgs/msg/String]' in listing.splitlines()
    hz = run_mvpose('topic', 'hz', '/test/ticks', '--duration', 4, timeout=60).stdout
    rates = [float(line.split(':')[1]) for line in hz.splitlines() if line.startswith('average rate:')]
    assert rates and all(10 < rate < 30 for rate in rates), hz  # published at 20 Hz
    publisher.interrupt()


def test_topic_bw_and_doctor_measure_a_topics_bandwidth(background):
    """10 Hz of 20 000-character strings: 200 kB/s and more (the serialised size has a header), as `topic bw`
    and `doctor` measure it; the doctor lists the publishing node on this host and the settings in force."""
    publisher = background('topic', 'pub', '/test/big', 'std_msgs/msg/String', '{data: %s}' % ('x' * 20000),
                           '--rate', 10)
    bw = run_mvpose('topic', 'bw', '/test/big', '--duration', 4, timeout=60).stdout
    rates = [float(line.split()[0]) for line in bw.splitlines() if line.endswith('messages') and 'KB/s' in line]
    # Over the most messages: the first report's 10 can come bunched after a late timer on a loaded machine
    # (273 KB/s from 10, then 228, 217, 212 from 20-40 with four processes busy on 2 cores, session 60).
    assert rates and 150 < rates[-1] < 260, bw
    doctor = run_mvpose('doctor', '--bandwidth-time', 3, timeout=60).stdout
    publisher.interrupt()
    row = next(line for line in doctor.splitlines() if line.startswith('  /test/big '))
    assert 'std_msgs/msg/String' in row and '1 pub (' in row, doctor
    assert 150 < float(row.split()[-2]) < 260 and row.split()[-1] == 'KB/s', row
    assert re.search(r'^  host \w+ \(this host\)[^\n]*\n(?:    .*\n)*    /mvpose_topic_pub$', doctor, re.MULTILINE), doctor
    assert re.search(r'^  ROS_AUTOMATIC_DISCOVERY_RANGE +LOCALHOST$', doctor, re.MULTILINE), doctor
    assert re.search(r'^  DDS-Security +(NOT )?built in', doctor, re.MULTILINE), doctor


STUCK_NODE_SCRIPT = '''
import ctypes, os, signal, sys, threading, time
from rclpy.node import Node
from mvpose_nodes.ros import helpers
helpers.STOP_LIMIT = 1.0
HANG_IN = sys.argv[1]


def hang_in_c():
    """For ever in C, where no signal reaches Python: a mutex locked twice."""
    mutex = ctypes.create_string_buffer(64)
    ctypes.CDLL(None).pthread_mutex_lock(mutex)
    ctypes.CDLL(None).pthread_mutex_lock(mutex)


class StuckNode(Node):
    """Stops itself with Ctrl-C, then hangs: in its clean-up, as rclpy's destroy_node once did, or in a
    callback, in C, as a node once did in the executor."""
    def __init__(self):
        super().__init__('stuck_node')
        if HANG_IN == 'callback':
            self.create_timer(0.5, self.stop_and_hang)
        else:
            threading.Timer(0.5, os.kill, args=(os.getpid(), signal.SIGINT)).start()

    def stop_and_hang(self):
        os.kill(os.getpid(), signal.SIGINT)
        hang_in_c()

    def destroy_node(self):
        if HANG_IN == 'clean-up holding the GIL':   # where no Python thread can run (as destroy_or_exit's test)
            ctypes.PyDLL(None).sleep(600)
        time.sleep(600)


sys.exit(helpers.run_node(StuckNode))
'''


@pytest.mark.parametrize('hang_in', ['clean-up', 'callback', 'clean-up holding the GIL'])
def test_a_node_that_hangs_after_ctrl_c_still_exits(tmp_path, hang_in):
    """run_node: a node that hangs after Ctrl-C, in its clean-up or in the executor, says so and exits
    STOP_LIMIT after (no orphan left behind its launcher, and within the launcher's SIGINT grace); where the
    clean-up hangs holding the GIL (no Python thread runs), the stacks are printed and the C library's timer
    ends it EXIT_TIMER_DELAY later."""
    script = tmp_path / 'stuck.py'
    script.write_text(STUCK_NODE_SCRIPT)
    result = run_mvpose('exec', 'python', script, hang_in, timeout=30)
    if hang_in == 'clean-up holding the GIL':
        assert 'still running' not in result.stderr and 'in destroy_node' in result.stderr, result.stderr
    else:
        assert ('StuckNode: still running 1 s after it was asked to stop (hung in rclpy); exiting without cleaning '
                'up' in result.stderr), result.stderr


TEARDOWN_SCRIPT = '''
import ctypes, sys, time
from mvpose_nodes.ros import helpers
helpers.STOP_LIMIT = 1.0


class Node:
    def destroy_node(self):
        if sys.argv[1] == 'hang':   # as rclpy's destroy_node once did after `topic echo --count 5` had printed
            time.sleep(600)
        elif sys.argv[1] == 'hang holding the GIL':   # ... and did so again where no Python thread could run
            ctypes.PyDLL(None).sleep(600)


print('the work done', flush=True)
started = time.monotonic()
code = helpers.destroy_or_exit(Node(), 'topic echo', 3)
print(f'returned {code} after {time.monotonic() - started:.1f} s')
'''


@pytest.mark.parametrize('hang', ['hang', 'hang holding the GIL', 'no hang'])
def test_a_tool_that_hangs_in_its_teardown_still_exits_with_its_result(tmp_path, hang):
    """destroy_or_exit: a command-line tool whose work is done and whose node's destroy_node hangs says so and
    ends with the tool's exit code STOP_LIMIT later; where the hang holds the GIL (no Python thread runs), the
    stacks are printed and the C library's timer ends it with that code; one that does not hang returns that
    code at once."""
    script = tmp_path / 'teardown.py'
    script.write_text(TEARDOWN_SCRIPT)
    result = run_mvpose('exec', 'python', script, hang, timeout=30, check=False)
    assert result.returncode == (0 if hang == 'no hang' else 3), result
    assert result.stdout.startswith('the work done\n'), result.stdout
    if hang == 'hang':
        assert ('topic echo: still running 1 s after its work was done (hung in rclpy); exiting without cleaning up'
                in result.stderr), result.stderr
    if hang == 'hang holding the GIL':
        assert 'still running' not in result.stderr and 'in destroy_node' in result.stderr, result.stderr
    if hang == 'no hang':
        assert 'returned 3 after 0.0 s' in result.stdout and 'still running' not in result.stderr, result
    else:
        assert 'returned' not in result.stdout


def test_rate_statistics_are_over_the_intervals_between_consecutive_arrivals():
    """Fewer arrivals than the window (the first reports of `topic hz`) and more: 4 Hz, then 2 Hz."""
    rate, shortest, longest, deviation, count = rate_statistics([0.0, 0.25, 0.5, 0.75], window=100)
    assert (rate, shortest, longest, deviation, count) == (4.0, 0.25, 0.25, 0.0, 3)
    rate, shortest, longest, deviation, count = rate_statistics([0.0, 0.25, 0.5, 1.0, 1.5], window=2)
    assert (rate, shortest, longest, deviation, count) == (2.0, 0.5, 0.5, 0.0, 2)
    assert rate_statistics([3.0], window=100) is None


STOP_SCRIPT = '''
import os, signal, threading, time
from mvpose_nodes.ros.helpers import StopSignal
with StopSignal() as stop:
    threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGINT)).start()
    started = time.monotonic()
    assert stop.wait(60.0) and stop.stopped and stop.wait(60.0)
    print(f'waited {time.monotonic() - started:.1f} s')
assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
'''


def test_a_stop_signal_during_a_wait_ends_it():
    """Ctrl-C while a tool's main thread sleeps in StopSignal.wait: the wait ends then, and so do later ones;
    the handlers in force before are put back."""
    result = subprocess.run([sys.executable, '-c', STOP_SCRIPT], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert float(result.stdout.split()[1]) < 30.0, result.stdout
