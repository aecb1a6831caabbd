"""`./mvpose demo`: replay a skeleton bag over DDS and show what arrives, frame by frame.

This is the foundation's demo: it proves the path bag -> `bag play` -> DDS -> subscriber with
a small generated bag (`bags/demo_skeleton`: a procedurally swinging walk of the 15-joint
skeleton). The full demo (camera bag through the feature and fitting nodes) replaces it when
those nodes exist.
"""
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from mvpose_nodes.body_model import JOINT_NAMES
from mvpose_nodes.errors import ArgumentParser, exit_on_user_error

SKELETON_TOPIC = '/mvpose/skeleton'
FRAME_RATE = 25.0  # [Hz] i3DPost's
START_NS = 1_700_000_000_000_000_000

# A standing person facing +x (metres; z up, floor z = 0, left = +y), the joints of JOINT_NAMES.
STANDING_POSE = {
    'pelvis': (0.0, 0.0, 0.95), 'left_hip': (0.0, 0.09, 0.95), 'left_knee': (0.0, 0.10, 0.52),
    'left_ankle': (0.0, 0.10, 0.08), 'right_hip': (0.0, -0.09, 0.95), 'right_knee': (0.0, -0.10, 0.52),
    'right_ankle': (0.0, -0.10, 0.08), 'neck': (0.0, 0.0, 1.45), 'head': (0.0, 0.0, 1.72),
    'left_shoulder': (0.0, 0.19, 1.43), 'left_elbow': (0.0, 0.21, 1.15), 'left_wrist': (0.0, 0.22, 0.90),
    'right_shoulder': (0.0, -0.19, 1.43), 'right_elbow': (0.0, -0.21, 1.15), 'right_wrist': (0.0, -0.22, 0.90),
}
# Limbs that swing about their root joint while walking: (root, moved joints, phase sign).
SWINGING_LIMBS = (('left_hip', ('left_knee', 'left_ankle'), 1), ('right_hip', ('right_knee', 'right_ankle'), -1),
                  ('left_shoulder', ('left_elbow', 'left_wrist'), -1),
                  ('right_shoulder', ('right_elbow', 'right_wrist'), 1))
WALK_SPEED = 1.2  # [m/s]
STRIDE_FREQUENCY = 0.9  # [Hz]
SWING_AMPLITUDE = math.radians(20)


def walking_pose(t):
    """Joint positions [m] (15×3 float64, JOINT_NAMES order) of the demo walk at time t [s]."""
    joints = {name: np.array(position) for name, position in STANDING_POSE.items()}
    angle = SWING_AMPLITUDE * math.sin(2 * math.pi * STRIDE_FREQUENCY * t)
    for root, moved, sign in SWINGING_LIMBS:
        c, s = math.cos(sign * angle), math.sin(sign * angle)
        rotation = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])  # about the y axis (sideways)
        for name in moved:
            joints[name] = joints[root] + rotation @ (joints[name] - joints[root])
    offset = np.array([WALK_SPEED * t - 2.0, 0.0, 0.0])
    return np.array([joints[name] + offset for name in JOINT_NAMES])


def skeleton_message(positions, stamp_ns):
    from geometry_msgs.msg import Pose
    from mvpose_msgs.msg import Skeleton
    msg = Skeleton(joint_names=list(JOINT_NAMES), status=Skeleton.STATUS_OK)
    msg.header.frame_id = 'world'
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 10**9)
    for position in positions:
        pose = Pose()
        pose.position.x, pose.position.y, pose.position.z = map(float, position)
        pose.orientation.w = 1.0
        msg.joints.append(pose)
    return msg


def write_demo_bag(path, frames):
    from rclpy.serialization import serialize_message
    from mvpose_nodes.bagfile import BagWriter
    with BagWriter(path) as bag:
        bag.add_topic(SKELETON_TOPIC, 'mvpose_msgs/msg/Skeleton')
        for frame in range(frames):
            stamp_ns = START_NS + int(frame * 1e9 / FRAME_RATE)
            bag.write(SKELETON_TOPIC, serialize_message(skeleton_message(walking_pose(frame / FRAME_RATE), stamp_ns)),
                      stamp_ns)


def main(argv=None, prog='demo'):
    parser = ArgumentParser(prog=prog, description=__doc__.splitlines()[0])
    parser.add_argument('--bag', type=Path, help='skeleton bag to replay (default: bags/demo_skeleton, made if missing)')
    parser.add_argument('--frames', type=int, default=100, help='frames of a newly made demo bag (default 100)')
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    with exit_on_user_error(prog):
        from mvpose_nodes.cli import repository_root
        bag = args.bag or repository_root() / 'bags' / 'demo_skeleton'
        if not bag.exists():
            print(f'[demo] making {bag} ({args.frames} frames at {FRAME_RATE:g} fps)', flush=True)
            write_demo_bag(bag, args.frames)
        return replay_and_show(bag)


def replay_and_show(bag):
    import rclpy
    from mvpose_msgs.msg import Skeleton
    from mvpose_nodes.bagfile import BagReader
    from mvpose_nodes.rosutil import StopSignal

    expected = BagReader(bag).topics[SKELETON_TOPIC].message_count
    head, pelvis = JOINT_NAMES.index('head'), JOINT_NAMES.index('pelvis')
    received = []

    def show(msg):
        received.append(msg)
        t = (msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec - START_NS) / 1e9
        p, h = msg.joints[pelvis].position, msg.joints[head].position
        print(f'[demo] frame {len(received):3d}/{expected}  t={t:5.2f} s  pelvis=({p.x:+.2f}, {p.y:+.2f}, {p.z:.2f}) m'
              f'  head z={h.z:.2f} m', flush=True)

    with StopSignal() as stop:
        node = rclpy.create_node('mvpose_demo_viewer')
        node.create_subscription(Skeleton, SKELETON_TOPIC, show, 100)
        print(f'[demo] replaying {bag} with `bag play`; receiving {SKELETON_TOPIC} over DDS', flush=True)
        player = subprocess.Popen([sys.executable, '-m', 'mvpose_nodes.cli', 'bag', 'play', str(bag),
                                   '--topics', SKELETON_TOPIC, '--wait-for-subscribers', '--delay', '0.3'])
        while player.poll() is None and not stop.stopped:
            rclpy.spin_once(node, timeout_sec=0.05)
        deadline = time.monotonic() + 1.0
        while len(received) < expected and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.05)
        if player.poll() is None:
            player.terminate()
        node.destroy_node()
    print(f'[demo] shown: {len(received)} of {expected} skeletons of {bag} crossed DDS from `bag play` to this '
          'viewer (`./mvpose topic echo /mvpose/skeleton` shows the same while a bag plays).')
    return 0 if len(received) == expected else 1
