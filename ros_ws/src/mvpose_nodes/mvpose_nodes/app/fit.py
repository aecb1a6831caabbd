"""`fit BAG -o OUT` and `eval RECORDED_BAG [--truth BAG]`: the skeleton fitted offline, and its accuracy.

fit runs the camera features and the skeleton fitter of the node graph on every frame of a camera
bag, without ROS, and records /mvpose/skeleton (and the bag's /mvpose/ground_truth, if any) to OUT.
eval matches a recorded /mvpose/skeleton with /mvpose/ground_truth by stamp and prints paper 000's
Table 2 layout (per joint: mean and std of |ΔX|, |ΔY|, |ΔZ| and the mean Euclidean error, in mm),
the mean of Eq. 12 (the per-frame mean joint error) beside the paper's own numbers, and left/right
limb swaps.
"""
import sys
from pathlib import Path

import numpy as np

from mvpose_nodes.tools.cli import ArgumentParser, UserError, exit_on_user_error


def build_parser(prog):
    parser = ArgumentParser(prog=prog, description=__doc__.split('\n\n')[0])
    parser.add_argument('bag', type=Path, help='camera bag (fit) or recorded output bag (eval)')
    return parser


def fit_main(argv=None, prog='fit'):
    parser = build_parser(prog)
    parser.add_argument('-o', '--output', type=Path, required=True, help='bag to write /mvpose/skeleton to')
    parser.add_argument('--cameras', type=int, nargs='+', default=[3, 5, 7], metavar='K',
                        help='cameras to fit from (default 3 5 7)')
    parser.add_argument('--profile', type=int, default=0, metavar='N',
                        help='after fitting, print the N functions where the fitter spent most time')
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    with exit_on_user_error(prog):
        fit_bag(args)
    return 0


def fit_bag(args):
    from mvpose_msgs.msg import Skeleton
    from rclpy.serialization import serialize_message
    from mvpose_nodes.io.bagfile import BagWriter
    from mvpose_nodes.body.model import PARAMETER_NAMES
    from mvpose_nodes.ros.camera_bag import GROUND_TRUTH_TOPIC, SKELETON_TOPIC, STREAM_QOS, cameras_in, frame_sets
    from mvpose_nodes.app.features import count_images, make_extractor
    from mvpose_nodes.fitting.fitter import SkeletonFitter
    from mvpose_nodes.fitting.views import view_from_features
    from mvpose_nodes.vision.features import ROLE_FACE, ellipse_top
    from mvpose_nodes.app.progress import Progress
    from mvpose_nodes.ros.conversions import skeleton_message, stage_messages

    cameras_in(args.bag, args.cameras)
    extractors = {k: make_extractor(None, None) for k in args.cameras}
    fitter = SkeletonFitter()
    progress = Progress(count_images(args.bag, args.cameras) // len(args.cameras), 'fit')
    fit_times = []
    profiler = None
    if args.profile:
        import cProfile
        profiler = cProfile.Profile()
    with BagWriter(args.output) as out:
        out.add_topic(SKELETON_TOPIC, 'mvpose_msgs/msg/Skeleton', [STREAM_QOS])
        out.add_topic(GROUND_TRUTH_TOPIC, 'mvpose_msgs/msg/Skeleton', [STREAM_QOS])
        for frame_set in frame_sets(args.bag, args.cameras):
            if not frame_set.images:
                continue
            views = []
            for number in sorted(frame_set.images):
                features = extractors[number](frame_set.images[number])
                if features.person:
                    skin = [(*e.center, e.area) for e in features.ellipses]
                    faces = [ellipse_top(e.center[1], e.semi_major, e.semi_minor, e.angle)
                             for e in features.ellipses if e.role == ROLE_FACE]
                    views.append(view_from_features(frame_set.cameras[number], features.visible_keypoints(),
                                                    features.contour, features.frontness, skin,
                                                    faces[0] if faces else None))
            try:
                if profiler:
                    profiler.enable()
                fit = fitter.fit(frame_set.stamp_ns / 1e9, views)
            except ValueError as error:
                print(f'[fit] frame {frame_set.frame}: {error}', file=sys.stderr)
                continue
            finally:
                if profiler:
                    profiler.disable()
            fit_times.append(fit.seconds)
            message = skeleton_message(fit.joints, frame_set.stamp_ns, parameter_names=list(PARAMETER_NAMES),
                                       parameters=fit.parameters.tolist(), stages=stage_messages(fit.stages),
                                       status=Skeleton.STATUS_INITIALISING if fit.initialised else Skeleton.STATUS_OK,
                                       fit_time=fit.seconds)
            out.write(SKELETON_TOPIC, serialize_message(message), frame_set.stamp_ns)
            if frame_set.truth is not None:
                out.write(GROUND_TRUTH_TOPIC, serialize_message(skeleton_message(frame_set.truth, frame_set.stamp_ns)),
                          frame_set.stamp_ns)
            progress.update()
    progress.close()
    if profiler:
        import pstats
        pstats.Stats(profiler, stream=sys.stdout).sort_stats('cumulative').print_stats(args.profile)
    if fit_times:
        print(f'[fit] {len(fit_times)} frames; fit time per frame median {1e3 * np.median(fit_times):.0f} ms '
              f'({1 / np.median(fit_times):.1f} fits/s, features excluded) -> {args.output}', file=sys.stderr)


def eval_main(argv=None, prog='eval'):
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ['suite']:   # `eval suite`: randomised studio cases (a bag named suite: ./suite)
        from mvpose_nodes.app.suite import main
        return main(argv[1:], prog=f'{prog} suite')
    if argv[:1] == ['compare']:   # `eval compare`: two suite runs case by case
        from mvpose_nodes.app.suite.compare import main
        return main(argv[1:], prog=f'{prog} compare')
    parser = build_parser(prog)
    compared = parser.add_mutually_exclusive_group()
    compared.add_argument('--truth', type=Path, help='bag with /mvpose/ground_truth (default: the recorded bag)')
    compared.add_argument('--against', type=Path, metavar='OTHER_RUN',
                          help="another recorded run's bag: how far its /mvpose/skeleton is from this one's, "
                               'frame set by frame set (is the graph repeatable?)')
    parser.epilog = ('`eval suite --help`: the fitter over randomised studio cases instead of one bag; '
                     '`eval compare --help`: two suite runs case by case.')
    args = parser.parse_args(argv)
    with exit_on_user_error(prog):
        from mvpose_nodes.app.reports.accuracy import print_table_2
        from mvpose_nodes.ros.camera_bag import GROUND_TRUTH_TOPIC, SKELETON_TOPIC
        if args.against:
            return print_run_difference(args.bag, args.against)
        fitted = skeletons(args.bag, SKELETON_TOPIC)
        truth = skeletons(args.truth or args.bag, GROUND_TRUTH_TOPIC)
        stamps = sorted(set(fitted) & set(truth))
        if not stamps:
            raise UserError(f"no stamp has both a fitted skeleton ({args.bag}) and a ground truth "
                            f"({args.truth or args.bag})")
        print_table_2(np.array([fitted[s] for s in stamps]), np.array([truth[s] for s in stamps]), args.bag)
    return 0


def print_run_difference(run, other):
    """Print how far two recorded runs' /mvpose/skeleton are apart: the largest joint distance [mm] over
    the frame sets both have, and the frame sets only one of them has."""
    from mvpose_nodes.ros.camera_bag import SKELETON_TOPIC
    mine, theirs = skeletons(run, SKELETON_TOPIC), skeletons(other, SKELETON_TOPIC)
    common = sorted(set(mine) & set(theirs))
    if not common:
        raise UserError(f"'{run}' and '{other}' have no frame set (stamp) in common")
    distances = np.array([np.linalg.norm(mine[s] - theirs[s], axis=1).max() for s in common]) * 1e3
    worst = common[int(np.argmax(distances))]
    print(f'eval: {run} against {other}: {len(common)} frame sets in both, {len(set(mine) - set(theirs))} only in '
          f'the first, {len(set(theirs) - set(mine))} only in the second')
    print(f'  largest joint distance: {distances.max():.3f} mm (stamp {worst} ns); mean of the per-frame-set '
          f'largest {distances.mean():.3f} mm; frame sets over 1 mm: {int((distances > 1.0).sum())}')
    return 0


def skeletons(bag_path, topic):
    """{stamp_ns: joints (15, 3)} of one skeleton topic of a bag."""
    from rclpy.serialization import deserialize_message
    from mvpose_msgs.msg import Skeleton
    from mvpose_nodes.io.bagfile import BagReader
    from mvpose_nodes.ros.conversions import joints_from_skeleton, stamp_ns
    bag = BagReader(bag_path)
    if topic not in bag.topics:
        raise UserError(f"bag '{bag_path}' has no {topic}")
    found = {}
    for _, _, data in bag.messages(topics=[topic]):
        message = deserialize_message(data, Skeleton)
        found[stamp_ns(message.header)] = joints_from_skeleton(message)
    return found
