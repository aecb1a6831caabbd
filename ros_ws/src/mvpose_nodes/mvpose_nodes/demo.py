"""`./mvpose demo`: replay the synthetic i3DPost walk over DDS and show the skeleton that arrives.

Makes `bags/i3dpost_walk_synth` (cameras 3, 5, 7, frames 52–101, 1080p) when it is missing,
plays it with `bag play`, prints a line per frame for each skeleton received on
/mvpose/ground_truth, and draws the skeleton over all the bag's cameras at the first frame.
The fitting nodes join this demo when they exist (the skeleton will then be /mvpose/skeleton).
"""
import subprocess
import sys
import time
from pathlib import Path

from mvpose_nodes.body_model import JOINT_NAMES
from mvpose_nodes.errors import ArgumentParser, exit_on_user_error

DEMO_BAG = Path('bags/i3dpost_walk_synth')
DEMO_SYNTH_ARGUMENTS = ('--cameras', '3', '5', '7', '--frames', '52-101')
OUTPUT = Path('output/demo')


def main(argv=None, prog='demo'):
    parser = ArgumentParser(prog=prog, description=__doc__.split('\n\n')[0])
    parser.add_argument('--bag', type=Path, help=f'camera bag to replay (default {DEMO_BAG}, made if missing)')
    parser.add_argument('-o', '--output', type=Path, help=f'folder for the pictures (default {OUTPUT})')
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    with exit_on_user_error(prog):
        from mvpose_nodes.cli import repository_root
        root = repository_root()
        bag = args.bag or root / DEMO_BAG
        if not bag.exists():
            print(f'[demo] making {bag} with `./mvpose synth {" ".join(DEMO_SYNTH_ARGUMENTS)}` (about a minute)',
                  flush=True)
            tool(['synth', *DEMO_SYNTH_ARGUMENTS, '-o', str(bag)])
        output = args.output or root / OUTPUT
        received = replay_and_show(bag)
        sheet = output / f'{bag.name}_preview.png'
        tool(['preview', str(bag), '-o', str(sheet)])
        print(f'[demo] shown: {received[0]} of {received[1]} skeletons of {bag} crossed DDS from `bag play` to this '
              f'viewer; the skeleton over every camera of the first frame is in {sheet}.')
        return 0 if received[0] == received[1] else 1


def tool(arguments):
    """Run another ./mvpose subcommand in this environment; stop the demo if it fails."""
    result = subprocess.run([sys.executable, '-m', 'mvpose_nodes.cli', *arguments])
    if result.returncode != 0:
        sys.exit(result.returncode)


def replay_and_show(bag):
    """Play `bag`, print every skeleton that arrives; (received, expected)."""
    import rclpy
    from mvpose_msgs.msg import Skeleton
    from mvpose_nodes.bagfile import BagReader
    from mvpose_nodes.camera_bag import GROUND_TRUTH_TOPIC, frame_number_of
    from mvpose_nodes.rosconv import joints_from_skeleton, stamp_ns
    from mvpose_nodes.rosutil import StopSignal

    reader = BagReader(bag)
    expected = reader.topics[GROUND_TRUTH_TOPIC].message_count if GROUND_TRUTH_TOPIC in reader.topics else 0
    head, pelvis = JOINT_NAMES.index('head'), JOINT_NAMES.index('pelvis')
    received = []

    def show(msg):
        received.append(msg)
        joints = joints_from_skeleton(msg)
        p = joints[pelvis]
        print(f'[demo] frame {frame_number_of(stamp_ns(msg.header)):4d}  ({len(received):2d}/{expected})  '
              f'pelvis=({p[0]:+.2f}, {p[1]:+.2f}, {p[2]:.2f}) m  head z={joints[head][2]:.2f} m', flush=True)

    with StopSignal() as stop:
        node = rclpy.create_node('mvpose_demo_viewer')
        node.create_subscription(Skeleton, GROUND_TRUTH_TOPIC, show, 100)
        print(f'[demo] replaying {bag} ({", ".join(sorted(reader.topics))}) with `bag play`', flush=True)
        player = subprocess.Popen([sys.executable, '-m', 'mvpose_nodes.cli', 'bag', 'play', str(bag),
                                   '--topics', GROUND_TRUTH_TOPIC, '--wait-for-subscribers', '--delay', '0.3'])
        while player.poll() is None and not stop.stopped:
            rclpy.spin_once(node, timeout_sec=0.05)
        deadline = time.monotonic() + 1.0
        while len(received) < expected and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.05)
        if player.poll() is None:
            player.terminate()
        node.destroy_node()
    return len(received), expected
