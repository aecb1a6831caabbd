"""Hosts for the multi-host tests (issue 16): Linux network namespaces, one per "host", joined by veth
pairs, and `./mvpose` processes started inside them. Nothing of it touches the test machine's own network:
the switch or router is a namespace too, and everything is deleted when the network is closed.

Two layouts:
- switched: every host on one subnet (10.200.0.0/24) through a bridge, as a studio's switch; DDS finds the
  others by multicast (ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET);
- routed: every host on a subnet of its own (10.200.N.0/24) behind a router that forwards unicast and no
  multicast, as separate networks are; DDS finds the others only through ROS_STATIC_PEERS.

Needs root (CAP_NET_ADMIN) and iproute2's `ip`; `unavailable()` says why not where they are missing.
drop_randomly() needs `iptables` too."""
import json
import os
import shutil
import signal
import subprocess
import time

from common import Background

SUBNET = '10.200'


def unavailable():
    """Why network namespaces cannot be made here, or None when they can."""
    if shutil.which('ip') is None:
        return "iproute2's `ip` is not installed"
    if os.geteuid() != 0:
        return 'network namespaces need root (CAP_NET_ADMIN)'
    probe = f'mvprobe{os.getpid()}'
    made = subprocess.run(['ip', 'netns', 'add', probe], capture_output=True, text=True)
    if made.returncode != 0:
        return f'`ip netns add` failed: {made.stderr.strip()}'
    subprocess.run(['ip', 'netns', 'delete', probe], check=True)
    return None


def ip(*args, namespace=None):
    """Run `ip [-n NAMESPACE] ARGS`; a failure raises with its message."""
    command = ['ip', *(['-n', namespace] if namespace else []), *map(str, args)]
    done = subprocess.run(command, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f'{" ".join(command)}: {done.stderr.strip()}')
    return done.stdout


class VirtualNetwork:
    """`hosts` (names) in namespaces of their own, each with one interface `eth0` to the switch (switched)
    or the router (routed), except those `unplugged`; a context manager that removes it all on exit,
    processes included. link() joins two hosts directly by a second network."""

    def __init__(self, hosts, routed=False, unplugged=()):
        self.hosts, self.routed, self.unplugged = list(hosts), routed, set(unplugged)
        tag = f'mv{os.getpid() % 100000}'
        self.namespaces = {host: f'{tag}{host}' for host in self.hosts}
        self.hub = f'{tag}{"router" if routed else "switch"}'
        self.addresses = {host: (f'{SUBNET}.{i + 1}.2' if routed else f'{SUBNET}.0.{i + 1}')
                          for i, host in enumerate(self.hosts) if host not in self.unplugged}
        self.processes = []

    def __enter__(self):
        try:
            self._build()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc):
        self.close()

    def _build(self):
        ip('netns', 'add', self.hub)
        ip('link', 'set', 'lo', 'up', namespace=self.hub)
        if self.routed:
            self._sysctl(self.hub, 'net.ipv4.ip_forward', 1)
        else:
            ip('link', 'add', 'br0', 'type', 'bridge', namespace=self.hub)
            ip('link', 'set', 'br0', 'up', namespace=self.hub)
        for i, host in enumerate(self.hosts):
            namespace, port = self.namespaces[host], f'port{i + 1}'
            ip('netns', 'add', namespace)
            self._sysctl(namespace, 'net.ipv6.conf.all.disable_ipv6', 1)   # IPv4 only, as DDS uses here
            ip('link', 'set', 'lo', 'up', namespace=namespace)
            if host in self.unplugged:
                continue
            ip('link', 'add', port, 'type', 'veth', 'peer', 'name', 'eth0', 'netns', namespace, namespace=self.hub)
            if self.routed:
                ip('addr', 'add', f'{SUBNET}.{i + 1}.1/24', 'dev', port, namespace=self.hub)
            else:
                ip('link', 'set', port, 'master', 'br0', namespace=self.hub)
            ip('link', 'set', port, 'up', namespace=self.hub)
            ip('addr', 'add', f'{self.addresses[host]}/24', 'dev', 'eth0', namespace=namespace)
            ip('link', 'set', 'eth0', 'up', namespace=namespace)
            if self.routed:
                ip('route', 'add', 'default', 'via', f'{SUBNET}.{i + 1}.1', namespace=namespace)

    def link(self, first, second):
        """A second network: `first` and `second` joined directly (interface eth1 each) on 10.201.0.0/24,
        `first` at .1 and `second` at .2."""
        ip('link', 'add', 'eth1', 'type', 'veth', 'peer', 'name', 'eth1', 'netns', self.namespaces[second],
           namespace=self.namespaces[first])
        for host, address in ((first, '10.201.0.1'), (second, '10.201.0.2')):
            ip('addr', 'add', f'{address}/24', 'dev', 'eth1', namespace=self.namespaces[host])
            ip('link', 'set', 'eth1', 'up', namespace=self.namespaces[host])

    @staticmethod
    def _sysctl(namespace, key, value):
        subprocess.run(['ip', 'netns', 'exec', namespace, 'sysctl', '-q', '-w', f'{key}={value}'], check=True)

    def environment(self, host):
        """The discovery settings of a process on `host`: SUBNET when switched; LOCALHOST and the other
        hosts as ROS_STATIC_PEERS when routed (multicast does not cross the router)."""
        if not self.routed:
            return {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET'}
        peers = ';'.join(address for other, address in self.addresses.items() if other != host)
        return {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST', 'ROS_STATIC_PEERS': peers}

    def start(self, host, *args, environment=None):
        """`./mvpose ARGS` on `host` in the background (a common.Background), with its discovery settings
        and `environment` on top."""
        process = Background(*args, prefix=('ip', 'netns', 'exec', self.namespaces[host]),
                             environment={**self.environment(host), **(environment or {})})
        self.processes.append(process)
        return process

    def set_link(self, host, up):
        """Take `host`'s link down (as a pulled cable) or bring it up again."""
        ip('link', 'set', 'eth0', 'up' if up else 'down', namespace=self.namespaces[host])

    def cap_bandwidth(self, host, megabits_per_second):
        """Limit what `host` sends and receives to `megabits_per_second` each way (a token bucket, `tc qdisc
        ... tbf`, on both ends of its link; what cannot be sent within 100 ms waits, then is dropped); None
        lifts the limit."""
        port = f'port{self.hosts.index(host) + 1}'
        for namespace, interface in ((self.namespaces[host], 'eth0'), (self.hub, port)):
            command = ['tc', '-n', namespace, 'qdisc', 'del' if megabits_per_second is None else 'add', 'dev',
                       interface, 'root']
            if megabits_per_second is not None:
                command += ['tbf', 'rate', f'{megabits_per_second}mbit', 'burst', '32kb', 'latency', '100ms']
            subprocess.run(command, check=True)

    def drop_randomly(self, host, probability):
        """Lose each IPv4 packet `host` receives or sends with `probability` (iptables' statistic match, as
        `tc netem` is not in every kernel); None ends it."""
        iptables = ['ip', 'netns', 'exec', self.namespaces[host], 'iptables']
        for chain in ('INPUT', 'OUTPUT'):
            if probability is None:
                subprocess.run([*iptables, '-F', chain], check=True)
            else:
                subprocess.run([*iptables, '-A', chain, '-m', 'statistic', '--mode', 'random', '--probability',
                                str(probability), '-j', 'DROP'], check=True)

    def bytes_sent(self, host):
        """Bytes `host` has sent on its link so far."""
        statistics = ip('-s', '-j', 'link', 'show', 'eth0', namespace=self.namespaces[host])
        return json.loads(statistics)[0]['stats64']['tx']['bytes']

    def close(self):
        """End every process started here (Ctrl-C, then SIGKILL) and anything else left in the namespaces,
        then delete the namespaces (their interfaces go with them)."""
        for process in self.processes:
            process.kill()
        for namespace in [*self.namespaces.values(), self.hub]:
            left = subprocess.run(['ip', 'netns', 'pids', namespace], capture_output=True, text=True).stdout.split()
            for pid in left:
                try:
                    os.kill(int(pid), signal.SIGKILL)
                except ProcessLookupError:
                    pass
            if left:
                time.sleep(0.2)
            subprocess.run(['ip', 'netns', 'delete', namespace], capture_output=True)
