"""Messages with seeded random content, for tests that check values survive a trip."""
import numpy as np

from mvpose_nodes.body.model import JOINT_NAMES, PARAMETER_NAMES, STAGE_NAMES


def sample_skeleton(seed, stamp_ns=1_700_000_000_000_000_000):
    """A fully populated mvpose_msgs/Skeleton: 15 joints, 29 parameters, 6 stages."""
    from geometry_msgs.msg import Pose
    from mvpose_msgs.msg import FitStage, Skeleton
    rng = np.random.default_rng(seed)
    msg = Skeleton()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 10**9)
    msg.header.frame_id = 'world'
    msg.joint_names = list(JOINT_NAMES)
    for _ in JOINT_NAMES:
        pose = Pose()
        pose.position.x, pose.position.y, pose.position.z = rng.uniform(-2, 2, 3).tolist()
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = q.tolist()
        msg.joints.append(pose)
    msg.parameter_names = list(PARAMETER_NAMES)
    msg.parameters = rng.uniform(-np.pi, np.pi, len(PARAMETER_NAMES)).tolist()
    msg.stages = [FitStage(name=name, cost=float(rng.uniform(0, 500)), evaluations=int(rng.integers(10, 900)),
                           cameras=[3, 5, 7], fitted=bool(rng.integers(0, 2))) for name in STAGE_NAMES]
    msg.status = Skeleton.STATUS_DEGRADED
    msg.status_message = f'sample {seed}'
    msg.fit_time = float(rng.uniform(0, 1))
    return msg
