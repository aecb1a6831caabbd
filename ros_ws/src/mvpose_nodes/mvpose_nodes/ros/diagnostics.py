"""Where a node's CPU goes, and the ROS diagnostics topic.

StageClock adds up the CPU seconds of the calling thread (time.thread_time) spent in each named stage of
a node's work. NodeDiagnostics publishes the node's state once a second as diagnostic_msgs/DiagnosticArray
on /diagnostics, the topic that ROS tools (rqt_robot_monitor, diagnostic_aggregator, Foxglove) read: one
DiagnosticStatus named after the node, hardware_id the host (host_identity: its name and IPv4 addresses), its level and message from the node, and as
values the node's own counters and the CPU seconds since the node started (and, logged once and in the
message, any publisher of another message type on a topic the node subscribes: foreign_publishers):
  cpu/process                   every thread of the process (time.process_time)
  cpu/thread/<name>             one thread (e.g. 'executor': rclpy's callbacks, taking and deserialising
                                messages; 'preparing' and 'fitting': the fitter's two workers)
  cpu/pool/<name>               the running threads of a thread pool together (concurrent.futures names
                                them <name>_0, <name>_1, ...; e.g. the fitter's 'hypotheses', which fit the
                                labellings and a stage's searches beside the 'fitting' thread)
  cpu/stage/<stage>, calls/<stage>   the StageClock stages (each within one of the threads)
  publishers matched/<topic>    publishers matched by the node's subscription of <topic>, and
  subscribers matched/<topic>   subscriptions matched by its publisher of <topic> (MatchedEndpoints: how a
                                launcher or a test knows the graph is connected, not only discovered)
What no stage covers in a thread is rclpy's own work there (take, deserialise, executor); what no
thread or pool covers in the process is DDS's threads (transport, discovery) and the interpreter's.
"""
import fcntl
import socket
import struct
import threading
import time
from contextlib import contextmanager

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

DIAGNOSTICS_TOPIC = '/diagnostics'
DIAGNOSTICS_PERIOD = 1.0   # [s], as ROS's diagnostic_updater publishes
PUBLISHERS_MATCHED = 'publishers matched/'
SUBSCRIBERS_MATCHED = 'subscribers matched/'
LEVELS = {'ok': DiagnosticStatus.OK, 'warn': DiagnosticStatus.WARN, 'error': DiagnosticStatus.ERROR}


def host_addresses():
    """{interface: IPv4 address} of this host's interfaces that have one (loopback included)."""
    addresses = {}
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        for _, name in socket.if_nameindex():
            try:   # SIOCGIFADDR (linux/sockios.h): the interface's address, in a struct ifreq
                answer = fcntl.ioctl(probe.fileno(), 0x8915, struct.pack('256s', name.encode()[:15]))
            except OSError:   # no IPv4 address (or down)
                continue
            addresses[name] = socket.inet_ntoa(answer[20:24])
    return addresses


def host_identity():
    """This host as DiagnosticStatus.hardware_id names it: 'NAME (ADDRESS, ...)', its IPv4 addresses
    other than loopback; the name alone is not enough where hosts share one (network namespaces, clones)."""
    addresses = [address for name, address in host_addresses().items() if not address.startswith('127.')]
    return f'{socket.gethostname()} ({", ".join(addresses) or "loopback only"})'


class StageClock:
    """CPU seconds per stage: `with clock('fit'): ...` adds the calling thread's CPU time of the block."""

    def __init__(self):
        self.seconds, self.calls = {}, {}
        self._lock = threading.Lock()

    @contextmanager
    def __call__(self, stage):
        started = time.thread_time()
        try:
            yield
        finally:
            spent = time.thread_time() - started
            with self._lock:
                self.seconds[stage] = self.seconds.get(stage, 0.0) + spent
                self.calls[stage] = self.calls.get(stage, 0) + 1

    def snapshot(self):
        """{stage: (CPU seconds, calls)} so far."""
        with self._lock:
            return {stage: (seconds, self.calls[stage]) for stage, seconds in self.seconds.items()}


def thread_cpu_seconds(thread):
    """CPU seconds of a running threading.Thread (its POSIX thread CPU clock); None once it has ended."""
    try:
        return time.clock_gettime(time.pthread_getcpuclockid(thread.ident))
    except (OSError, TypeError):
        return None


def pool_cpu_seconds(name):
    """CPU seconds of the running threads of the thread pool `name` (ThreadPoolExecutor's
    thread_name_prefix: its threads are named <name>_<i>) together; 0 before it has started one."""
    pool = [thread for thread in threading.enumerate() if thread.name.startswith(f'{name}_')]
    return sum(seconds for seconds in map(thread_cpu_seconds, pool) if seconds is not None)


def status_values(clocks, threads, counters, pools=()):
    """The DiagnosticStatus values [KeyValue] of StageClocks, {name: threading.Thread}, {key: value} and
    the names of thread pools (pool_cpu_seconds)."""
    values = [KeyValue(key='cpu/process', value=f'{time.process_time():.6f}')]
    for name, thread in threads.items():
        seconds = thread_cpu_seconds(thread)
        if seconds is not None:
            values.append(KeyValue(key=f'cpu/thread/{name}', value=f'{seconds:.6f}'))
    values += [KeyValue(key=f'cpu/pool/{name}', value=f'{pool_cpu_seconds(name):.6f}') for name in pools]
    for clock in clocks:
        for stage, (seconds, calls) in clock.snapshot().items():
            values += [KeyValue(key=f'cpu/stage/{stage}', value=f'{seconds:.6f}'),
                       KeyValue(key=f'calls/{stage}', value=str(calls))]
    values += [KeyValue(key=key, value=str(value)) for key, value in counters.items()]
    return values


def stage_cpu(status):
    """Parse a DiagnosticStatus of NodeDiagnostics: ({'process': s, 'thread/<name>': s, 'pool/<name>': s,
    'stage/<stage>': s},
    {stage: calls}, {other key: value})."""
    cpu, calls, other = {}, {}, {}
    for item in status.values:
        if item.key.startswith('cpu/'):
            cpu[item.key[4:]] = float(item.value)
        elif item.key.startswith('calls/'):
            calls[item.key[6:]] = int(item.value)
        else:
            other[item.key] = item.value
    return cpu, calls, other


class NodeDiagnostics:
    """Publishes `node`'s DiagnosticStatus on /diagnostics every DIAGNOSTICS_PERIOD. state() -> (level
    'ok' | 'warn' | 'error', message, {key: value}); clocks: StageClocks; threads: {name: Thread} (the
    executor's, the thread that creates this, is added as 'executor'); pools: names of the node's thread
    pools (pool_cpu_seconds)."""

    def __init__(self, node, state, clocks=(), threads=None, pools=()):
        self.node, self.state, self.clocks, self.pools = node, state, list(clocks), tuple(pools)
        self.threads = {'executor': threading.current_thread(), **(threads or {})}
        self.publisher = node.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC, 10)
        self.hardware_id = host_identity()
        self.reported = set()   # (topic, type) of the publishers of a wrong type already logged
        node.create_timer(DIAGNOSTICS_PERIOD, self.publish)

    def publish(self):
        level, message, counters = self.state()
        strangers = foreign_publishers(self.node)
        for topic, found, expected in strangers:
            if (topic, found) not in self.reported:
                self.reported.add((topic, found))
                self.node.get_logger().warning(f'{topic}: a publisher of {found} (not {expected}): DDS does not '
                                               'connect it to this node, so its messages are not received')
        if strangers:
            level = 'error' if level == 'error' else 'warn'
            message += '; ' + ', '.join(f'{topic} has a publisher of {found}' for topic, found, _ in strangers)
        matched = [KeyValue(key=f'{PUBLISHERS_MATCHED}{subscription.topic_name}',
                            value=str(subscription.get_publisher_count())) for subscription in self.node.subscriptions]
        matched += [KeyValue(key=f'{SUBSCRIBERS_MATCHED}{publisher.topic_name}',
                             value=str(publisher.get_subscription_count())) for publisher in self.node.publishers]
        status = DiagnosticStatus(level=LEVELS[level], name=self.node.get_fully_qualified_name(), message=message,
                                  hardware_id=self.hardware_id,
                                  values=status_values(self.clocks, self.threads, counters, self.pools) + matched)
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.node.get_clock().now().to_msg()
        self.publisher.publish(array)


class MatchedEndpoints:
    """What the nodes of a graph say on /diagnostics about their connections, as of each node's newest status
    (a node not heard from yet has matched nothing). missing(inputs, outputs): the wanted (fully qualified
    node name, topic) subscriptions `inputs` that have matched no publisher yet, and the (node name, topic)
    publishers `outputs` that have matched no subscription yet, each as a line of text."""

    def __init__(self, node):
        self.matched = {}   # (prefix, node name, topic) -> count
        node.create_subscription(DiagnosticArray, DIAGNOSTICS_TOPIC, self.take, 50)

    def take(self, array):
        for status in array.status:
            for value in status.values:
                for prefix in (PUBLISHERS_MATCHED, SUBSCRIBERS_MATCHED):
                    if value.key.startswith(prefix):
                        self.matched[(prefix, status.name, value.key[len(prefix):])] = int(value.value)

    def missing(self, inputs=(), outputs=()):
        """`outputs` may also give (node name, topic, count): that many subscriptions matched."""
        lines = [f'{topic} -> {name}' for name, topic in inputs
                 if self.matched.get((PUBLISHERS_MATCHED, name, topic), 0) < 1]
        for name, topic, count in ((*output, 1)[:3] for output in outputs):
            if self.matched.get((SUBSCRIBERS_MATCHED, name, topic), 0) < count:
                lines.append(f'{name} -> {topic} ({count} subscriber(s))')
        return lines


def foreign_publishers(node):
    """[(topic, its publisher's type, the type `node` subscribes)] for each publisher on a topic the node
    subscribes whose message type is another: DDS never connects the two, and this rmw (Fast DDS in Jazzy)
    raises no incompatible-type event, so without this a wrong type on a topic is silence."""
    strangers = []
    for subscription in node.subscriptions:
        kind = subscription.msg_type
        expected = f"{kind.__module__.split('.')[0]}/msg/{kind.__name__}"
        for info in node.get_publishers_info_by_topic(subscription.topic_name):
            if info.topic_type != expected:
                strangers.append((subscription.topic_name, info.topic_type, expected))
    return strangers
