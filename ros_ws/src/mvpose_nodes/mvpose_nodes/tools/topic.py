"""`topic echo | list | hz | bw | pub`: ros2cli's topic verbs, for environments without ros2cli."""
import math
import sys
import time

import yaml

from mvpose_nodes.tools.cli import ArgumentParser, UserError, exit_on_user_error
from mvpose_nodes.io.interfaces import full_type_name, message_class

DISCOVERY_TIME = 1.0  # [s] default wait for the graph to be discovered


def build_parser(prog):
    parser = ArgumentParser(prog=prog, description=__doc__.splitlines()[0])
    verbs = parser.add_subparsers(dest='verb', metavar='VERB', required=True)

    echo = verbs.add_parser('echo', help='print the messages of a topic as YAML',
                            description='Print the messages of a topic, as YAML documents separated by ---, '
                                        'like ros2 topic echo. The subscription QoS is adapted to the '
                                        'publishers (reliable / transient-local only if all of them are).')
    echo.add_argument('topic')
    echo.add_argument('type', nargs='?', help='message type, e.g. mvpose_msgs/msg/Skeleton (default: what the publishers publish)')
    echo.add_argument('--once', action='store_true', help='print one message and exit')
    echo.add_argument('-n', '--count', type=int, metavar='N', help='exit after N messages')
    echo.add_argument('--field', metavar='PATH', help='print only this field, e.g. header.stamp or joints.0.position')
    echo.add_argument('--csv', action='store_true', help='one comma-separated line per message')
    echo.add_argument('--no-arr', action='store_true', help='show arrays as their type and length')
    echo.add_argument('--no-str', action='store_true', help='show strings as their length')
    echo.add_argument('-l', '--truncate-length', type=int, metavar='N', help='cut strings and arrays at N items')
    echo.add_argument('--timeout', type=float, metavar='S',
                      help='give up with exit code 1 if no publisher appeared or no message arrived within S seconds')

    listing = verbs.add_parser('list', help='list the topics of the graph',
                               description='List the live topics, like ros2 topic list.')
    listing.add_argument('-t', '--show-types', action='store_true', help='show each topic\'s type')
    listing.add_argument('--spin-time', type=float, default=DISCOVERY_TIME, metavar='S',
                         help=f'time to discover the graph (default {DISCOVERY_TIME})')

    hz = verbs.add_parser('hz', help='measure the publishing rate of a topic',
                          description='Print the receive rate of a topic every second, like ros2 topic hz.')
    hz.add_argument('topic')
    hz.add_argument('-w', '--window', type=int, default=10000, help='number of intervals averaged (default 10000)')
    hz.add_argument('--duration', type=float, metavar='S', help='stop after S seconds')

    bw = verbs.add_parser('bw', help='measure the bandwidth of a topic',
                          description='Print the bandwidth a topic takes (serialised messages received) every '
                                      'second, like ros2 topic bw.')
    bw.add_argument('topic')
    bw.add_argument('-w', '--window', type=int, default=100, help='number of messages averaged (default 100)')
    bw.add_argument('--duration', type=float, metavar='S', help='stop after S seconds')

    pub = verbs.add_parser('pub', help='publish a message given as YAML',
                           description='Publish a message, like ros2 topic pub, e.g. '
                                       "topic pub /x std_msgs/msg/String '{data: hello}' --once")
    pub.add_argument('topic')
    pub.add_argument('type')
    pub.add_argument('values', nargs='?', default='{}', help='field values as YAML (default {})')
    pub.add_argument('-r', '--rate', type=float, default=1.0, help='publishing rate [Hz] (default 1)')
    pub.add_argument('-1', '--once', action='store_true', help='publish once and exit')
    pub.add_argument('-t', '--times', type=int, metavar='N', help='publish N times and exit')
    pub.add_argument('-w', '--wait-matching-subscriptions', type=int, default=None, metavar='N',
                     help='wait for N matching subscriptions first (default 1 with --once/--times, else 0)')
    pub.add_argument('--qos-reliability', choices=['reliable', 'best_effort'], default='reliable')
    pub.add_argument('--qos-durability', choices=['volatile', 'transient_local'], default='volatile')
    pub.add_argument('--qos-depth', type=int, default=10)
    return parser


def main(argv=None, prog='topic'):
    args = build_parser(prog).parse_args(sys.argv[1:] if argv is None else argv)
    with exit_on_user_error(f'{prog} {args.verb}'):
        return {'echo': echo, 'list': list_topics, 'hz': hz, 'bw': bw, 'pub': pub}[args.verb](args)


def _formatter(args):
    """Message -> printed text, per the echo options."""
    from mvpose_nodes.io import msgdict

    def field_of(msg):
        return msg if not args.field else msgdict.get_message_field(msg, args.field)

    options = dict(truncate_length=args.truncate_length, no_arr=args.no_arr, no_str=args.no_str)

    def render(msg):
        value = field_of(msg)
        is_message = hasattr(value, 'get_fields_and_field_types')
        if args.csv:
            return msgdict.message_to_csv(value, **options) if is_message else str(value)
        if is_message:
            return msgdict.message_to_yaml(value, **options) + '---'
        plain = _plain(value)
        if isinstance(plain, (list, dict)):
            return yaml.safe_dump(plain, default_flow_style=False, allow_unicode=True, width=math.inf) + '---'
        return f'{plain}\n---'
    return render


def _plain(value):
    """A field value that is not a message (number, string, list, array) as plain Python data."""
    from mvpose_nodes.io import msgdict
    if hasattr(value, 'get_fields_and_field_types'):
        return msgdict.message_to_ordereddict(value)
    if isinstance(value, (list, tuple)) or hasattr(value, 'tolist'):
        return [_plain(v) for v in (value.tolist() if hasattr(value, 'tolist') else value)]
    return value.item() if hasattr(value, 'item') else value


def echo(args):
    if args.type:
        full_type_name(args.type)
        message_class(args.type)
    import rclpy
    from mvpose_nodes.io.msgdict import FieldError
    from mvpose_nodes.ros.helpers import StopSignal, destroy_or_exit, subscription_qos_for, wait_for_publishers

    render = _formatter(args)
    limit = 1 if args.once else args.count
    started = time.monotonic()
    with StopSignal() as stop:
        node = rclpy.create_node('mvpose_topic_echo')
        published_type = wait_for_publishers(node, args.topic, args.timeout or math.inf, stop)
        if published_type is None:
            if stop.stopped:
                return 130
            print(f'topic echo: no publisher on {args.topic} within {args.timeout} s', file=sys.stderr)
            return 1
        msg_class = message_class(args.type or published_type)
        received = []

        def show(msg):
            try:
                print(render(msg), flush=True)
            except FieldError as error:
                raise UserError(str(error)) from None
            received.append(1)

        node.create_subscription(msg_class, args.topic, show, subscription_qos_for(node, args.topic))
        while not stop.stopped and (limit is None or len(received) < limit):
            if args.timeout and not received and time.monotonic() - started > args.timeout:
                print(f'topic echo: no message on {args.topic} within {args.timeout} s', file=sys.stderr)
                return 1
            rclpy.spin_once(node, timeout_sec=0.1)
        return destroy_or_exit(node, 'topic echo', 0 if not stop.stopped else 130)


def list_topics(args):
    import rclpy
    from mvpose_nodes.ros.helpers import StopSignal, destroy_or_exit
    with StopSignal() as stop:
        node = rclpy.create_node('mvpose_topic_list')
        deadline = time.monotonic() + args.spin_time
        while time.monotonic() < deadline and not stop.stopped:
            rclpy.spin_once(node, timeout_sec=0.05)
        for name, types in sorted(node.get_topic_names_and_types()):
            print(f"{name} [{', '.join(types)}]" if args.show_types else name)
        return destroy_or_exit(node, 'topic list', 0)


def rate_statistics(stamps, window):
    """(rate [Hz], min, max, std dev [s] of the intervals, intervals) over the last `window` intervals."""
    last = stamps[-window - 1:]
    intervals = [b - a for a, b in zip(last, last[1:])]
    if not intervals:
        return None
    mean = sum(intervals) / len(intervals)
    std = math.sqrt(sum((i - mean) ** 2 for i in intervals) / len(intervals))
    return 1.0 / mean if mean > 0 else math.inf, min(intervals), max(intervals), std, len(intervals)


def human_bytes(count):
    """A byte count as ros2 topic bw prints it: B, KB, MB (powers of 1000)."""
    for unit, size in (('MB', 1e6), ('KB', 1e3)):
        if count >= size:
            return f'{count / size:.2f} {unit}'
    return f'{count:.0f} B'


def hz(args):
    def report(received):
        stats = rate_statistics([at for at, _ in received], args.window)
        return (f'average rate: {stats[0]:.3f}\n\tmin: {stats[1]:.3f}s max: {stats[2]:.3f}s std dev: {stats[3]:.5f}s '
                f'window: {stats[4]}' if stats else 'no new messages')
    return measure(args, 'mvpose_topic_hz', report, args.window + 1)


def bw(args):
    def report(received):
        seconds = received[-1][0] - received[0][0] if len(received) > 1 else 0.0
        if seconds <= 0:
            return 'no new messages'
        sizes = [size for _, size in received]
        return (f'{human_bytes(sum(sizes[1:]) / seconds)}/s from {len(sizes)} messages\n\tMessage size mean: '
                f'{human_bytes(sum(sizes) / len(sizes))} min: {human_bytes(min(sizes))} max: {human_bytes(max(sizes))}')
    return measure(args, 'mvpose_topic_bw', report, args.window)


def measure(args, node_name, report, window):
    """Subscribe to args.topic (serialised messages) once it has a publisher and print report([(arrival
    time [s], size [bytes]), ...]) of the last `window` messages every second, until args.duration or Ctrl-C."""
    import rclpy
    from mvpose_nodes.ros.helpers import StopSignal, destroy_or_exit, subscription_qos_for, wait_for_publishers
    with StopSignal() as stop:
        node = rclpy.create_node(node_name)
        published_type = wait_for_publishers(node, args.topic, args.duration or math.inf, stop)
        if published_type is None:
            return 130 if stop.stopped else 1
        received = []
        node.create_subscription(message_class(published_type), args.topic,
                                 lambda data: received.append((time.monotonic(), len(data))),
                                 subscription_qos_for(node, args.topic), raw=True)
        started = next_report = time.monotonic()
        while not stop.stopped and not (args.duration and time.monotonic() - started > args.duration):
            rclpy.spin_once(node, timeout_sec=0.05)
            if time.monotonic() >= next_report + 1.0:
                next_report = time.monotonic()
                print(report(received), flush=True)
                del received[:-window]
        return destroy_or_exit(node, f'topic {args.verb}', 0)


def pub(args):
    from mvpose_nodes.io.msgdict import FieldError, set_message_fields
    msg_class = message_class(args.type)
    try:
        values = yaml.safe_load(args.values)
    except yaml.YAMLError as error:
        raise UserError(f'values are not YAML: {str(error).splitlines()[0]}') from None
    if values is None:
        values = {}
    if not isinstance(values, dict):
        raise UserError(f'values must be a YAML mapping of field names, got {args.values!r}')
    try:
        msg = set_message_fields(msg_class(), values)
    except FieldError as error:
        raise UserError(str(error)) from None
    times = 1 if args.once else args.times
    if args.rate <= 0:
        raise UserError(f'--rate must be > 0 (got {args.rate})')
    wait_for = args.wait_matching_subscriptions
    if wait_for is None:
        wait_for = 1 if times else 0

    import rclpy
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from mvpose_nodes.ros.helpers import StopSignal, destroy_or_exit, wait_for_acknowledgements
    qos = QoSProfile(depth=args.qos_depth, reliability=ReliabilityPolicy.get_from_short_key(args.qos_reliability),
                     durability=DurabilityPolicy.get_from_short_key(args.qos_durability))
    with StopSignal() as stop:
        node = rclpy.create_node('mvpose_topic_pub')
        publisher = node.create_publisher(msg_class, args.topic, qos)
        while publisher.get_subscription_count() < wait_for and not stop.stopped:
            rclpy.spin_once(node, timeout_sec=0.05)
        count = 0
        while not stop.stopped and (times is None or count < times):
            publisher.publish(msg)
            count += 1
            print(f'publishing #{count}: {args.type}', flush=True)
            if times is None or count < times:
                stop.wait(1.0 / args.rate)
        wait_for_acknowledgements([publisher], timeout_sec=2.0)
        return destroy_or_exit(node, 'topic pub', 0)


if __name__ == '__main__':
    sys.exit(main())
