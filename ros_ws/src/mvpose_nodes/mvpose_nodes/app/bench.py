"""`./mvpose bench [BAG] [--rate R | --transport]`: throughput, latency and CPU of the real graph over
DDS, against the bag's decode floor; or what each of a camera's messages costs to cross DDS.

The graph of launch/mvpose.launch.yaml (three camera_features and the skeleton_fitter) runs as separate
processes, as in `./mvpose demo`. Instead of `bag play`, this process publishes the bag: the calibration
(latched) first, then the frame sets' compressed images, either
  closed loop (default): at most --window frame sets in flight (sent, no skeleton yet), so the graph runs
      as fast as it keeps up and no frame set is dropped by a full queue; or
  open loop (--rate R): each frame set at its stamp's time in the bag / R, whatever the graph does, as a
      camera or `bag play` would; the fitter then skips what it cannot keep up with (pending_frame_sets).
Wall times in this process give the latencies:

  decode      decode_image (vision/decoding.py, as the nodes decode) of one of the bag's images, here, on
              one core (before the graph starts)
  features    images of a frame set published -> /cam<K>/labelled_contour of that stamp received, per camera
              (DDS, decode and the feature pipeline in the camera_features node)
  sync wait   skeleton received - fit_time - the last camera's contour received (the wait for the set
              in the fitter, its distance maps, plus publishing and DDS of the skeleton)
  fit         Skeleton.fit_time, the fit alone
  end to end  images published -> /mvpose/skeleton of that stamp received

A frame set answered with STATUS_LOST (no fit: the fitter lost the person, or had fewer than 2 views with
one) is lost, or has too few views; one still unanswered when a later one is fitted was passed over (the
fitter fits in stamp order and skips what it cannot keep up with); one without any answer for STALL_TIMEOUT
(closed loop) or DRAIN_TIMEOUT (open loop) counts as dropped. The skeletons are read with a deep history
(helpers.EVERY_SKELETON), so none is missed while this process is slow.

end-to-end throughput = frame sets fitted / (last skeleton received - first images published);
decode-only throughput = 1 / (cameras x median decode time of one image): frame sets per second that one
core decoding the bag's images could deliver, and nothing else. CPU seconds and CPU % of each node are
over the run (from /proc/PID/stat), peak RSS over the node's whole life (VmHWM). Where each node's CPU
goes, stage by stage (and the skeleton_fitter's hypotheses pool, which does part of its fit, apart from
DDS's threads), comes from the nodes' own /diagnostics (ros/diagnostics.py) at the start and the end of
the run. In open loop, the fitted frame sets' mean joint error against the bag's /mvpose/ground_truth,
and per quarter of the run how many were fitted and their error (a start costs the first most). With
-o RUN the fitted skeletons are recorded to a bag, for `./mvpose eval RUN --truth BAG`.

`./mvpose soak [BAG] [--frame-sets N]`: the same closed loop for N frame sets, the bag's frame sets sent
again and again with their stamps moved on by the bag's length each time (so that to the graph they are
one long recording): each node's resident memory and the latency sampled every --sample-every frame sets,
and every frame set not fitted counted (a soak finds leaks, a latency that drifts and drops that are not
on purpose).

--transport: the graph does not run. The first camera's first image with a person in the bag, its
camera_features messages (silhouette raw and PNG, labelled contour, skin ellipses) and a bare Header are
sent to an echo process one at a time (tools/transport.py): size, serialisation CPU and round trip per
topic. The raw silhouette is what the skeleton_fitter used to read per camera and frame set; the contour
is what it reads now.
"""
import os
import sys
import time
from pathlib import Path

import numpy as np

from mvpose_nodes.app.graph_run import ALL_CAMERAS, GRAPH_CAMERAS, GraphRun, write_run_bag
from mvpose_nodes.app.reports.benchmark import (STALL_TIMEOUT, BenchResult, SoakSample, cpu_split, format_soak,
                                                format_table, median_p95, node_usage, resident_mib, sample_process)
from mvpose_nodes.tools.cli import ArgumentParser, UserError, exit_on_user_error

DEFAULT_BAG = Path('bags/i3dpost_walk_synth')
MAKE_DEFAULT_BAG = '`./mvpose synth --cameras 3 5 7 --frames 52-101 -o bags/i3dpost_walk_synth` or `./mvpose demo`'
DEFAULT_WINDOW = 2
TRANSPORT_ROUND_TRIPS = 50          # per topic, with --transport
SUBSCRIBER_TIMEOUT = 30.0           # [s] for the graph to subscribe to the bench's publishers
DIAGNOSTICS_TIMEOUT = 5.0           # [s] for every node's /diagnostics (published each second)
DRAIN_TIMEOUT = 10.0                # [s] open loop: skeletons still awaited after the last frame set sent
IMAGE_DEPTH = 10
SOAK_FRAME_SETS = 10_000
SOAK_SAMPLE_EVERY = 500
SOAK_WARM_UP = 500                  # frame sets before memory growth is counted (start-up, caches)


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


class LoopedFrameSets:
    """`total` frame sets made of a bag's [(stamp, {camera: CompressedImage CDR})], played again and
    again: the k-th time round, every stamp is moved on by k × (the bag's length + one frame period), in the
    images' headers too, so that the stamps keep increasing as in one long recording. Indexable like the
    list (the current round's images are re-serialised once)."""

    def __init__(self, frame_sets, total):
        self.frame_sets, self.total = frame_sets, total
        stamps = [stamp for stamp, _ in frame_sets]
        period = (stamps[-1] - stamps[0]) // max(1, len(stamps) - 1) if len(stamps) > 1 else 40_000_000
        self.round_ns = stamps[-1] - stamps[0] + period
        self._round, self._views = 0, [views for _, views in frame_sets]

    def __len__(self):
        return self.total

    def __getitem__(self, index):
        if not 0 <= index < self.total:
            raise IndexError(index)
        round_number, position = divmod(index, len(self.frame_sets))
        if round_number != self._round:
            self._round, self._views = round_number, [self._moved(views, round_number * self.round_ns)
                                                      for _, views in self.frame_sets]
        return self.frame_sets[position][0] + round_number * self.round_ns, self._views[position]

    @staticmethod
    def _moved(views, offset_ns):
        from rclpy.serialization import deserialize_message, serialize_message
        from sensor_msgs.msg import CompressedImage
        from mvpose_nodes.ros.conversions import set_stamp, stamp_ns
        moved = {}
        for camera, data in views.items():
            image = deserialize_message(data, CompressedImage)
            set_stamp(image.header, stamp_ns(image.header) + offset_ns, image.header.frame_id)
            moved[camera] = serialize_message(image)
        return moved


def decode_times(frame_sets):
    """Milliseconds of vision.decoding.decode_image (as the camera_features nodes decode) for every image of
    the frame sets, in this process."""
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import CompressedImage
    from mvpose_nodes.vision.decoding import decode_image
    times, shape = [], None
    for _, views in frame_sets:
        for data in views.values():
            buffer = bytes(deserialize_message(data, CompressedImage).data)
            started = time.perf_counter()
            image = decode_image(buffer)
            times.append(1e3 * (time.perf_counter() - started))
            if image is None:
                raise UserError('an image of the bag does not decode')
            shape = image.shape
    return times, shape


def run_bench(bag, window, rate, limit, log_path, total=None, sample_every=None, cameras=GRAPH_CAMERAS,
              keep_messages=False):
    """The bench run (the module's docstring) of the graph of `cameras` (graph_run.launch_file); with `total`,
    that many frame sets (LoopedFrameSets), and with `sample_every`, a SoakSample in result.samples each time
    that many more frame sets are answered; with `keep_messages`, the fitted Skeleton messages in
    result.messages."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import CameraInfo, CompressedImage
    from geometry_msgs.msg import PoseStamped
    from mvpose_msgs.msg import LabelledContour, Skeleton
    from mvpose_nodes.tools.bag import wait_for_subscribers
    from mvpose_nodes.app.fit import skeletons
    from mvpose_nodes.ros.camera_bag import GROUND_TRUTH_TOPIC, SKELETON_TOPIC
    from mvpose_nodes.app.graph_run import wait_for_connections, launch_file
    from mvpose_nodes.tools.launch import Launch, load_launch_file
    from mvpose_nodes.app.progress import Progress
    from mvpose_nodes.ros.conversions import joints_from_skeleton, stamp_ns
    from mvpose_nodes.ros.diagnostics import DIAGNOSTICS_TOPIC, stage_cpu
    from mvpose_nodes.ros.helpers import EVERY_SKELETON, LATCHED, StopSignal, wait_for_acknowledgements

    cameras = tuple(cameras)
    calibration, frame_sets = load_frame_sets(bag, cameras, limit)
    truth = {}
    if rate is not None:   # open loop: the fitted frame sets' error against the bag's truth, if it has one
        try:
            truth = skeletons(bag, GROUND_TRUTH_TOPIC)
        except UserError:
            pass
    print(f'[bench] decoding the {len(frame_sets) * len(cameras)} images of {len(frame_sets)} frame sets here '
          'for the decode-only floor', file=sys.stderr, flush=True)
    decode_ms, shape = decode_times(frame_sets)
    if total is not None:
        frame_sets = LoopedFrameSets(frame_sets, total)
    result = BenchResult(str(bag), cameras, shape[1], shape[0], window, len(frame_sets), rate, decode_ms=decode_ms)
    ticks = os.sysconf('SC_CLK_TCK')
    log_path = Path(log_path)
    log_path.parent.mkdir(parents=True, exist_ok=True)
    with open(log_path, 'w') as log, StopSignal() as stop:
        launch = Launch(load_launch_file(launch_file(cameras)), output=log)
        node = rclpy.create_node('mvpose_bench')
        answered = {}      # stamp -> 'fitted' | 'lost' | 'unfitted' | 'passed over' | 'dropped'
        statuses = {}      # stamp -> {camera: LabelledContour status}
        lost = set()       # stamps answered with STATUS_LOST
        diagnostics = {}   # node name -> (time received, DiagnosticStatus), the newest

        def contour_receiver(camera):
            def receive(message):
                stamp = stamp_ns(message.header)
                if stamp in result.sent:
                    result.features.setdefault(stamp, {})[camera] = time.monotonic()
                    statuses.setdefault(stamp, {})[camera] = message.status
            return receive

        def skeleton(message):
            stamp = stamp_ns(message.header)
            if stamp not in result.sent or stamp in answered:
                return
            if message.status == Skeleton.STATUS_LOST:
                lost.add(stamp)   # answered without a fit (the last pose repeated): counted below
            else:
                result.skeletons[stamp] = (time.monotonic(), message.fit_time)
                if keep_messages:
                    result.messages[stamp] = message
                answered[stamp] = 'fitted'
                if stamp in truth:
                    result.errors_mm[stamp] = 1e3 * float(np.linalg.norm(
                        joints_from_skeleton(message) - truth[stamp], axis=1).mean())

        def diagnostic(array):
            for status in array.status:   # named by the node's full name, /skeleton_fitter
                diagnostics[status.name.lstrip('/')] = (time.monotonic(), status)

        def newest_diagnostics(after, what):
            """{node: stage_cpu(status)} once every graph node has published a status after `after`."""
            names = [name.lstrip('/') for name in pids if name != 'bench (this process)']
            deadline = time.monotonic() + DIAGNOSTICS_TIMEOUT
            while not all(name in diagnostics and diagnostics[name][0] > after for name in names):
                if time.monotonic() > deadline:
                    missing = [name for name in names if name not in diagnostics or diagnostics[name][0] <= after]
                    raise UserError(f'no {DIAGNOSTICS_TOPIC} from {", ".join(missing)} {what} within '
                                    f'{DIAGNOSTICS_TIMEOUT:.0f} s; see {log_path}')
                rclpy.spin_once(node, timeout_sec=0.1)
            return {name: stage_cpu(diagnostics[name][1]) for name in names}

        for k in cameras:
            node.create_subscription(LabelledContour, f'/cam{k}/labelled_contour', contour_receiver(k), 100)
        node.create_subscription(Skeleton, SKELETON_TOPIC, skeleton, EVERY_SKELETON)
        node.create_subscription(DiagnosticArray, DIAGNOSTICS_TOPIC, diagnostic, 100)
        image_qos = QoSProfile(depth=IMAGE_DEPTH, reliability=ReliabilityPolicy.RELIABLE)
        image_publishers = {k: node.create_publisher(CompressedImage, f'/cam{k}/image_raw/compressed', image_qos)
                            for k in cameras}
        calibration_publishers = {topic: node.create_publisher(CameraInfo if topic.endswith('info') else PoseStamped,
                                                               topic, LATCHED) for topic in calibration}
        try:
            result.launched = time.monotonic()
            launch.start()
            pids = launch.pids()
            pids['bench (this process)'] = os.getpid()
            print(f'[bench] starting the graph (log: {log_path})', file=sys.stderr, flush=True)
            wait_for_connections(node, launch, stop, log_path, cameras)
            result.connected = time.monotonic()
            wait_for_subscribers(node, {**{f'/cam{k}/image_raw/compressed': p for k, p in image_publishers.items()},
                                        **calibration_publishers}, SUBSCRIBER_TIMEOUT, stop)
            for topic, publisher in calibration_publishers.items():
                publisher.publish(calibration[topic])
            wait_for_acknowledgements(calibration_publishers.values(), timeout_sec=5.0)
            # The statuses that showed the graph connected will do: a node publishes them from its executor, after
            # its start-up, and idles from then until the first images (a few ms of DDS at most, counted in the
            # run). Waiting for newer ones held the first images back by a status period (1 s) and put that
            # wait in the start-up figure.
            cpu_before = newest_diagnostics(result.launched, 'before the run')
            before = {name: sample_process(pid) for name, pid in pids.items()}
            started = time.monotonic()
            progress = Progress(len(frame_sets), 'bench', unit='frame sets')
            next_index, outstanding, finished = 0, [], []   # finished: stamps answered, in that order
            first_stamp = frame_sets[0][0]
            while not stop.stopped and (next_index < len(frame_sets) or outstanding):
                now = time.monotonic()
                while next_index < len(frame_sets) and (
                        len(outstanding) < window if rate is None
                        else now - started >= (frame_sets[next_index][0] - first_stamp) / 1e9 / rate):
                    stamp, views = frame_sets[next_index]
                    for k, data in views.items():
                        image_publishers[k].publish(data)
                    result.sent[stamp] = time.monotonic()
                    outstanding.append(stamp)
                    next_index += 1
                # Open loop: wake for the next frame set's time, not before (a busy poll would take the graph's CPU).
                due = (None if rate is None or next_index == len(frame_sets)
                       else (frame_sets[next_index][0] - first_stamp) / 1e9 / rate - (time.monotonic() - started))
                rclpy.spin_once(node, timeout_sec=0.05 if due is None else min(max(due, 0.0), 0.05))
                now = time.monotonic()
                newest_fitted = max(result.skeletons, default=None)
                for stamp in list(outstanding):
                    views = statuses.get(stamp, {})
                    if stamp in answered:
                        pass   # fitted: the skeleton callback said so
                    elif len(views) == len(cameras) and sum(s == LabelledContour.STATUS_OK for s in views.values()) < 2:
                        answered[stamp] = 'unfitted'   # the fitter does not fit fewer than 2 views
                        result.unfitted += 1
                    elif stamp in lost:
                        answered[stamp] = 'lost'   # the fitter said it lost the person (Skeleton.STATUS_LOST)
                        result.lost += 1
                    elif newest_fitted is not None and stamp < newest_fitted:
                        answered[stamp] = 'passed over'   # the fitter fits in stamp order: it skipped this one
                        result.overtaken += 1
                    elif now - result.sent[stamp] > (STALL_TIMEOUT if rate is None else DRAIN_TIMEOUT):
                        answered[stamp] = 'dropped'
                        result.dropped += 1
                    if stamp in answered:
                        outstanding.remove(stamp)
                        progress.update()
                        finished.append(stamp)
                        if sample_every and len(finished) % sample_every == 0:
                            result.samples.append(soak_sample(result, finished, sample_every, pids, started))
                if launch.wait(timeout=0) is not None:
                    raise UserError(f'a node of the graph stopped (exit code {launch.exit_code}); see {log_path}')
            progress.close()
            result.wall_seconds = time.monotonic() - started
            after = {name: sample_process(pid) for name, pid in pids.items()}
            result.usage = node_usage(before, after, result.wall_seconds, ticks)
            cpu_after = newest_diagnostics(time.monotonic(), 'after the run')
            result.split = {name: cpu_split(cpu_before[name][0], cpu_after[name][0]) for name in cpu_after}
            fitter_counts = cpu_after.get('skeleton_fitter', ({}, {}, {}))[2]
            before_counts = cpu_before.get('skeleton_fitter', ({}, {}, {}))[2]
            result.skipped = (int(fitter_counts.get('frame sets skipped (stale)', 0))
                              - int(before_counts.get('frame sets skipped (stale)', 0)))
        finally:
            node.destroy_node()
            launch.stop()
    if stop.stopped:
        raise KeyboardInterrupt
    return result


def soak_sample(result, finished, period, pids, started):
    """A SoakSample now: the nodes' RSS, and the median latency of the last `period` of the `finished`
    frame sets (stamps, in the order they were answered)."""
    latencies = [1e3 * (result.skeletons[s][0] - result.sent[s]) for s in finished[-period:] if s in result.skeletons]
    return SoakSample(len(finished), time.monotonic() - started,
                      {name: resident_mib(pid) for name, pid in pids.items()}, median_p95(latencies)[0])


def camera_messages(bag, camera):
    """[(topic, message)]: camera `camera`'s first compressed image with a person in the bag, and the
    messages its camera_features node publishes for it (silhouette raw and PNG, contour, ellipses)."""
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import CompressedImage
    from std_msgs.msg import Header
    from mvpose_nodes.app.features import make_extractor
    from mvpose_nodes.ros.conversions import feature_messages, image_from_compressed, mono_image, png_mono

    extractor = make_extractor(None, None)
    for _, views in load_frame_sets(bag, (camera,))[1]:
        image = deserialize_message(views[camera], CompressedImage)
        features = extractor(image_from_compressed(image))
        if features.person:
            ellipses, contour = feature_messages(features, image.header)
            mask = features.silhouette.astype(np.uint8) * 255
            base = f'/cam{camera}'
            return [('(a bare std_msgs/Header)', Header(frame_id=image.header.frame_id)),
                    (f'{base}/image_raw/compressed', image),
                    (f'{base}/silhouette', mono_image(mask, image.header)),
                    (f'{base}/silhouette/compressed', png_mono(mask, image.header)),
                    (f'{base}/labelled_contour', contour),
                    (f'{base}/skin_ellipses', ellipses)]
    raise UserError(f"bag '{bag}': camera {camera} sees no person in any image")


def run_transport(bag):
    from mvpose_nodes.ros.helpers import StopSignal
    from mvpose_nodes.tools.transport import format_transport, measure
    messages = camera_messages(bag, GRAPH_CAMERAS[0])
    print(f'[bench] {TRANSPORT_ROUND_TRIPS} round trips of each of {len(messages)} messages through an echo process',
          file=sys.stderr, flush=True)
    with StopSignal() as stop:
        results = measure(messages, TRANSPORT_ROUND_TRIPS, stop)
    return format_transport(results)


def main(argv=None, prog='bench'):
    parser = ArgumentParser(prog=prog, description=__doc__.split('\n\n')[0])
    parser.add_argument('bag', nargs='?', type=Path, help=f'camera bag with cameras 3, 5, 7 (default {DEFAULT_BAG})')
    parser.add_argument('--window', type=int, default=DEFAULT_WINDOW,
                        help=f'frame sets in flight at most (default {DEFAULT_WINDOW})')
    parser.add_argument('--rate', type=float, metavar='R',
                        help="open loop: send each frame set at its time in the bag / R (1.0: the bag's own speed), "
                             'whatever the graph does (default: closed loop, --window)')
    parser.add_argument('--frames', type=int, help='use only the first N frame sets (default all)')
    parser.add_argument('--all-cameras', action='store_true',
                        help='the graph of all 8 cameras (launch/mvpose8.launch.yaml) on a bag that has them, '
                             'instead of cameras 3, 5, 7')
    parser.add_argument('-o', '--output', type=Path, metavar='RUN',
                        help='also record the fitted skeletons to this bag (at --rate 1.0: the frame sets the fitter '
                             'took), for `./mvpose eval RUN --truth BAG` (Table 2, Eq. 12 per frame set, swaps)')
    parser.add_argument('--transport', action='store_true',
                        help="instead of running the graph: size, serialisation and DDS round trip of a camera's "
                             'messages (image in; silhouette raw and PNG, contour, ellipses out)')
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    with exit_on_user_error(prog):
        if args.window < 1:
            raise UserError(f'--window must be at least 1 (got {args.window})')
        if args.rate is not None and not args.rate > 0:
            raise UserError(f'--rate must be above 0 (got {args.rate})')
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
        if args.output is not None and args.output.exists():
            raise UserError(f"output bag '{args.output}' already exists; choose another -o or remove it")
        if args.transport:
            print(run_transport(bag), flush=True)
            return 0
        result = run_bench(bag, args.window, args.rate, args.frames, root / 'output' / 'bench' / 'graph.log',
                           cameras=ALL_CAMERAS if args.all_cameras else GRAPH_CAMERAS,
                           keep_messages=args.output is not None)
        if bag.is_relative_to(root):
            result.bag = str(bag.relative_to(root))
        print(format_table(result), flush=True)
        if args.output is not None:
            write_run_bag(GraphRun(fitted=result.messages), args.output)
            print(f'[bench] the {len(result.messages)} fitted skeletons -> {args.output} '
                  f'(`./mvpose eval {args.output} --truth {result.bag}`)', file=sys.stderr, flush=True)
    # Closed loop every frame set must be fitted; open loop, skipping is the point and the table says how much.
    return 0 if args.rate is not None or len(result.skeletons) == result.frame_sets else 1


def soak_main(argv=None, prog='soak'):
    parser = ArgumentParser(prog=prog, description='Loop a bag through the graph for a long run (see `bench --help`): '
                                                   "each node's memory and the latency over time, and every frame "
                                                   'set not fitted.')
    parser.add_argument('bag', nargs='?', type=Path, help=f'camera bag with cameras 3, 5, 7 (default {DEFAULT_BAG})')
    parser.add_argument('--frame-sets', type=int, default=SOAK_FRAME_SETS, metavar='N',
                        help=f'frame sets to send, the bag looped (default {SOAK_FRAME_SETS})')
    parser.add_argument('--sample-every', type=int, default=SOAK_SAMPLE_EVERY, metavar='N',
                        help=f'frame sets between two samples of memory and latency (default {SOAK_SAMPLE_EVERY})')
    parser.add_argument('--warm-up', type=int, default=SOAK_WARM_UP, metavar='N',
                        help=f'frame sets before memory growth is counted (default {SOAK_WARM_UP})')
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    with exit_on_user_error(prog):
        if min(args.frame_sets, args.sample_every) < 1 or args.warm_up < 0:
            raise UserError('--frame-sets and --sample-every must be at least 1, --warm-up not negative')
        from mvpose_nodes.app.main import repository_root
        root = repository_root()
        bag = args.bag or root / DEFAULT_BAG
        if not bag.exists():
            raise UserError(f"bag '{bag}' not found" + ('' if args.bag else f': run {MAKE_DEFAULT_BAG}'))
        result = run_bench(bag, DEFAULT_WINDOW, None, None, root / 'output' / 'soak' / 'graph.log',
                           total=args.frame_sets, sample_every=args.sample_every)
        print(format_soak(result, args.warm_up), flush=True)
    # Passed over and skipped frame sets are the fitter keeping to the newest (on purpose), lost ones its answer
    # that it lost the person; dropped ones got no answer at all.
    return 0 if result.dropped == 0 and len(result.sent) == result.frame_sets else 1


if __name__ == '__main__':
    sys.exit(main())
