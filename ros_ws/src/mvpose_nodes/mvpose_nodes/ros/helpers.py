"""rclpy helpers shared by the nodes and tools: the Jazzy run pattern, QoS conversions, graph look-ups."""
import ctypes
import faulthandler
import os
import re
import select
import signal
import sys
import threading
import time

import rclpy
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException
from rclpy.experimental import EventsExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions

from mvpose_nodes.io.bagfile import DEFAULT_QOS_PROFILE
from mvpose_nodes.ros.params import ParameterError
from mvpose_nodes.vision.skin import SkinModelError

SPIN_PERIOD = 0.1  # [s] the longest a node takes to see a shutdown
# [s] the longest a node may take to end once asked to stop (Ctrl-C, SIGTERM): past it the process says so and
# exits (watch_stop). Two hangs in rclpy made this needed: Node.destroy_node() once spun for ever at 100 % of a
# core in destroy_when_not_in_use() (py-spy; 1 in a few hundred stops, EventsExecutor), and a camera_features
# node once ignored SIGINT and then SIGTERM until its launcher killed it (1 of 10 fresh-clone test runs).
# Shorter than the 5 s a launcher gives a node after SIGINT before it sends SIGTERM (`launch --sigint-timeout`,
# as ros2 launch's), so that such a hang still ends as a clean stop.
STOP_LIMIT = 3.0
# [s] past STOP_LIMIT, when a tool's teardown hung where no Python thread can run: faulthandler prints the
# stacks at half of this, the exit timer ends the process at all of it (destroy_or_exit).
EXIT_TIMER_DELAY = 1.0
SIGEV_THREAD, CLOCK_MONOTONIC = 2, 1   # signal.h and time.h (Linux)
# glibc's malloc (see keep_freed_memory): buffers up to this size come from the heap rather than mmap, and
# freed memory up to the trim threshold stays in the process. 64 MB is above any one frame's buffer (a 1080p
# RGB image is 6 MB, a frame set's distance maps about 17 MB).
MMAP_THRESHOLD_BYTES = 64 << 20
TRIM_THRESHOLD_BYTES = 256 << 20
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3   # mallopt's parameter numbers (glibc malloc.h)

# Reliable, transient-local, depth 1: calibration, and the last skeleton for late subscribers.
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
# A reader of /mvpose/skeleton that must see every skeleton (bench, soak, demo): compatible with LATCHED, but
# its history keeps up to 100 skeletons its executor has not taken yet. With LATCHED's depth of 1 each new
# skeleton replaced the one not yet taken whenever the reader's process was slow (a soak beside three busy
# loops lost 2 of 300 frame sets so).
EVERY_SKELETON = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                            durability=DurabilityPolicy.TRANSIENT_LOCAL)


class ReportOnce:
    """Mixin for a Node: report_once(cause, text) logs a warning the first time each cause occurs, so a
    stream of bad messages logs once and the node keeps going."""

    def report_once(self, cause, text):
        reported = self.__dict__.setdefault('_reported_causes', set())
        if cause not in reported:
            reported.add(cause)
            self.get_logger().warning(text)


def camera_of_namespace(namespace, executable):
    """The camera number K of a per-camera node's namespace /cam<K>; ParameterError naming the executable."""
    match = re.match(r'^/cam(\d+)$', namespace)
    if not match:
        raise ParameterError(f"{executable} must run in a camera's namespace /cam<K> (e.g. --ros-args -r "
                        f"__ns:=/cam3); it runs in '{namespace}'")
    return int(match[1])


def run_node(make_node, args=None):
    """Jazzy's rclpy run pattern for a node that spins until Ctrl-C or shutdown; the exit code.
    A bad parameter, namespace or model file while the node starts is one line and code 2.

    The node spins in rclpy's EventsExecutor (rclpy.experimental, C++): it takes a third of the CPU of
    the default SingleThreadedExecutor per callback (the skeleton_fitter's rclpy share 9 -> 3 ms per
    frame set, each camera_features' 3 -> 1.5; `./mvpose bench`). Its spin() busy-loops at 100 % of a
    core and ignores Ctrl-C in this rclpy (7.1.6), so it is spun in steps of SPIN_PERIOD, after each of
    which a shutdown (the signal handler's) is seen.

    The clean-up may hang in rclpy holding the GIL, where watch_stop's thread cannot run (as destroy_node did
    in a tool, destroy_or_exit): from the clean-up's start the process is ended STOP_LIMIT + EXIT_TIMER_DELAY
    later (end_if_hung) with the node's exit code (1 for an error not handled here, as Python's), after every
    thread's stack is printed. So run_node ends its process's work: call it last."""
    keep_freed_memory()
    rclpy.init(args=args)
    name = getattr(make_node, '__name__', 'node')
    watch_stop(rclpy.get_default_context(), name)
    node = None
    code = 0
    executor = EventsExecutor()
    try:
        node = make_node()
        executor.add_node(node)
        while rclpy.ok():
            executor.spin_once(timeout_sec=SPIN_PERIOD)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (ParameterError, SkinModelError) as error:
        print(f'[ERROR] {name}: {error}', file=sys.stderr)
        code = 2
    finally:
        # An error none of the above handles is on its way out: Python would exit with 1.
        end_if_hung(1 if sys.exc_info()[0] is not None else code)
        executor.shutdown()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return code


def keep_freed_memory():
    """Have glibc's malloc keep the memory a node frees, so that each frame's large buffers (images, masks,
    distance maps: each over malloc's 128 kB mmap threshold) reuse the process's pages instead of being
    mapped afresh. Otherwise, depending on the process's heap, every frame faults its buffers in page by
    page: `./mvpose bench` counted 1000-1400 minor page faults per frame in two of three camera_features
    nodes (one took almost none), each camera's CPU 21-26 ms per frame set against 19-21 with this
    (docs/method.md, session 37). Where the C library has no mallopt (not glibc), nothing changes."""
    mallopt = getattr(ctypes.CDLL(None), 'mallopt', None)
    if mallopt is not None:
        mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)
        mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES)


def watch_stop(context, name):
    """A daemon thread that ends the process STOP_LIMIT seconds after `context` was shut down, if it still
    runs then. rclpy's signal handler shuts the context down from a thread of its own on Ctrl-C and SIGTERM, so
    this holds wherever the main thread hangs, in the executor or in the clean-up, unless it holds the GIL there,
    which stops this thread too (for the clean-up run_node arms exit_timer)."""
    def watch():
        while context.ok():
            time.sleep(SPIN_PERIOD)
        time.sleep(STOP_LIMIT)
        abandon(name, 'it was asked to stop')
    threading.Thread(target=watch, name='stop watchdog', daemon=True).start()


def destroy_or_exit(node, name, code):
    """node.destroy_node() for a command-line tool whose work is done, which then returns `code`; if the process
    has not ended STOP_LIMIT seconds later (rclpy hung in destroy_node, in its shutdown or in the middleware's
    threads at the interpreter's exit), it says so and ends with `code` all the same. A Python thread watches
    and says so while the interpreter can run it; but rclpy has hung in destroy_node holding the GIL (a `topic
    echo --count 5` that had printed its five messages, sessions 42 and 70), and then no Python thread runs:
    for that a POSIX timer ends the process EXIT_TIMER_DELAY later, after every thread's stack is printed
    (end_if_hung)."""
    def watch():
        time.sleep(STOP_LIMIT)
        abandon(name, 'its work was done', code)
    threading.Thread(target=watch, name='teardown watchdog', daemon=True).start()
    end_if_hung(code)
    node.destroy_node()
    return code


def end_if_hung(code):
    """The last resort of a process's clean-up, whatever its threads do: every thread's stack printed
    (faulthandler, which needs no GIL) STOP_LIMIT + EXIT_TIMER_DELAY / 2 from now, and the process ended with
    `code` EXIT_TIMER_DELAY after STOP_LIMIT (exit_timer), if it still runs then; the Python watchdogs, which
    say why at STOP_LIMIT, come first where the GIL lets them."""
    faulthandler.dump_traceback_later(STOP_LIMIT + EXIT_TIMER_DELAY / 2)
    exit_timer(STOP_LIMIT + EXIT_TIMER_DELAY, code)


def exit_timer(seconds, code):
    """End this process with exit status `code` `seconds` from now, whatever its threads do: a POSIX timer
    (timer_create, SIGEV_THREAD) whose expiry starts a thread of the C library's that calls _exit(code), so it
    needs neither the GIL nor a running interpreter. The timer's argument, a union sigval, is passed as _exit's
    int (in a register on x86-64 and aarch64, the ABIs of the ROS 2 wheels). Where the C library has no
    timer_create, nothing is armed."""
    libc = ctypes.CDLL(None, use_errno=True)
    if not hasattr(libc, 'timer_create'):
        return
    event = _SignalEvent(value=code, notify=SIGEV_THREAD,
                         function=ctypes.cast(libc._exit, ctypes.c_void_p).value)
    timer = ctypes.c_void_p()
    if libc.timer_create(CLOCK_MONOTONIC, ctypes.byref(event), ctypes.byref(timer)) != 0:
        raise OSError(ctypes.get_errno(), f'timer_create: {os.strerror(ctypes.get_errno())}')
    whole = int(seconds)
    expiry = _TimerSpec(value=_TimeSpec(whole, int((seconds - whole) * 1e9)))
    libc.timer_settime.argtypes = (ctypes.c_void_p, ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p)
    if libc.timer_settime(timer, 0, ctypes.byref(expiry), None) != 0:
        raise OSError(ctypes.get_errno(), f'timer_settime: {os.strerror(ctypes.get_errno())}')


class _TimeSpec(ctypes.Structure):
    """struct timespec (time.h)."""
    _fields_ = [('seconds', ctypes.c_long), ('nanoseconds', ctypes.c_long)]


class _TimerSpec(ctypes.Structure):
    """struct itimerspec (time.h): no interval, one expiry `value` from now."""
    _fields_ = [('interval', _TimeSpec), ('value', _TimeSpec)]


class _SignalEvent(ctypes.Structure):
    """struct sigevent (signal.h, glibc and musl on Linux: 64 bytes) for SIGEV_THREAD: `function` called with
    `value` on a new thread."""
    _fields_ = [('value', ctypes.c_void_p), ('signal', ctypes.c_int), ('notify', ctypes.c_int),
                ('function', ctypes.c_void_p), ('attributes', ctypes.c_void_p), ('padding', ctypes.c_int * 8)]


def abandon(name, after, code=0):
    """A process hung in rclpy `after` something (watch_stop, destroy_or_exit): say it and end the process with
    `code`, which frees what it held."""
    print(f'[WARN] {name}: still running {STOP_LIMIT:g} s after {after} (hung in rclpy); exiting without cleaning up',
          file=sys.stderr, flush=True)
    os._exit(code)


class StopSignal:
    """Catch SIGINT/SIGTERM ourselves (rclpy's handler would shut the context down at once),
    so that a tool can drain what the middleware still holds before it exits.

    The handler only sets a flag and writes a byte to a pipe, which wait() selects on: a handler that took a
    lock (threading.Event.set) could interrupt the main thread inside that same Event's wait(), while it holds
    the lock, and wait for it for ever (a `topic pub` hung so on Ctrl-C, 1 in a few hundred)."""

    def __init__(self):
        self._stopped = False
        self._read_end = self._write_end = None

    def __enter__(self):
        rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
        self._read_end, self._write_end = os.pipe()
        os.set_blocking(self._write_end, False)
        self._previous = {sig: signal.signal(sig, self._handle) for sig in (signal.SIGINT, signal.SIGTERM)}
        return self

    def _handle(self, signum, frame):
        self._stopped = True
        try:
            os.write(self._write_end, b'!')
        except BlockingIOError:  # the pipe is full of earlier signals' bytes: wait() wakes anyway
            pass

    @property
    def stopped(self):
        return self._stopped

    def wait(self, seconds):
        """Sleep `seconds`, or less if a stop signal comes (or came); whether one did."""
        if not self._stopped:
            select.select([self._read_end], [], [], max(seconds, 0.0))
        return self._stopped

    def __exit__(self, *exc):
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        os.close(self._read_end)
        os.close(self._write_end)
        rclpy.try_shutdown()


def qos_to_dict(profile):
    """rclpy QoSProfile -> the dict rosbag2 stores (metadata version 9 spelling)."""
    def duration(value):
        nanoseconds = value.nanoseconds if hasattr(value, 'nanoseconds') else 0
        return {'sec': nanoseconds // 10**9, 'nsec': nanoseconds % 10**9}
    return {
        'history': profile.history.short_key, 'depth': profile.depth,
        'reliability': profile.reliability.short_key, 'durability': profile.durability.short_key,
        'deadline': duration(profile.deadline), 'lifespan': duration(profile.lifespan),
        'liveliness': profile.liveliness.short_key,
        'liveliness_lease_duration': duration(profile.liveliness_lease_duration),
        'avoid_ros_namespace_conventions': profile.avoid_ros_namespace_conventions,
    }


def _policy(policy_class, value, default):
    """A QoS policy from a stored value: short key ('reliable') or the rmw enum integer."""
    try:
        return policy_class.get_from_short_key(value) if isinstance(value, str) else policy_class(int(value))
    except (KeyError, ValueError, TypeError):
        return policy_class.get_from_short_key(default)


def qos_from_dict(stored):
    """The history, depth, reliability and durability of a stored profile as a QoSProfile."""
    merged = {**DEFAULT_QOS_PROFILE, **(stored or {})}
    history = _policy(HistoryPolicy, merged['history'], 'keep_last')
    if history not in (HistoryPolicy.KEEP_LAST, HistoryPolicy.KEEP_ALL):
        history = HistoryPolicy.KEEP_LAST
    return QoSProfile(
        history=history, depth=max(1, int(merged.get('depth') or DEFAULT_QOS_PROFILE['depth'])),
        reliability=_policy(ReliabilityPolicy, merged['reliability'], 'reliable'),
        durability=_policy(DurabilityPolicy, merged['durability'], 'volatile'))


def subscription_qos_for(node, topic, depth=10):
    """A QoS that matches every current publisher of `topic`, as `ros2 topic echo` and
    `ros2 bag record` choose it: reliable only if all publishers are reliable, transient-local
    only if all are (so that a late subscriber still gets what they latched)."""
    publishers = node.get_publishers_info_by_topic(topic)
    reliable = bool(publishers) and all(p.qos_profile.reliability == ReliabilityPolicy.RELIABLE for p in publishers)
    latched = bool(publishers) and all(p.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
                                       for p in publishers)
    return QoSProfile(
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


def topic_types(node):
    """{topic: type name} of the live graph (first type when a topic has several)."""
    return {name: types[0] for name, types in node.get_topic_names_and_types() if types}


def wait_for_publishers(node, topic, timeout, stop=None):
    """Spin until `topic` has a publisher; the type name it publishes, or None after `timeout` [s].

    Subscribing only then lets the subscription QoS match the publishers (see subscription_qos_for)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and not (stop and stop.stopped):
        publishers = node.get_publishers_info_by_topic(topic)
        if publishers:
            return publishers[0].topic_type
        rclpy.spin_once(node, timeout_sec=0.1)
    return None


def wait_for_acknowledgements(publishers, timeout_sec):
    """Give reliable subscribers the time to take what was published before the process exits."""
    deadline = time.monotonic() + timeout_sec
    for publisher in publishers:
        remaining = max(0.0, deadline - time.monotonic())
        publisher.wait_for_all_acked(Duration(seconds=remaining))
