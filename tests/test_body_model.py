"""Body-model names, labels and joint frames; paper 004's rotation between bone vectors. The labels
against the message constants: test_messages.py."""
import numpy as np
import pytest

from mvpose_nodes.body import model
from mvpose_nodes.body.geometry import matrix_from_quaternion, quaternion_from_matrix, rotation_about, rotation_between

pytestmark = pytest.mark.pure


def test_model_sizes_follow_paper_table_1():
    assert len(model.JOINT_NAMES) == 15 and len(model.BONES) == 14
    assert len(model.PARAMETER_NAMES) == 29 and len(set(model.PARAMETER_NAMES)) == 29
    assert {j for bone in model.BONES for j in bone} == set(model.JOINT_NAMES)


@pytest.mark.parametrize('seed', range(5))
def test_rotation_between_takes_r_to_r_prime(seed):
    rng = np.random.default_rng(seed)
    r, r_prime = rng.normal(size=3), rng.normal(size=3)
    rotated = matrix_from_quaternion(rotation_between(r, r_prime)) @ r
    assert np.allclose(rotated / np.linalg.norm(rotated), r_prime / np.linalg.norm(r_prime), atol=1e-12)


def test_rotation_between_parallel_and_antiparallel():
    r = np.array([0.3, -0.2, 0.9])
    assert np.allclose(rotation_between(r, 2 * r), [0, 0, 0, 1])
    half_turn = matrix_from_quaternion(rotation_between(r, -r))
    assert np.allclose(half_turn @ r, -r, atol=1e-12)
    assert np.isclose(np.linalg.det(half_turn), 1.0)


def test_quaternion_matrix_round_trip():
    rng = np.random.default_rng(7)
    for _ in range(20):
        R = rotation_about(rng.normal(size=3), rng.uniform(-np.pi, np.pi))
        assert np.allclose(matrix_from_quaternion(quaternion_from_matrix(R)), R, atol=1e-12)


def rest_pose():
    """Standing upright facing +x (left +y), arms hanging: every joint frame equals the torso frame."""
    return np.array([(0, 0, 0.95), (0, 0.09, 0.95), (0, 0.09, 0.52), (0, 0.09, 0.08), (0, -0.09, 0.95),
                     (0, -0.09, 0.52), (0, -0.09, 0.08), (0, 0, 1.45), (0, 0, 1.72), (0, 0.19, 1.43),
                     (0, 0.19, 1.15), (0, 0.19, 0.90), (0, -0.19, 1.43), (0, -0.19, 1.15), (0, -0.19, 0.90)], float)


def test_joint_frames_of_the_rest_pose_are_the_torso_frame():
    assert np.allclose(model.joint_orientations(rest_pose()), [0, 0, 0, 1], atol=1e-12)


def test_joint_frames_follow_a_raised_arm_and_a_turned_body():
    joints = rest_pose()
    shoulder, elbow, wrist = (model.JOINT_NAMES.index(n) for n in ('left_shoulder', 'left_elbow', 'left_wrist'))
    joints[[elbow, wrist]] = joints[shoulder] + np.array([[0.28, 0, 0], [0.53, 0, 0]])  # arm straight forward
    turn = rotation_about([0, 0, 1], 0.7)
    frames = model.joint_orientations(joints @ turn.T)
    expected_arm = turn @ rotation_about([0, 1, 0], -np.pi / 2)  # hanging (−z) to forward (+x): about −y
    assert np.allclose(matrix_from_quaternion(frames[shoulder]), expected_arm, atol=1e-9)
    assert np.allclose(matrix_from_quaternion(frames[0]), turn, atol=1e-12)
