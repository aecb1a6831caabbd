"""What a message costs to cross DDS between two processes: its size, the CPU to serialise and deserialise
it, and the round trip to an echo process, which answers each message's header.

`measure(messages)` starts the echo (`python -m mvpose_nodes.tools.transport TYPE ...`, the environment's
ROS_DOMAIN_ID and RMW) and, per message, publishes it `count` times, one at a time, each with its own stamp,
and waits for the echo's std_msgs/Header of that stamp. A Header sent and answered is the baseline: what
a message costs to cross beyond that is the transport of its size (Fast DDS: shared memory on one host,
fragmented over UDP between hosts). Both directions use the graph's stream QoS (reliable, volatile, depth
TRANSPORT_DEPTH), as the camera_features publishers do.
"""
import subprocess
import sys
import time
from dataclasses import dataclass, field

import numpy as np

TOPIC_PREFIX = '/mvpose_transport'
ACK_TOPIC = f'{TOPIC_PREFIX}/ack'
TRANSPORT_DEPTH = 5
MATCH_TIMEOUT = 20.0    # [s] for the echo to start and subscribe
ANSWER_TIMEOUT = 2.0    # [s] for one message's answer
SERIALISE_REPEATS = 20  # serialisation is timed as the median of this many


@dataclass
class TransportResult:
    """One message kind: name, type, size [bytes], serialise / deserialise [ms] (median in this
    process), round trips [ms] (each message sent and its header answered), unanswered count."""
    name: str
    type_name: str
    size: int
    serialise_ms: float
    deserialise_ms: float
    round_trip_ms: list = field(default_factory=list)
    unanswered: int = 0


def header_of(message):
    """The std_msgs/Header a message is answered by: its header field, or itself when it is a Header."""
    return getattr(message, 'header', message)


def topic_of(index):
    return f'{TOPIC_PREFIX}/m{index}'


def transport_qos():
    """Both directions' QoS: the graph's stream QoS (reliable, volatile, depth TRANSPORT_DEPTH)."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    return QoSProfile(depth=TRANSPORT_DEPTH, reliability=ReliabilityPolicy.RELIABLE)


def echo_main(type_names):
    """The echo process: answers every message on topic_of(i) (of type type_names[i]) with its header on
    ACK_TOPIC, until stopped."""
    from rclpy.node import Node
    from std_msgs.msg import Header
    from mvpose_nodes.io.interfaces import message_class
    from mvpose_nodes.ros.helpers import run_node

    qos = transport_qos()

    class Echo(Node):
        def __init__(self):
            super().__init__('mvpose_transport_echo')
            publisher = self.create_publisher(Header, ACK_TOPIC, qos)
            for index, type_name in enumerate(type_names):
                self.create_subscription(message_class(type_name), topic_of(index),
                                         lambda message: publisher.publish(header_of(message)), qos)
    return run_node(Echo, [sys.argv[0]])


def serialisation_ms(message):
    """Median milliseconds to serialise `message` and to deserialise it again, in this process."""
    from rclpy.serialization import deserialize_message, serialize_message
    serialise, deserialise = [], []
    for _ in range(SERIALISE_REPEATS):
        started = time.perf_counter()
        data = serialize_message(message)
        serialise.append(time.perf_counter() - started)
        started = time.perf_counter()
        deserialize_message(data, type(message))
        deserialise.append(time.perf_counter() - started)
    return len(data), 1e3 * float(np.median(serialise)), 1e3 * float(np.median(deserialise))


def measure(messages, count, stop):
    """TransportResults of [(name, message)] (each with a header, or a std_msgs/Header), `count` round
    trips each, in order; `stop`: helpers.StopSignal (rclpy initialised)."""
    import rclpy
    from std_msgs.msg import Header
    from mvpose_nodes.io.interfaces import full_type_name
    from mvpose_nodes.ros.conversions import stamp_ns
    from mvpose_nodes.tools.cli import UserError

    def type_name(message):
        module = type(message).__module__.split('.')
        return full_type_name(f'{module[0]}/{module[1]}/{type(message).__name__}')

    type_names = [type_name(message) for _, message in messages]
    qos = transport_qos()
    node = rclpy.create_node('mvpose_transport')
    answers = {}
    node.create_subscription(Header, ACK_TOPIC, lambda header: answers.setdefault(stamp_ns(header), time.perf_counter()), qos)
    publishers = [node.create_publisher(type(message), topic_of(index), qos) for index, (_, message) in enumerate(messages)]
    echo = subprocess.Popen([sys.executable, '-m', 'mvpose_nodes.tools.transport', *type_names])
    try:
        deadline = time.monotonic() + MATCH_TIMEOUT
        while (any(p.get_subscription_count() == 0 for p in publishers) or node.count_publishers(ACK_TOPIC) == 0) \
                and not stop.stopped:
            if time.monotonic() > deadline or echo.poll() is not None:
                raise UserError(f'the transport echo did not subscribe to {TOPIC_PREFIX}/* within {MATCH_TIMEOUT:.0f} s')
            rclpy.spin_once(node, timeout_sec=0.05)
        results, sequence = [], 0
        for (name, message), publisher, kind in zip(messages, publishers, type_names):
            result = TransportResult(name, kind, *serialisation_ms(message))
            for attempt in range(count + 1):   # the first of each kind warms the path up and is not counted
                sequence += 1
                header = header_of(message)
                header.stamp.sec, header.stamp.nanosec = 0, sequence
                sent = time.perf_counter()
                publisher.publish(message)
                deadline = time.monotonic() + ANSWER_TIMEOUT
                while sequence not in answers and time.monotonic() < deadline and not stop.stopped:
                    rclpy.spin_once(node, timeout_sec=0.01)
                if stop.stopped:
                    raise KeyboardInterrupt
                if attempt == 0:
                    continue
                if sequence in answers:
                    result.round_trip_ms.append(1e3 * (answers[sequence] - sent))
                else:
                    result.unanswered += 1
            results.append(result)
        return results
    finally:
        echo.terminate()
        try:
            echo.wait(timeout=5)
        except subprocess.TimeoutExpired:
            echo.kill()
            echo.wait()
        node.destroy_node()


def format_transport(results):
    """The table `./mvpose bench --transport` prints."""
    baseline = next((r for r in results if r.type_name == 'std_msgs/msg/Header'), None)
    base = float(np.median(baseline.round_trip_ms)) if baseline and baseline.round_trip_ms else 0.0
    lines = ['transport over DDS between two processes (round trip: the message there, its header back)',
             f'  {"topic":<34} {"type":<30} {"bytes":>9} {"serialise":>9} {"deserialise":>11} '
             f'{"round trip median":>17} {"p95":>6} {"beyond a Header":>15}']
    for r in results:
        trips = np.asarray(r.round_trip_ms)
        median = float(np.median(trips)) if len(trips) else float('nan')
        p95 = float(np.percentile(trips, 95)) if len(trips) else float('nan')
        extra = '' if r is baseline else f'{median - base:15.2f}'
        lines.append(f'  {r.name:<34} {r.type_name:<30} {r.size:>9} {r.serialise_ms:>9.2f} {r.deserialise_ms:>11.2f} '
                     f'{median:>17.2f} {p95:>6.2f} {extra}'
                     + (f'   ({r.unanswered} unanswered)' if r.unanswered else ''))
    lines.append('  [ms]; serialise and deserialise: rclpy in this process, median; round trips: '
                 f'{len(results[0].round_trip_ms) + results[0].unanswered if results else 0} per topic')
    return '\n'.join(lines)


if __name__ == '__main__':
    sys.exit(echo_main(sys.argv[1:]))
