"""`bag record | play | info | reindex`: rosbag2-compatible MCAP bags without rosbag2.

The bags are ordinary rosbag2 bags (see bagfile.py): `ros2 bag info/play` of a
system ROS 2 install and the `rosbags` library read what `bag record` writes,
and `bag play` plays what `ros2 bag record -s mcap` wrote.
"""
import datetime
import sys
import time

from mvpose_nodes.io.bagfile import METADATA_FILE, BagReader, BagWriter, directory_size, reindex
from mvpose_nodes.tools.cli import ArgumentParser, UserError, exit_on_user_error
from mvpose_nodes.io.interfaces import MessageTypeError, message_class

# Topics that carry calibration: latched on playback so that nodes started late still get them.
LATCHED_TOPIC_SUFFIXES = ('/camera_info', '/camera_pose')
POLLING_INTERVAL_MS = 100  # how often `record` looks for new topics, as ros2 bag record's --polling-interval
DRAIN_TIME = 0.5  # [s] how long `record` keeps taking messages after Ctrl-C
FLUSH_PERIOD = 1.0  # [s] `record` puts what it received on the disk at least this often (BagWriter.flush)
# `play` starts once discovery has been quiet this long [s]: four DDS participant announcement periods of the
# Fast DDS profile ./mvpose runs with (config/fastdds.xml: 0.25 s). Measured here, a running subscriber was
# matched 0.04-0.38 s after the player's publisher was made (20 trials), but on the test suite's loaded 2
# cores 0.6 s of quiet once started the play before it. A process started without that profile announces
# itself every 3 s (Fast DDS's default) and may be found later: use --wait-for-subscribers.
DISCOVERY_SETTLE = 1.0
DISCOVERY_LIMIT = 5.0  # [s] the longest `play` waits for discovery to settle
# [s] the longest `play` waits for its subscribers to acknowledge a latched message (calibration) before it
# plays on: a subscriber that had not yet matched the player's publisher on its side when the message went
# out gets it at the publisher's next heartbeat, every 3 s in Fast DDS, and the images after it must not
# arrive before it (measured: calibration 2-3 s behind the images made 2 of 10 demo runs fail).
LATCHED_ACK_TIMEOUT = 4.0


def build_parser(prog):
    parser = ArgumentParser(prog=prog, description=__doc__.splitlines()[0])
    verbs = parser.add_subparsers(dest='verb', metavar='VERB', required=True)

    record = verbs.add_parser('record', help='record live topics into a new bag directory',
                              description='Record live topics into a rosbag2 directory (metadata.yaml + .mcap). '
                                          'Stops on Ctrl-C, after writing everything already received. What it '
                                          f'received is on the disk every {FLUSH_PERIOD:g} s (complete MCAP chunks and '
                                          'a current metadata.yaml), so a recorder that is killed loses at most '
                                          'that much: `bag info` and `bag play` read the rest, `bag reindex` '
                                          'finishes the file.')
    chosen = record.add_mutually_exclusive_group(required=True)
    chosen.add_argument('--topics', nargs='+', metavar='TOPIC', help='topics to record')
    chosen.add_argument('-a', '--all', action='store_true', help='record every topic (new ones too)')
    record.add_argument('-o', '--output', help='bag directory to create (default: rosbag2_YYYY_MM_DD-hh_mm_ss)')
    record.add_argument('-p', '--polling-interval', type=int, default=POLLING_INTERVAL_MS, metavar='MS',
                        help=f'how often to look for new topics to record [ms] (default {POLLING_INTERVAL_MS})')

    play = verbs.add_parser('play', help='replay a bag at its recorded timing',
                            description='Publish the stored messages of a bag directory or bare .mcap file '
                                        'at their recorded timing. Calibration topics (*/camera_info, '
                                        '*/camera_pose) and topics recorded as transient-local are published '
                                        'transient-local, so subscribers that start late still get them.')
    play.add_argument('bag', help='bag directory or .mcap file')
    play.add_argument('-r', '--rate', type=float, default=1.0, help='playback speed factor (default 1.0)')
    play.add_argument('-l', '--loop', action='store_true', help='start again at the end until Ctrl-C')
    play.add_argument('--start-offset', type=float, default=0.0, metavar='S',
                      help='skip the first S seconds of the bag')
    play.add_argument('--topics', nargs='+', metavar='TOPIC', help='play only these topics')
    play.add_argument('-d', '--delay', type=float, default=0.0, metavar='S',
                      help='wait S seconds after creating the publishers before the first message '
                           '(gives subscribers time to discover them)')
    play.add_argument('--settle', type=float, default=DISCOVERY_SETTLE, metavar='S',
                      help='before the first message, wait until the subscribers already running have matched the '
                           'new publishers: until discovery has shown no change for S seconds (default '
                           f'{DISCOVERY_SETTLE:g}; at most {DISCOVERY_LIMIT:g} s), so that a graph started before the '
                           'player loses nothing; 0 starts at once, as ros2 bag play does')
    play.add_argument('--wait-for-subscribers', type=float, nargs='?', const=30.0, default=0.0, metavar='S',
                      help='before the first message, wait up to S seconds (default 30 when given) until every '
                           'played topic (and /clock with --clock) has a matched subscriber, then for discovery to '
                           'settle (--settle), so that a graph started after the player loses nothing (then --delay '
                           'still applies)')
    play.add_argument('--clock', type=float, nargs='?', const=40.0, default=0.0, metavar='HZ',
                      help='also publish the bag time on /clock at HZ (default 40 when given)')

    info = verbs.add_parser('info', help='summarise a bag', description='Print what a bag holds, like ros2 bag info.')
    info.add_argument('bag', help='bag directory or .mcap file')

    reindex = verbs.add_parser('reindex', help='finish the file of a bag whose recorder was killed',
                               description='Rewrite the .mcap file of a bag directory complete, with its summary '
                                           'and indexes, from its messages (those of its complete chunks when its '
                                           'recorder was killed before it closed the file), and metadata.yaml from '
                                           'it, as `ros2 bag reindex` does. Bags of one .mcap file, as `bag record` '
                                           'writes them.')
    reindex.add_argument('bag', help='bag directory')
    return parser


def main(argv=None, prog='bag'):
    args = build_parser(prog).parse_args(sys.argv[1:] if argv is None else argv)
    with exit_on_user_error(f'{prog} {args.verb}'):
        if args.verb == 'info':
            print(describe(BagReader(args.bag), args.bag))
        elif args.verb == 'play':
            play(args)
        elif args.verb == 'reindex':
            print(reindexed(args.bag))
        else:
            record(args)
    return 0


def format_time(ns):
    stamp = datetime.datetime.fromtimestamp(ns / 1e9, tz=datetime.timezone.utc)
    return f'{stamp:%b %d %Y %H:%M:%S.%f}'[:-3] + f' ({ns // 10**9}.{ns % 10**9:09d})'


def reindexed(path):
    """`bag reindex`: rewrite the bag and say what was recovered and cut."""
    recovery = reindex(path)
    bag = BagReader(path)
    done = f'reindexed {path}: {bag.message_count} messages on {len(bag.topics)} topics'
    if recovery is None:
        return f'{done} (the file was finished)'
    cut = (f'{recovery.cut_bytes} bytes after its last complete record (an unfinished chunk) were cut'
           if recovery.cut_bytes else 'it ended after a complete record')
    return f'{done}, recovered from an unfinished file; {cut}'


def describe(bag, path):
    """The text of `bag info`, laid out like `ros2 bag info`."""
    size = directory_size(path)
    lines = [
        f"Files:             {', '.join(str(f.name) for f in bag.files)}",
        f'Bag size:          {size / 2**20:.1f} MiB',
        'Storage id:        mcap',
        f"ROS Distro:        {bag.metadata.get('ros_distro', 'unknown')}",
        f'Duration:          {bag.duration_ns / 1e9:.9f}s',
        f'Start:             {format_time(bag.start_ns)}',
        f'End:               {format_time(bag.end_ns)}',
        f'Messages:          {bag.message_count}',
    ]
    for mcap_path, recovery in bag.unfinished.items():
        lines.append(f'Unfinished:        {mcap_path.name}: its recorder did not close it; {recovery.messages} '
                     f'messages read from its complete chunks, {recovery.cut_bytes} bytes after them cut '
                     f'(`bag reindex` finishes it)')
    disagreements = bag.metadata_disagreements()
    if disagreements:
        lines.append(f"Warning:           {METADATA_FILE} disagrees with the MCAP, whose figures these are "
                     f"(`bag reindex` rewrites it): {'; '.join(disagreements)}")
    lines.append('Topic information:')
    width = max((len(t) for t in bag.topics), default=0)
    for topic in sorted(bag.topics.values(), key=lambda t: t.name):
        lines.append(f'  Topic: {topic.name:<{width}} | Type: {topic.type} | Count: {topic.message_count} | '
                     f'Serialization Format: {topic.serialization_format}')
    return '\n'.join(lines)


def play(args):
    if args.rate <= 0:
        raise UserError(f'--rate must be > 0 (got {args.rate})')
    if min(args.start_offset, args.delay, args.clock, args.wait_for_subscribers, args.settle) < 0:
        raise UserError('--start-offset, --delay, --clock, --settle and --wait-for-subscribers must not be negative')
    bag = BagReader(args.bag)
    disagreements = bag.metadata_disagreements()
    if disagreements:
        print(f"[play] warning: {METADATA_FILE} of '{args.bag}' disagrees with its MCAP, which is played "
              f"(`bag reindex` rewrites it): {'; '.join(disagreements)}", file=sys.stderr)
    topics = list(bag.topics) if not args.topics else args.topics
    missing = [t for t in topics if t not in bag.topics]
    if missing:
        raise UserError(f"topic(s) {', '.join(missing)} not in bag '{args.bag}' (it has: {', '.join(sorted(bag.topics))})")
    classes = {t: message_class(bag.topics[t].type) for t in topics}

    import rclpy  # after the checks above, so that bad input fails fast with one line
    from rosgraph_msgs.msg import Clock
    from rclpy.qos import DurabilityPolicy
    from mvpose_nodes.ros.helpers import StopSignal, qos_from_dict, wait_for_acknowledgements

    with StopSignal() as stop:
        node = rclpy.create_node('mvpose_bag_player')
        publishers = {}
        for topic in topics:
            info = bag.topics[topic]
            qos = qos_from_dict(info.offered_qos_profiles[0] if info.offered_qos_profiles else None)
            if topic.endswith(LATCHED_TOPIC_SUFFIXES):
                qos.durability = DurabilityPolicy.TRANSIENT_LOCAL
            publishers[topic] = node.create_publisher(classes[topic], topic, qos)
        clock = node.create_publisher(Clock, '/clock', 10) if args.clock else None
        played_publishers = {**publishers, **({'/clock': clock} if clock else {})}
        wait_for_discovery(node, played_publishers, args.settle, stop)
        if args.wait_for_subscribers:
            wait_for_subscribers(node, played_publishers, args.wait_for_subscribers, stop)
            # The nodes of a graph started with the player come up one after another: the later ones too.
            wait_for_discovery(node, played_publishers, args.settle, stop)
        stop.wait(args.delay)
        begin_ns = bag.start_ns + int(args.start_offset * 1e9)
        audience = Audience(publishers, {topic for topic, publisher in publishers.items()
                                         if publisher.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL})
        print(f'[play] playing {len(topics)} topics of {args.bag} at rate {args.rate:g}', file=sys.stderr, flush=True)
        try:
            while not stop.stopped:
                play_once(bag, topics, begin_ns, audience, clock, args, stop)
                if not args.loop:
                    break
            wait_for_acknowledgements(publishers.values(), timeout_sec=2.0)
        finally:
            node.destroy_node()
    print(f'[play] published {audience.published} messages on {len(topics)} topics', file=sys.stderr)
    if audience.unheard:
        print(f'[play] warning: {audience.describe_unheard()} were published before any subscriber had matched '
              'their topic, so nobody received them (start the subscribers first, or play with '
              '--wait-for-subscribers)', file=sys.stderr)
    if audience.unacknowledged:
        print(f"[play] warning: latched messages on {', '.join(sorted(audience.unacknowledged))} were not "
              f'acknowledged by every subscriber within {LATCHED_ACK_TIMEOUT:g} s (played on regardless)',
              file=sys.stderr)


class Audience:
    """The player's publishers, and which messages had nobody to hear them: per topic, those published
    while no subscriber had matched, before the first that had one (a topic nobody ever subscribes is
    not counted: playing it is not a loss). A message on a `latched` topic (transient-local: calibration)
    is played on from only once its subscribers have acknowledged it (LATCHED_ACK_TIMEOUT)."""

    def __init__(self, publishers, latched=()):
        from rclpy.duration import Duration
        self.publishers, self.latched = publishers, set(latched)
        self.ack_timeout = Duration(seconds=LATCHED_ACK_TIMEOUT)
        self.published = 0
        self.before_first_subscriber = dict.fromkeys(publishers, 0)
        self.unheard = {}   # topic -> messages published before its first subscriber matched
        self.unacknowledged = set()   # latched topics a subscriber did not acknowledge in time

    def publish(self, topic, data):
        publisher = self.publishers[topic]
        publisher.publish(data)
        self.published += 1
        if topic in self.latched and not publisher.wait_for_all_acked(self.ack_timeout):
            self.unacknowledged.add(topic)
        if topic in self.before_first_subscriber:
            if publisher.get_subscription_count():
                count = self.before_first_subscriber.pop(topic)
                if count:
                    self.unheard[topic] = count
            else:
                self.before_first_subscriber[topic] += 1

    def describe_unheard(self):
        """'4 messages (3 on /a, 1 on /b)'"""
        parts = ', '.join(f'{count} on {topic}' for topic, count in sorted(self.unheard.items()))
        return f'{sum(self.unheard.values())} messages ({parts})'


def wait_for_discovery(node, publishers, settle, stop):
    """Until discovery is quiet: what the graph shows of the played topics' subscribers, and what the
    publishers have matched, unchanged for `settle` seconds (at most DISCOVERY_LIMIT). DDS gives no event
    for "every participant running has been found": a new process finds the others as they announce
    themselves, so the wait is for that to stop changing."""
    if not settle:
        return

    def snapshot():
        return (tuple(node.count_subscribers(topic) for topic in publishers),
                tuple(publisher.get_subscription_count() for publisher in publishers.values()),
                len(node.get_node_names_and_namespaces()))

    started = changed = time.monotonic()
    seen = snapshot()
    while not stop.stopped and time.monotonic() - changed < settle and time.monotonic() - started < DISCOVERY_LIMIT:
        stop.wait(0.02)
        now = snapshot()
        if now != seen:
            seen, changed = now, time.monotonic()


def wait_for_subscribers(node, publishers, timeout, stop):
    """Until every topic has a matched subscriber, and as many as the graph knows of (a topic with two
    subscribers, e.g. camera_info read by a feature node and the fitter, waits for both)."""
    deadline = time.monotonic() + timeout
    unmatched = list(publishers)
    while unmatched and time.monotonic() < deadline and not stop.stopped:
        stop.wait(0.05)
        unmatched = [topic for topic, publisher in publishers.items()
                     if publisher.get_subscription_count() < max(1, node.count_subscribers(topic))]
    if unmatched:
        print(f"[play] no subscriber after {timeout:g} s on: {', '.join(unmatched)}; playing anyway", file=sys.stderr)


def play_once(bag, topics, begin_ns, audience, clock, args, stop):
    """Publish the bag once from `begin_ns` at `args.rate` through `audience` (an Audience)."""
    from builtin_interfaces.msg import Time
    from rosgraph_msgs.msg import Clock
    wall_start = time.monotonic()
    clock_period = 1.0 / args.clock if clock else None
    next_clock = wall_start
    count = 0
    total = max(1, bag.end_ns - begin_ns)
    show_progress = sys.stderr.isatty()
    for topic_info, log_time_ns, data in bag.messages(topics=topics, start_ns=begin_ns):
        due = wall_start + (log_time_ns - begin_ns) / 1e9 / args.rate
        while not stop.stopped:
            now = time.monotonic()
            if clock and now >= next_clock:
                bag_ns = begin_ns + int((now - wall_start) * args.rate * 1e9)
                bag_ns = min(bag_ns, log_time_ns)
                clock.publish(Clock(clock=Time(sec=bag_ns // 10**9, nanosec=bag_ns % 10**9)))
                next_clock += clock_period
            if now >= due:
                break
            stop.wait((min(due, next_clock) if clock else due) - now)
        if stop.stopped:
            break
        audience.publish(topic_info.name, data)
        count += 1
        if show_progress and count % 10 == 0:
            print(f'\r[play] {(log_time_ns - begin_ns) / 1e9:7.2f} s  {100 * (log_time_ns - begin_ns) / total:5.1f} %'
                  f'  {count} messages', end='', file=sys.stderr, flush=True)
    if show_progress:
        print(file=sys.stderr)


def record(args):
    import rclpy
    from mvpose_nodes.ros.helpers import StopSignal, qos_to_dict, subscription_qos_for, topic_types

    if args.polling_interval < 1:
        raise UserError(f'--polling-interval must be at least 1 ms (got {args.polling_interval})')
    output = args.output or datetime.datetime.now().strftime('rosbag2_%Y_%m_%d-%H_%M_%S')
    wanted = None if args.all else set(args.topics)
    with StopSignal() as stop, BagWriter(output) as bag:
        node = rclpy.create_node('mvpose_bag_recorder')
        subscriptions = {}
        unknown_types = set()
        received = {}   # topic -> [messages received, highest publication sequence number]

        def write(topic):
            def callback(data, info):
                bag.write(topic, data, node.get_clock().now().nanoseconds)
                counts = received.setdefault(topic, [0, 0])
                counts[0] += 1
                counts[1] = max(counts[1], info.get('publication_sequence_number') or 0)
            return callback

        def discover():
            for topic, type_name in topic_types(node).items():
                if topic in subscriptions or (wanted is not None and topic not in wanted) or topic in unknown_types:
                    continue
                try:
                    msg_class = message_class(type_name)
                except MessageTypeError as error:
                    unknown_types.add(topic)
                    print(f'[record] skipping {topic}: {error}', file=sys.stderr)
                    continue
                offered = [qos_to_dict(p.qos_profile) for p in node.get_publishers_info_by_topic(topic)]
                bag.add_topic(topic, type_name, offered)
                subscriptions[topic] = node.create_subscription(
                    msg_class, topic, write(topic), subscription_qos_for(node, topic, depth=100), raw=True)
                print(f'[record] recording {topic} ({type_name})', file=sys.stderr, flush=True)

        node.create_timer(args.polling_interval / 1000, discover)
        node.create_timer(FLUSH_PERIOD, bag.flush)
        discover()
        print(f'[record] writing {output}; Ctrl-C to stop', file=sys.stderr, flush=True)
        while not stop.stopped:
            rclpy.spin_once(node, timeout_sec=0.1)
        # Take what the middleware already holds before closing: nothing received is lost.
        drain_until = time.monotonic() + DRAIN_TIME
        while time.monotonic() < drain_until:
            rclpy.spin_once(node, timeout_sec=0.05)
        node.destroy_node()
        counts = bag.metadata()['rosbag2_bagfile_information']['message_count']
    print(f'[record] wrote {counts} messages on {len(subscriptions)} topics to {output}', file=sys.stderr)
    missed = missed_messages(received)
    if missed:
        print(f'[record] warning: {sum(missed.values())} messages may have been missed before the subscription '
              f'matched or on the way ({", ".join(f"{n} on {topic}" for topic, n in missed.items())}): their '
              'publishers numbered more messages than came', file=sys.stderr)


def missed_messages(received):
    """{topic: messages its publisher sent that never came}, from {topic: [messages received, highest
    publication sequence number]}: DDS numbers a publisher's messages from 1, so the highest number less
    the count received is what was sent before the subscription matched, or lost (exact with one
    publisher per topic; with several, numbers overlap and it counts too few, never too many)."""
    return {topic: highest - count for topic, (count, highest) in sorted(received.items()) if highest > count}


if __name__ == '__main__':
    sys.exit(main())
