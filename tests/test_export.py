"""`export`'s formats: the recorded motion as CSV, JSON and BVH. The BVH's own forward kinematics gives the
joints back, its channels are the model's parameters, and CSV and JSON parse back to the recorded values.
The command on a bag and its one-line errors: test_commands.py."""
import csv
import io
import json

import numpy as np
import pytest

from mvpose_nodes.body.model import BONES, JOINT_NAMES, PARAMETER_NAMES
from mvpose_nodes.body.kinematics import JOINT_INDEX, PARAMETER_INDEX, bone_lengths, euler_matrix, forward_kinematics
from mvpose_nodes.studio.mocap import BVH_TO_WORLD, elementary_rotations, load_bvh
from mvpose_nodes.io.motion_export import Motion, read_bvh, write_csv, write_json, write_motion

pytestmark = pytest.mark.pure

EPOCH_NS = 1_230_768_000_000_000_000  # 2009-01-01, the synthetic bags' epoch
FRAME_NS = 40_000_000                 # 25 fps


def random_model_motion(rng, frames, height=1.75, max_ry=np.pi):
    """(parameters (F, 29), joints (F, 15, 3)) of random poses of the model: every angle uniform in
    (−π, π) (Y angles within ±max_ry), root anywhere in a 4 m square."""
    parameters = rng.uniform(-np.pi, np.pi, (frames, len(PARAMETER_NAMES)))
    for name in PARAMETER_NAMES:
        if name.endswith('_ry'):
            parameters[:, PARAMETER_INDEX[name]] = rng.uniform(-max_ry, max_ry, frames)
    parameters[:, [PARAMETER_INDEX['torso_x'], PARAMETER_INDEX['torso_y']]] = rng.uniform(-2, 2, (frames, 2))
    parameters[:, PARAMETER_INDEX['torso_z']] = rng.uniform(0.8, 1.0, frames)
    lengths = bone_lengths(height)
    return parameters, np.array([forward_kinematics(p, lengths)[0] for p in parameters])


def motion_of(joints, parameters=None, stamps_ns=None):
    count = len(joints)
    return Motion(stamps_ns=EPOCH_NS + FRAME_NS * np.arange(count) if stamps_ns is None else stamps_ns,
                  status=np.arange(count) % 4, joints=joints,
                  parameters=np.full((count, len(PARAMETER_NAMES)), np.nan) if parameters is None else parameters)


@pytest.mark.parametrize('seed', range(4))
def test_bvh_forward_kinematics_gives_random_model_poses_back(tmp_path, seed):
    """Wild random poses (any Euler angles, gimbal lock included by chance), written with the recorded
    parameters and, separately, with none (the roll then from inverse kinematics): the BVH read back
    and run through its own forward kinematics puts every joint where it was."""
    rng = np.random.default_rng(seed)
    parameters, joints = random_model_motion(rng, 12, height=rng.uniform(1.5, 1.95))
    for label, recorded in (('parameters', parameters), ('none', None)):
        path = tmp_path / f'{label}.bvh'
        write_motion(motion_of(joints, recorded), path, 'bvh')
        back, frame_time = read_bvh(path)
        assert np.abs(back - joints).max() < 1e-6, label
        assert frame_time == pytest.approx(0.04)


def test_bvh_hierarchy_channels_and_axes(tmp_path):
    """The BVH tree is the model's bone tree, Y up in metres, and the rotation channels (Y, Z, X) are the
    model's (rz, −ry, rx) in degrees: the parameters themselves where the BVH parent is the model's
    parent bone, 0 where the model has no DOF; an upper arm relative to its clavicle."""
    rng = np.random.default_rng(7)
    parameters, joints = random_model_motion(rng, 6, max_ry=np.pi / 2 - 0.05)  # ZYX Euler angles are unique here
    path = tmp_path / 'motion.bvh'
    write_motion(motion_of(joints, parameters), path, 'bvh')
    bvh = load_bvh(path)
    names = ['torso', 'left_hip', 'left_thigh', 'left_shin', 'left_shin_end', 'right_hip', 'right_thigh',
             'right_shin', 'right_shin_end', 'head', 'head_end', 'left_clavicle', 'left_upper_arm', 'left_forearm',
             'left_forearm_end', 'right_clavicle', 'right_upper_arm', 'right_forearm', 'right_forearm_end']
    assert list(bvh.names) == names
    parent = {name: bvh.names[p] if p >= 0 else None for name, p in zip(bvh.names, bvh.parents)}
    assert parent['left_thigh'] == 'left_hip' and parent['left_hip'] == 'torso' and parent['head'] == 'torso'
    assert parent['left_upper_arm'] == 'left_clavicle' and parent['left_clavicle'] == 'torso'
    lengths = bone_lengths(1.75)
    offset = dict(zip(bvh.names, bvh.offsets))
    np.testing.assert_allclose(offset['head'], [0, lengths['spine'], 0], atol=1e-9)    # Y up
    np.testing.assert_allclose(offset['head_end'], [0, lengths['head'], 0], atol=1e-9)
    np.testing.assert_allclose(offset['left_thigh'], [-lengths['hip'], 0, 0], atol=1e-9)  # the left at −X
    np.testing.assert_allclose(offset['left_shin_end'], [0, -lengths['shin'], 0], atol=1e-9)
    np.testing.assert_allclose(offset['left_hip'], 0, atol=1e-12)
    assert bvh.channels[0] == ('Xposition', 'Yposition', 'Zposition', 'Yrotation', 'Zrotation', 'Xrotation')
    assert all(channels == ('Yrotation', 'Zrotation', 'Xrotation') for name, channels in
               zip(bvh.names[1:], bvh.channels[1:]) if not name.endswith('_end'))
    np.testing.assert_allclose(bvh.motion[:, :3], joints[:, JOINT_INDEX['pelvis']][:, [0, 2, 1]] * [1, 1, -1], atol=1e-9)

    columns, column = {}, 0
    for name, channels in zip(bvh.names, bvh.channels):
        columns[name] = slice(column + len(channels) - 3, column + len(channels)) if channels else None
        column += len(channels)

    def degrees(values):  # the equal rotation angles ±360° apart
        return (np.asarray(values) + 180.0) % 360.0 - 180.0

    for frame in range(len(parameters)):
        def channels(name):
            return bvh.motion[frame, columns[name]]

        def expected(*names):  # (rz, −ry, rx) [deg] of the named (rx, ry, rz), None = 0
            rx, ry, rz = (parameters[frame, PARAMETER_INDEX[n]] if n else 0.0 for n in names)
            return np.degrees([rz, -ry, rx])
        for side in ('left', 'right'):
            for bone, names in ((f'{side}_thigh', (f'{side}_thigh_rx', f'{side}_thigh_ry', f'{side}_thigh_rz')),
                                (f'{side}_shin', (f'{side}_shin_rx', None, None)),
                                (f'{side}_clavicle', (None, f'{side}_clavicle_ry', f'{side}_clavicle_rz')),
                                (f'{side}_forearm', (f'{side}_forearm_rx', None, None)),
                                (f'{side}_hip', (None,) * 3)):
                assert np.allclose(degrees(channels(bone) - expected(*names)), 0, atol=1e-6), (frame, bone)
            # The upper arm hangs from the clavicle's end: its channels are its rotation relative to the clavicle.
            y, z, x = channels(f'{side}_upper_arm')
            local = (elementary_rotations('Y', [y]) @ elementary_rotations('Z', [z])
                     @ elementary_rotations('X', [x]))[0]
            clavicle = euler_matrix(0.0, *parameters[frame, [PARAMETER_INDEX[f'{side}_clavicle_ry'], PARAMETER_INDEX[f'{side}_clavicle_rz']]])
            upper_arm = euler_matrix(*parameters[frame, [PARAMETER_INDEX[f'{side}_upper_arm_r{a}'] for a in 'xyz']])
            np.testing.assert_allclose(BVH_TO_WORLD @ local @ BVH_TO_WORLD.T, clavicle.T @ upper_arm, atol=1e-8)
        for bone in ('torso', 'head'):
            assert np.allclose(degrees(channels(bone) - expected(*(f'{bone}_r{a}' for a in 'xyz'))), 0, atol=1e-6)


def test_bvh_without_parameters_takes_the_roll_from_inverse_kinematics(tmp_path):
    """Joint positions leave each bone's roll open; without recorded parameters the roll comes from the
    model (inverse_kinematics), so knees and elbows stay hinges (X rotation only) and the hip bones, which
    have no DOF, do not turn."""
    parameters, joints = random_model_motion(np.random.default_rng(9), 8)
    path = tmp_path / 'motion.bvh'
    write_motion(motion_of(joints), path, 'bvh')
    bvh = load_bvh(path)
    start = dict(zip(bvh.names, np.cumsum([0] + [len(c) for c in bvh.channels])))
    for side in ('left', 'right'):
        np.testing.assert_allclose(bvh.motion[:, start[f'{side}_hip']:start[f'{side}_hip'] + 3], 0, atol=1e-6)
        for hinge in (f'{side}_shin', f'{side}_forearm'):
            yz = bvh.motion[:, start[hinge]:start[hinge] + 2]
            assert np.allclose((yz + 180) % 360 - 180, 0, atol=1e-6), hinge


def test_bvh_of_a_mocap_walk_keeps_every_bone_direction(tmp_path, cmu_walk):
    """Joints that are not the model's (the CMU walk: uneven shoulders, bone lengths that vary over the
    take through resampling): every bone points exactly where it was recorded, the root is exact, and a
    joint is off by no more than the length deviations from the median along its chain."""
    joints = cmu_walk.joints[:40]
    path = tmp_path / 'walk.bvh'
    write_motion(motion_of(joints), path, 'bvh')
    back, _ = read_bvh(path)
    np.testing.assert_allclose(back[:, JOINT_INDEX['pelvis']], joints[:, JOINT_INDEX['pelvis']], atol=1e-8)
    chain_slack = np.zeros((len(joints), len(JOINT_NAMES)))
    for start, end in BONES:  # parents come first in BONES
        recorded, exported = joints[:, JOINT_INDEX[end]] - joints[:, JOINT_INDEX[start]], back[:, JOINT_INDEX[end]] - back[:, JOINT_INDEX[start]]
        cosine = (np.sum(recorded * exported, axis=1)
                  / (np.linalg.norm(recorded, axis=1) * np.linalg.norm(exported, axis=1)))
        assert np.all(cosine > 1 - 1e-12), (start, end)
        length = np.linalg.norm(recorded, axis=1)
        chain_slack[:, JOINT_INDEX[end]] = chain_slack[:, JOINT_INDEX[start]] + np.abs(length - np.median(length))
    error = np.linalg.norm(back - joints, axis=-1)
    assert np.all(error <= chain_slack + 1e-8)
    assert 1e-4 < error.max() < 0.02  # lengths do vary over this take, but by millimetres


def test_csv_and_json_parse_back():
    rng = np.random.default_rng(3)
    parameters, joints = random_model_motion(rng, 4)
    parameters[2] = np.nan  # a frame without parameters
    stamps = EPOCH_NS + np.array([0, 40_000_000, 80_000_001, 120_000_000])
    motion = motion_of(joints, parameters, stamps)

    text = io.StringIO()
    write_csv(motion, text)
    rows = list(csv.reader(io.StringIO(text.getvalue())))
    header, rows = rows[0], rows[1:]
    assert header[:5] == ['stamp_s', 'status', 'pelvis_x_m', 'pelvis_y_m', 'pelvis_z_m']
    assert header[2 + 3 * JOINT_INDEX['right_wrist'] + 2] == 'right_wrist_z_m'
    assert header[47:50] == ['torso_x_m', 'torso_y_m', 'torso_z_m'] and header[50] == 'torso_rx_rad'
    assert header[-1] == 'right_forearm_rx_rad' and len(header) == 2 + 45 + 29
    assert [row[0] for row in rows] == ['1230768000.000000000', '1230768000.040000000', '1230768000.080000001',
                                        '1230768000.120000000']
    assert [int(row[1]) for row in rows] == [0, 1, 2, 3]
    np.testing.assert_allclose(np.array([row[2:47] for row in rows], dtype=float), joints.reshape(4, 45), atol=1e-9)
    assert rows[2][47:] == [''] * 29
    kept = [0, 1, 3]
    np.testing.assert_allclose(np.array([rows[i][47:] for i in kept], dtype=float), parameters[kept], atol=1e-9)

    text = io.StringIO()
    write_json(motion, text, source={'bag': 'b', 'topic': '/t'})
    document = json.loads(text.getvalue())
    assert document['units']['joints'] == 'm' and document['source'] == {'bag': 'b', 'topic': '/t'}
    assert document['joint_names'] == list(JOINT_NAMES) and document['parameter_names'] == list(PARAMETER_NAMES)
    assert document['bones'][0] == {'parent': 'pelvis', 'child': 'neck'} and len(document['bones']) == 14
    assert document['parameter_units'][:4] == ['m', 'm', 'm', 'rad']
    frames = document['frames']
    assert [f['stamp_ns'] for f in frames] == stamps.tolist() and [f['status'] for f in frames] == [0, 1, 2, 3]
    assert frames[2]['stamp'] == pytest.approx(1230768000.080000001, abs=1e-6)
    assert np.array_equal(np.array([f['joints'] for f in frames]), joints)  # JSON floats round-trip exactly
    assert frames[2]['parameters'] is None and np.array_equal(frames[3]['parameters'], parameters[3])
