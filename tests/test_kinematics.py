"""The 29-DOF body model: forward kinematics, and joint angles back from 3D joints by paper 004's exact
method (and the older constrained method shown worse)."""
import numpy as np
import pytest

from mvpose_nodes.body.model import PARAMETER_NAMES
from mvpose_nodes.body.geometry import (cross, matrix_from_quaternion, normalize, quaternion_from_matrix,
                                        rotation_between)
from mvpose_nodes.body.kinematics import (BONES, JOINT_INDEX, PARAMETER_INDEX, bone_lengths, euler_from_quaternion,
                                     euler_matrix, forward_kinematics, inverse_kinematics, lengths_of)

pytestmark = pytest.mark.pure


def constrained_euler(direction, zero_angle):
    """The older IK step that paper 004 improves on: the Euler angles (rx, ry, rz) that turn a limb's
    rest direction −Z into `direction` with one angle forced to zero (zero_angle 'rx' or 'ry').
    The direction comes out right, but the limb's twist about itself, and so where a hinge child
    bends, generally does not."""
    d = normalize(direction)
    tilt = np.arccos(np.clip(-d[2], -1.0, 1.0))  # angle from straight down
    if zero_angle == 'rx':   # Rz·Ry·(0, 0, −1) = (−cos rz sin ry, −sin rz sin ry, −cos ry)
        return 0.0, tilt, float(np.arctan2(-d[1], -d[0]))
    # Rz·Rx·(0, 0, −1) = (−sin rz sin rx, cos rz sin rx, −cos rx)
    return tilt, 0.0, float(np.arctan2(-d[0], d[1]))


LENGTHS = bone_lengths(1.75)


def rest_parameters():
    parameters = np.zeros(len(PARAMETER_NAMES))
    parameters[PARAMETER_INDEX['torso_z']] = 0.93
    return parameters


def random_twist_free_pose(rng):
    """Random parameters whose 3-DOF limb rotations are the smallest rotations taking the rest
    direction to a random direction (their twist is what joint positions cannot show)."""
    parameters = rest_parameters()
    parameters[[PARAMETER_INDEX['torso_x'], PARAMETER_INDEX['torso_y']]] = rng.uniform(-1, 1, 2)
    parameters[[PARAMETER_INDEX['torso_rx'], PARAMETER_INDEX['torso_ry'], PARAMETER_INDEX['torso_rz']]] = rng.uniform(-0.4, 0.4, 3) * [1, 1, 6]
    for bone in BONES:
        if len(bone.angles) == 3 and bone.angles[0] is not None and bone.name != 'torso':
            direction = np.array(bone.rest) + rng.uniform(-0.8, 0.8, 3)
            parameters[[PARAMETER_INDEX[n] for n in bone.angles]] = euler_from_quaternion(rotation_between(bone.rest, direction))
        elif len(bone.angles) == 1:
            parameters[PARAMETER_INDEX[bone.angles[0]]] = rng.uniform(0.05, 1.8) * (-1 if 'shin' in bone.name else 1)
        elif bone.angles:
            parameters[[PARAMETER_INDEX[bone.angles[1]], PARAMETER_INDEX[bone.angles[2]]]] = rng.uniform(-0.3, 0.3, 2)
    return parameters


def test_rest_pose_is_upright_and_sized_by_height():
    joints, _ = forward_kinematics(rest_parameters(), LENGTHS)
    assert joints[JOINT_INDEX['head'], 2] - joints[JOINT_INDEX['left_ankle'], 2] == pytest.approx(1.75 * (1 - 0.039), abs=1e-9)
    assert joints[JOINT_INDEX['left_hip'], 0] < joints[JOINT_INDEX['right_hip'], 0], 'left is −X (the model faces +Y, right is +X)'
    assert np.allclose(joints[JOINT_INDEX['left_wrist'], :2], joints[JOINT_INDEX['left_shoulder'], :2])


def test_euler_matrix_and_quaternion_conversion_agree_including_gimbal_lock():
    rng = np.random.default_rng(0)
    for angles in list(rng.uniform(-3, 3, (50, 3))) + [(0.3, np.pi / 2, -0.7), (1.1, -np.pi / 2, 0.4)]:
        R = euler_matrix(*angles)
        assert np.allclose(euler_matrix(*euler_from_quaternion(quaternion_from_matrix(R))), R, atol=1e-9)


@pytest.mark.parametrize('seed', range(20))
def test_random_poses_forward_then_inverse_give_back_the_same_rotations(seed):
    parameters = random_twist_free_pose(np.random.default_rng(seed))
    joints, frames = forward_kinematics(parameters, LENGTHS)
    recovered = inverse_kinematics(joints)
    joints_again, frames_again = forward_kinematics(recovered, LENGTHS)
    assert np.allclose(joints_again, joints, atol=1e-9)
    for bone in BONES:
        assert np.allclose(frames_again[bone.name], frames[bone.name], atol=1e-9), bone.name


def test_the_older_constrained_method_is_worse():
    """Paper 004's point: forcing an Euler angle to zero gets a limb's direction but not its twist, so
    the hinge below it bends in the wrong plane. Measured on the wrists and ankles of random poses."""
    rng = np.random.default_rng(42)
    exact, constrained = [], []
    for _ in range(30):
        parameters = random_twist_free_pose(rng)
        joints, frames = forward_kinematics(parameters, LENGTHS)
        recovered = inverse_kinematics(joints)
        older = recovered.copy()
        for limb in ('left_thigh', 'right_thigh', 'left_upper_arm', 'right_upper_arm'):
            bone = BONES[[b.name for b in BONES].index(limb)]
            local = frames['torso'].T @ (joints[JOINT_INDEX[bone.joint]] - joints[JOINT_INDEX[bone.parent_joint]])
            older[[PARAMETER_INDEX[n] for n in bone.angles]] = constrained_euler(local, 'rx' if 'arm' in limb else 'ry')
        ends = [JOINT_INDEX[n] for n in ('left_wrist', 'right_wrist', 'left_ankle', 'right_ankle')]
        exact.append(np.abs(forward_kinematics(recovered, LENGTHS)[0][ends] - joints[ends]).max())
        constrained.append(np.abs(forward_kinematics(older, LENGTHS)[0][ends] - joints[ends]).max())
    assert max(exact) < 1e-9
    assert np.median(constrained) > 0.01, 'centimetres off at the wrists and ankles'


def test_constrained_method_still_gets_the_limb_direction():
    for zero in ('rx', 'ry'):
        direction = np.array([0.3, -0.5, -0.7])
        rotation = euler_matrix(*constrained_euler(direction, zero))
        assert np.allclose(rotation @ [0, 0, -1], direction / np.linalg.norm(direction), atol=1e-12)


def test_parallel_and_antiparallel_bones():
    joints, _ = forward_kinematics(rest_parameters(), LENGTHS)
    assert np.allclose(inverse_kinematics(joints)[3:], 0, atol=1e-12), 'rest pose: every angle zero'
    raised = joints.copy()   # left arm straight up: anti-parallel to its rest direction
    shoulder = raised[JOINT_INDEX['left_shoulder']]
    raised[JOINT_INDEX['left_elbow']] = shoulder + [0, 0, LENGTHS['upper_arm']]
    raised[JOINT_INDEX['left_wrist']] = shoulder + [0, 0, LENGTHS['upper_arm'] + LENGTHS['forearm']]
    again, _ = forward_kinematics(inverse_kinematics(raised), LENGTHS)
    assert np.allclose(again, raised, atol=1e-9)


@pytest.mark.parametrize('shape', [(3,), (7, 3), (2, 5, 3)])
def test_the_vector_helpers_compute_as_numpy_does_to_the_bit(shape):
    """cross and normalize skip NumPy's general routines for speed: the same numbers, single or batched."""
    rng = np.random.default_rng(len(shape))
    a, b = rng.normal(size=shape), rng.normal(size=shape)
    assert np.array_equal(cross(a, b), np.cross(a, b))
    assert np.array_equal(normalize(a), a / np.linalg.norm(a, axis=-1, keepdims=True))
    assert np.array_equal(normalize(np.zeros(shape)), np.zeros(shape))
    q = rng.normal(size=shape[:-1] + (4,))
    batch = matrix_from_quaternion(q).reshape(-1, 3, 3)
    assert np.array_equal(batch, [matrix_from_quaternion(one) for one in q.reshape(-1, 4)])
    assert np.allclose(batch @ batch.transpose(0, 2, 1), np.eye(3), atol=1e-12)
    rows_a, rows_b = a.reshape(-1, 3), b.reshape(-1, 3).copy()
    rows_b[0], rows_b[-1] = (2.0 if len(rows_b) > 1 else -3.0) * rows_a[0], -3.0 * rows_a[-1]   # (anti-)parallel
    batch = rotation_between(rows_a, rows_b)
    assert np.array_equal(batch, [rotation_between(x, y) for x, y in zip(rows_a, rows_b)])
    assert np.allclose(np.linalg.norm(batch, axis=-1), 1.0, atol=1e-12)


def test_lengths_of_random_poses_are_the_bone_lengths_left_and_right_averaged():
    rng = np.random.default_rng(3)
    lengths = {key: value * rng.uniform(0.9, 1.1) for key, value in LENGTHS.items()}
    joints = np.array([forward_kinematics(random_twist_free_pose(rng), lengths)[0] for _ in range(5)])
    joints[2] = np.nan   # a frame without a skeleton does not count
    assert lengths_of(joints) == pytest.approx(lengths, abs=1e-9)
    longer = joints.copy()
    longer[:, JOINT_INDEX['left_wrist']] += 0.1 * (longer[:, JOINT_INDEX['left_wrist']] - longer[:, JOINT_INDEX['left_elbow']])
    assert lengths_of(longer)['forearm'] == pytest.approx(lengths['forearm'] * 1.05, abs=1e-9)
