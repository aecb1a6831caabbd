"""`doctor`: what a DDS graph spread over hosts needs checked, like `ros2 doctor --report` and `ros2 topic bw`:
the DDS settings this process runs with, this host's addresses, every node of the graph grouped by the host
it runs on, and every topic with its publishers, subscribers and bandwidth.

Hosts: Fast DDS puts a host id in each participant's GUID prefix (bytes 2-3, from the host's addresses), so
the endpoints rclpy lists say which nodes share a host; an mvpose node also names its host and addresses in
its /diagnostics status (hardware_id), which gives the host id a name."""
import collections
import os
import sys
import time
from pathlib import Path

from mvpose_nodes.tools.cli import ArgumentParser, UserError, exit_on_user_error
from mvpose_nodes.io.interfaces import message_class
from mvpose_nodes.tools.topic import human_bytes

DISCOVERY_TIME = 2.0   # [s]: a few of the 0.25 s announcements of config/fastdds.xml, and a /diagnostics period
BANDWIDTH_TIME = 3.0   # [s]
SETTINGS = (
    ('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp (the default)'),
    ('ROS_DOMAIN_ID', '0'),
    ('ROS_AUTOMATIC_DISCOVERY_RANGE', 'SUBNET'),
    ('ROS_STATIC_PEERS', 'none'),
    ('FASTRTPS_DEFAULT_PROFILES_FILE', "none: Fast DDS's defaults"),
    ('ROS_SECURITY_ENABLE', 'false'),
)
# Strings that a Fast DDS built with DDS-Security (-DSECURITY=ON) holds for its builtin plugins.
SECURITY_PLUGIN_NAMES = (b'dds.sec.auth.builtin.PKI-DH', b'dds.sec.crypto.builtin.AES-GCM-GMAC')


def build_parser(prog):
    parser = ArgumentParser(prog=prog, description='Print the DDS settings in force, this host\'s addresses, the '
                            'nodes of the graph by host, and every topic with its publishers, subscribers and '
                            'bandwidth, like ros2 doctor --report and ros2 topic bw.')
    parser.add_argument('--spin-time', type=float, default=DISCOVERY_TIME, metavar='S',
                        help=f'time to discover the graph (default {DISCOVERY_TIME:g})')
    parser.add_argument('--bandwidth-time', type=float, default=BANDWIDTH_TIME, metavar='S',
                        help=f'time to measure each topic\'s bandwidth, all at once (default {BANDWIDTH_TIME:g}; '
                             '0: do not subscribe to anything)')
    return parser


def main(argv=None, prog='doctor'):
    args = build_parser(prog).parse_args(sys.argv[1:] if argv is None else argv)
    with exit_on_user_error(prog):
        return report(args)


def fast_dds_library():
    """The Fast DDS shared library rmw_fastrtps_cpp loaded into this process, or None."""
    for line in Path('/proc/self/maps').read_text().splitlines():
        path = line.split()[-1]
        if '/libfastrtps.so' in path or '/libfastdds.so' in path:
            return Path(path)
    return None


def security_support(library):
    """Whether the Fast DDS library was built with DDS-Security, as a line for the report."""
    if library is None:
        return 'unknown (no Fast DDS library loaded)'
    data = library.read_bytes()
    if all(name in data for name in SECURITY_PLUGIN_NAMES):
        return f'built in ({library.name} has the PKI-DH and AES-GCM-GMAC plugins)'
    return (f'NOT built in: {library.name} has no authentication or encryption plugin; isolate the capture '
            'network instead (README, "Multi-host capture")')


def host_of(gid):
    """The Fast DDS host id (hex) in an endpoint's GUID prefix."""
    return bytes(gid)[2:4].hex()


def report(args):
    if min(args.spin_time, args.bandwidth_time) < 0:
        raise UserError('--spin-time and --bandwidth-time must not be negative')
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from mvpose_nodes.ros.diagnostics import DIAGNOSTICS_TOPIC, host_addresses
    from mvpose_nodes.ros.helpers import StopSignal, destroy_or_exit
    with StopSignal() as stop:
        node = rclpy.create_node('mvpose_doctor')
        hardware = {}   # fully qualified node name -> its DiagnosticStatus.hardware_id
        node.create_subscription(DiagnosticArray, DIAGNOSTICS_TOPIC,
                                 lambda array: hardware.update((s.name, s.hardware_id) for s in array.status), 50)
        spin(node, args.spin_time, stop)
        print('DDS settings in force (this process)')
        for name, unset in SETTINGS:
            print(f'  {name:32s}{os.environ.get(name) or f"unset: {unset}"}')
        print(f'  {"DDS-Security":32s}{security_support(fast_dds_library())}')
        this_host = next(host_of(p.endpoint_gid) for p in node.get_publishers_info_by_topic('/rosout')
                         if p.node_name == node.get_name())
        addresses = ', '.join(f'{name} {address}' for name, address in host_addresses().items())
        print(f'\nThis host: DDS host id {this_host}, {addresses}')

        topics, endpoints, hosts = graph_of_others(node)
        print(f'\nNodes ({sum(map(len, hosts.values()))}) by host')
        for host, names in sorted(hosts.items()):
            named = sorted({hardware[n] for n in names if n in hardware})
            print(f'  host {host}{" (this host)" if host == this_host else ""}'
                  f'{": " + "; ".join(named) if named else ""}')
            for name in sorted(names):
                print(f'    {name}')

        sizes = measure_sizes(node, topics, args.bandwidth_time, stop)
        print(f'\nTopics ({len(topics)}): publishers and subscribers (their hosts)'
              + (f', and over {args.bandwidth_time:g} s the rate and bandwidth this host received'
                 if args.bandwidth_time else ''))
        for topic, type_name in sorted(topics.items()):
            where = ' / '.join(f'{len(ends)} {kind} ({", ".join(sorted({host_of(e.endpoint_gid) for e in ends}))})'
                               if ends else f'0 {kind}' for ends, kind in zip(endpoints[topic], ('pub', 'sub')))
            measured = (f'{len(sizes[topic]) / args.bandwidth_time:6.1f} Hz '
                        f'{human_bytes(sum(sizes[topic]) / args.bandwidth_time):>9s}/s' if args.bandwidth_time else '')
            print(f'  {topic:36s} {type_name:38s} {where:34s} {measured}')
        return destroy_or_exit(node, 'doctor', 130 if stop.stopped else 0)


def graph_of_others(node):
    """What `node` sees of the graph but itself: {topic: type}, {topic: (publishers, subscriptions)} (rclpy
    TopicEndpointInfo lists) and {host id: fully qualified node names}."""
    def others(infos):
        return [info for info in infos if (info.node_namespace, info.node_name) != ('/', node.get_name())]
    topics = {name: types[0] for name, types in node.get_topic_names_and_types() if types}
    endpoints = {topic: (others(node.get_publishers_info_by_topic(topic)),
                         others(node.get_subscriptions_info_by_topic(topic))) for topic in topics}
    hosts = collections.defaultdict(set)
    for publishers, subscriptions in endpoints.values():
        for info in (*publishers, *subscriptions):
            hosts[host_of(info.endpoint_gid)].add(f'{info.node_namespace.rstrip("/")}/{info.node_name}')
    return topics, endpoints, hosts


def measure_sizes(node, topics, seconds, stop):
    """{topic: [serialised size [bytes] of each message received]} over `seconds`, subscribed to every one of
    `topics` ({topic: type}) with a QoS its publishers match (nothing subscribed when seconds is 0)."""
    from mvpose_nodes.ros.helpers import subscription_qos_for
    sizes = {topic: [] for topic in topics}
    if seconds:
        for topic, type_name in topics.items():
            node.create_subscription(message_class(type_name), topic, lambda data, t=topic: sizes[t].append(len(data)),
                                     subscription_qos_for(node, topic), raw=True)
        spin(node, seconds, stop)
    return sizes


def spin(node, seconds, stop):
    import rclpy
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and not stop.stopped:
        rclpy.spin_once(node, timeout_sec=0.05)


if __name__ == '__main__':
    sys.exit(main())
