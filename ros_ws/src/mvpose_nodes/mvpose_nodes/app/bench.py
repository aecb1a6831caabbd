"""`./mvpose bench [BAG]`: throughput and latency of the real graph over DDS, against the bag's decode floor.

The graph of launch/mvpose.launch.yaml (three camera_features and the skeleton_fitter) runs as separate
processes, as in `./mvpose demo`. Instead of `bag play` at a fixed rate, this process publishes the bag
closed-loop: the calibration (latched) first, then the frame sets' compressed images, keeping at most
--window frame sets in flight (sent, no skeleton yet), so the graph runs as fast as it keeps up and no
frame set is dropped by a full queue. Wall times in this process give the latencies:

  decode      cv2.imdecode of one of the bag's images, here, on one core (before the graph starts)
  features    images of a frame set published -> /cam<K>/labelled_contour of that stamp received, per camera
              (DDS, decode and the feature pipeline in the camera_features node)
  sync wait   skeleton received - fit_time - the last camera's contour received (the wait for the set
              in the fitter, plus publishing and DDS of the skeleton)
  fit         Skeleton.fit_time, the fit alone
  end to end  images published -> /mvpose/skeleton of that stamp received

end-to-end throughput = frame sets fitted / (last skeleton received - first images published);
decode-only throughput = 1 / (cameras x median decode time of one image): frame sets per second that one
core decoding the bag's images could deliver, and nothing else. CPU seconds and CPU % of each node are
over the closed-loop run (from /proc/PID/stat), peak RSS over the node's whole life (VmHWM).
"""
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mvpose_nodes.tools.cli import ArgumentParser, UserError, exit_on_user_error

DEFAULT_BAG = Path('bags/i3dpost_walk_synth')
MAKE_DEFAULT_BAG = '`./mvpose synth --cameras 3 5 7 --frames 52-101 -o bags/i3dpost_walk_synth` or `./mvpose demo`'
DEFAULT_WINDOW = 2
FLOOR_RATE, AIM_RATE = 3, 25        # [frame sets/s] issue 6: the least the graph must do, and real time
STALL_TIMEOUT = 60.0                # [s] without a skeleton for a frame set sent: it counts as dropped
SUBSCRIBER_TIMEOUT = 30.0           # [s] for the graph to subscribe to the bench's publishers
IMAGE_DEPTH = 10


# ---------------------------------------------------------------- statistics (pure, tested on numbers)

def median_p95(values):
    """(median, 95th percentile) of `values` (linear interpolation, as numpy); (nan, nan) when empty."""
    values = np.asarray(list(values), dtype=float)
    if values.size == 0:
        return float('nan'), float('nan')
    return float(np.median(values)), float(np.percentile(values, 95))


def stage_latencies(sent, features, skeletons):
    """Per-stage latencies [ms] from the wall times [s] of one run.

    sent: {stamp: time the frame set's images were published}; features: {stamp: {camera: time its
    labelled_contour arrived}}; skeletons: {stamp: (time the skeleton arrived, its fit_time [s])}.
    Returns {'features': [...] (one per camera and frame set), 'sync wait': [...], 'fit': [...],
    'end to end': [...]}; sync wait and end to end only for frame sets with every camera's contour."""
    out = {'features': [], 'sync wait': [], 'fit': [], 'end to end': []}
    for stamp, t_sent in sent.items():
        arrived = features.get(stamp, {})
        out['features'].extend(1e3 * (t - t_sent) for t in arrived.values())
        if stamp not in skeletons:
            continue
        t_skeleton, fit_time = skeletons[stamp]
        out['fit'].append(1e3 * fit_time)
        out['end to end'].append(1e3 * (t_skeleton - t_sent))
        if arrived:
            out['sync wait'].append(1e3 * (t_skeleton - fit_time - max(arrived.values())))
    return out


def throughput(sent, skeletons):
    """Frame sets fitted per second: fitted / (last skeleton arrival - first images published); 0 if none."""
    if not skeletons or not sent:
        return 0.0
    span = max(t for t, _ in skeletons.values()) - min(sent.values())
    return len(skeletons) / span if span > 0 else float('inf')


def decode_only_rate(decode_ms, cameras):
    """Frame sets per second one core decoding only: 1 / (cameras x median decode time of one image)."""
    median, _ = median_p95(decode_ms)
    return 1e3 / (cameras * median) if median > 0 else float('nan')


def cpu_ticks(stat_text):
    """utime + stime [clock ticks] of a /proc/PID/stat line (the command name may hold spaces and ')')."""
    fields = stat_text.rsplit(')', 1)[1].split()
    return int(fields[11]) + int(fields[12])   # fields 14 and 15 of proc(5), counted from 'state' = 3


def peak_rss_kib(status_text):
    """VmHWM [kB] of a /proc/PID/status text, or None when it has none (e.g. a zombie)."""
    for line in status_text.splitlines():
        if line.startswith('VmHWM:'):
            return int(line.split()[1])
    return None


def sample_process(pid):
    """(cpu ticks, peak RSS kB) of a running process, or None when it is gone."""
    try:
        return (cpu_ticks(Path(f'/proc/{pid}/stat').read_text()),
                peak_rss_kib(Path(f'/proc/{pid}/status').read_text()))
    except (OSError, IndexError, ValueError):
        return None


def node_usage(before, after, wall_seconds, ticks_per_second):
    """Per node: (CPU s, CPU % of wall_seconds, peak RSS MiB) from two samples {node: (ticks, peak kB)}
    taken at the start and the end of the run; None entries (process gone) give NaNs."""
    rows = {}
    for name, end in after.items():
        start = before.get(name)
        if end is None or start is None:
            rows[name] = (float('nan'), float('nan'), float('nan'))
            continue
        seconds = (end[0] - start[0]) / ticks_per_second
        percent = 100.0 * seconds / wall_seconds if wall_seconds > 0 else float('nan')
        rows[name] = (seconds, percent, end[1] / 1024 if end[1] is not None else float('nan'))
    return rows


# ---------------------------------------------------------------- the report

@dataclass
class BenchResult:
    bag: str
    cameras: tuple
    width: int
    height: int
    window: int
    frame_sets: int
    sent: dict = field(default_factory=dict)        # stamp -> t published
    features: dict = field(default_factory=dict)    # stamp -> {camera: t contour received}
    skeletons: dict = field(default_factory=dict)   # stamp -> (t received, fit_time)
    unfitted: int = 0                               # frame sets the fitter had too few views for
    dropped: int = 0                                # frame sets without any answer within STALL_TIMEOUT
    decode_ms: list = field(default_factory=list)
    usage: dict = field(default_factory=dict)       # node -> (CPU s, CPU %, peak RSS MiB)
    wall_seconds: float = 0.0


def _number(value, width=8, digits=1):
    return f'{value:{width}.{digits}f}' if np.isfinite(value) else f'{"-":>{width}}'


def format_table(result):
    """The printed table of a BenchResult."""
    fitted = len(result.skeletons)
    rate = throughput(result.sent, result.skeletons)
    floor_rate = decode_only_rate(result.decode_ms, len(result.cameras))
    missing = result.frame_sets - fitted
    if not missing:
        outcome = 'none dropped'
    else:
        outcome = ', '.join(part for part in (
            f'{result.unfitted} with too few views' if result.unfitted else '',
            f'{result.dropped} dropped (no answer in {STALL_TIMEOUT:.0f} s)' if result.dropped else '',
            f'{missing - result.unfitted - result.dropped} not sent' if missing - result.unfitted - result.dropped
            else '') if part)
    ratio = rate / floor_rate if floor_rate and np.isfinite(floor_rate) else float('nan')
    lines = [
        f'bench: {result.bag}  ({result.frame_sets} frame sets, cameras {" ".join(map(str, result.cameras))}, '
        f'{result.width}×{result.height}, window {result.window})',
        f'  end-to-end    {_number(rate, 6, 2)} frame sets/s   ({fitted} of {result.frame_sets} fitted, {outcome})'
        f'     floor {FLOOR_RATE}/s, aim {AIM_RATE}/s',
        f'  decode only   {_number(floor_rate, 6, 1)} frame sets/s on one core (1 / ({len(result.cameras)} × median '
        f'decode));  end-to-end / decode-only = {ratio:.3f}',
        '  latency [ms]          median      p95',
    ]
    stages = stage_latencies(result.sent, result.features, result.skeletons)
    notes = {'decode': '(cv2.imdecode of one image, this process)',
             'features': '(images sent -> contour received, per camera)',
             'sync wait': '(skeleton received - fit - last contour received; includes queueing behind the previous fit)',
             'fit': '(Skeleton.fit_time)',
             'end to end': '(images sent -> skeleton received)'}
    for stage, values in (('decode', result.decode_ms), *stages.items()):
        median, p95 = median_p95(values)
        lines.append(f'    {stage:<16}{_number(median, 9)}{_number(p95, 9)}   {notes[stage]}')
    lines.append(f'  node                        CPU s    CPU %   peak RSS MiB   (CPU over the {result.wall_seconds:.1f} s run)')
    for name, (seconds, percent, mib) in result.usage.items():
        lines.append(f'    {name:<24}{_number(seconds, 7)}{_number(percent, 9, 0)}{_number(mib, 15, 0)}')
    return '\n'.join(lines)


# ---------------------------------------------------------------- the run

def load_frame_sets(bag, cameras, limit=None):
    """The bag's calibration {topic: cdr} and its complete frame sets [(stamp, {camera: cdr})] in stamp order."""
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import CompressedImage
    from mvpose_nodes.io.bagfile import BagReader
    from mvpose_nodes.ros.conversions import stamp_ns

    reader = BagReader(bag)
    images = {f'/cam{k}/image_raw/compressed': k for k in cameras}
    calibration_topics = [f'/cam{k}/{kind}' for k in cameras for kind in ('camera_info', 'camera_pose')]
    missing = [topic for topic in [*images, *calibration_topics] if topic not in reader.topics]
    if missing:
        raise UserError(f"bag '{bag}' lacks {', '.join(missing)} (the graph fits cameras {list(cameras)})")
    calibration, by_stamp = {}, {}
    for info, _, data in reader.messages(topics=[*images, *calibration_topics]):
        if info.name in images:
            stamp = stamp_ns(deserialize_message(data, CompressedImage).header)
            by_stamp.setdefault(stamp, {})[images[info.name]] = data
        else:
            calibration.setdefault(info.name, data)   # the first: what a late subscriber gets when latched
    frame_sets = [(stamp, views) for stamp, views in sorted(by_stamp.items()) if len(views) == len(cameras)]
    if not frame_sets:
        raise UserError(f"bag '{bag}' has no frame set with an image of every camera {list(cameras)}")
    return calibration, frame_sets[:limit]


def decode_times(frame_sets):
    """Milliseconds of cv2.imdecode for every image of the frame sets, in this process."""
    import cv2
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import CompressedImage
    times, shape = [], None
    for _, views in frame_sets:
        for data in views.values():
            buffer = np.frombuffer(bytes(deserialize_message(data, CompressedImage).data), np.uint8)
            started = time.perf_counter()
            image = cv2.imdecode(buffer, cv2.IMREAD_COLOR)
            times.append(1e3 * (time.perf_counter() - started))
            if image is None:
                raise UserError('an image of the bag does not decode')
            shape = image.shape
    return times, shape


def run_bench(bag, window, limit, log_path):
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import CameraInfo, CompressedImage
    from geometry_msgs.msg import PoseStamped
    from mvpose_msgs.msg import LabelledContour, Skeleton
    from mvpose_nodes.tools.bag import wait_for_subscribers
    from mvpose_nodes.ros.camera_bag import SKELETON_TOPIC
    from mvpose_nodes.app.graph_run import GRAPH_CAMERAS, wait_for_connections, launch_file
    from mvpose_nodes.tools.launch import Launch, load_launch_file
    from mvpose_nodes.app.progress import Progress
    from mvpose_nodes.ros.conversions import stamp_ns
    from mvpose_nodes.ros.helpers import LATCHED, StopSignal, wait_for_acknowledgements

    cameras = tuple(GRAPH_CAMERAS)
    calibration, frame_sets = load_frame_sets(bag, cameras, limit)
    print(f'[bench] decoding the {len(frame_sets) * len(cameras)} images of {len(frame_sets)} frame sets here '
          'for the decode-only floor', file=sys.stderr, flush=True)
    decode_ms, shape = decode_times(frame_sets)
    result = BenchResult(str(bag), cameras, shape[1], shape[0], window, len(frame_sets), decode_ms=decode_ms)
    ticks = os.sysconf('SC_CLK_TCK')
    log_path = Path(log_path)
    log_path.parent.mkdir(parents=True, exist_ok=True)
    with open(log_path, 'w') as log, StopSignal() as stop:
        launch = Launch(load_launch_file(launch_file()), output=log)
        node = rclpy.create_node('mvpose_bench')
        answered = {}   # stamp -> 'fitted' | 'unfitted' | 'dropped'
        statuses = {}   # stamp -> {camera: LabelledContour status}

        def contour_receiver(camera):
            def receive(message):
                stamp = stamp_ns(message.header)
                if stamp in result.sent:
                    result.features.setdefault(stamp, {})[camera] = time.monotonic()
                    statuses.setdefault(stamp, {})[camera] = message.status
            return receive

        def skeleton(message):
            stamp = stamp_ns(message.header)
            if message.status == Skeleton.STATUS_LOST:
                return   # no fit: the last pose repeated (counted as too few views below)
            if stamp in result.sent and stamp not in result.skeletons:
                result.skeletons[stamp] = (time.monotonic(), message.fit_time)
                answered[stamp] = 'fitted'

        for k in cameras:
            node.create_subscription(LabelledContour, f'/cam{k}/labelled_contour', contour_receiver(k), 100)
        node.create_subscription(Skeleton, SKELETON_TOPIC, skeleton, LATCHED)
        image_qos = QoSProfile(depth=IMAGE_DEPTH, reliability=ReliabilityPolicy.RELIABLE)
        image_publishers = {k: node.create_publisher(CompressedImage, f'/cam{k}/image_raw/compressed', image_qos)
                            for k in cameras}
        calibration_publishers = {topic: node.create_publisher(CameraInfo if topic.endswith('info') else PoseStamped,
                                                               topic, LATCHED) for topic in calibration}
        try:
            launch.start()
            pids = launch.pids()
            pids['bench (this process)'] = os.getpid()
            print(f'[bench] starting the graph (log: {log_path})', file=sys.stderr, flush=True)
            wait_for_connections(node, launch, stop)
            wait_for_subscribers(node, {**{f'/cam{k}/image_raw/compressed': p for k, p in image_publishers.items()},
                                        **calibration_publishers}, SUBSCRIBER_TIMEOUT, stop)
            for topic, publisher in calibration_publishers.items():
                publisher.publish(calibration[topic])
            wait_for_acknowledgements(calibration_publishers.values(), timeout_sec=5.0)
            time.sleep(0.5)
            before = {name: sample_process(pid) for name, pid in pids.items()}
            started = time.monotonic()
            progress = Progress(len(frame_sets), 'bench', unit='frame sets')
            next_index, outstanding = 0, []
            while not stop.stopped and (next_index < len(frame_sets) or outstanding):
                while len(outstanding) < window and next_index < len(frame_sets):
                    stamp, views = frame_sets[next_index]
                    for k, data in views.items():
                        image_publishers[k].publish(data)
                    result.sent[stamp] = time.monotonic()
                    outstanding.append(stamp)
                    next_index += 1
                rclpy.spin_once(node, timeout_sec=0.05)
                now = time.monotonic()
                for stamp in list(outstanding):
                    views = statuses.get(stamp, {})
                    if stamp not in answered and len(views) == len(cameras) and \
                            sum(s == LabelledContour.STATUS_OK for s in views.values()) < 2:
                        answered[stamp] = 'unfitted'   # the fitter does not fit fewer than 2 views
                        result.unfitted += 1
                    elif stamp not in answered and now - result.sent[stamp] > STALL_TIMEOUT:
                        answered[stamp] = 'dropped'
                        result.dropped += 1
                    if stamp in answered:
                        outstanding.remove(stamp)
                        progress.update()
                if launch.wait(timeout=0) is not None:
                    raise UserError(f'a node of the graph stopped (exit code {launch.exit_code}); see {log_path}')
            progress.close()
            result.wall_seconds = time.monotonic() - started
            after = {name: sample_process(pid) for name, pid in pids.items()}
            result.usage = node_usage(before, after, result.wall_seconds, ticks)
        finally:
            node.destroy_node()
            launch.stop()
    if stop.stopped:
        raise KeyboardInterrupt
    return result


def main(argv=None, prog='bench'):
    parser = ArgumentParser(prog=prog, description=__doc__.split('\n\n')[0])
    parser.add_argument('bag', nargs='?', type=Path, help=f'camera bag with cameras 3, 5, 7 (default {DEFAULT_BAG})')
    parser.add_argument('--window', type=int, default=DEFAULT_WINDOW,
                        help=f'frame sets in flight at most (default {DEFAULT_WINDOW})')
    parser.add_argument('--frames', type=int, help='use only the first N frame sets (default all)')
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    with exit_on_user_error(prog):
        if args.window < 1:
            raise UserError(f'--window must be at least 1 (got {args.window})')
        if args.frames is not None and args.frames < 1:
            raise UserError(f'--frames must be at least 1 (got {args.frames})')
        from mvpose_nodes.app.main import repository_root
        root = repository_root()
        bag = args.bag
        if bag is None:
            bag = root / DEFAULT_BAG
            if not bag.exists():
                raise UserError(f'{DEFAULT_BAG} is missing: run {MAKE_DEFAULT_BAG}')
        elif not bag.exists():
            raise UserError(f"bag '{bag}' not found")
        result = run_bench(bag, args.window, args.frames, root / 'output' / 'bench' / 'graph.log')
        if bag.is_relative_to(root):
            result.bag = str(bag.relative_to(root))
        print(format_table(result), flush=True)
    return 0 if len(result.skeletons) == result.frame_sets else 1


if __name__ == '__main__':
    sys.exit(main())
