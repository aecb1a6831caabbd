"""The motions of the randomised evaluation (issue 13), studio.catalogue: every CMU clip, the 3dsMax-friendly
CMU 131_01, the AMP humanoid's run, hop, cartwheels and backflip, and the scripted actions, each a plausible
person of the requested height, rigid, on the floor and at least 4 s long."""
import dataclasses
import functools

import numpy as np
import pytest

from mvpose_nodes.body.kinematics import inverse_kinematics
from mvpose_nodes.body.model import BONES, JOINT_INDEX, PARAMETER_INDEX
from mvpose_nodes.fitting.stage_search import JOINT_LIMITS
from mvpose_nodes.studio import actions, amp, catalogue, mocap
from mvpose_nodes.studio.mocap import MotionFileError

pytestmark = pytest.mark.pure

HEIGHT = 1.75
ANKLES = [JOINT_INDEX['left_ankle'], JOINT_INDEX['right_ankle']]
ANKLE_HEIGHT = mocap.ANKLE_HEIGHT_PER_HEIGHT * HEIGHT
AIRBORNE = ('amp_run', 'amp_hop', 'amp_cartwheel', 'amp_backflip')  # leave the floor: flight, hands down
# The body model's trunk is one rigid bone, but a captured subject's back bends: the distance pelvis–neck
# (and neck–shoulders, the clavicles) changes by these [m] (131_01 kneels and bows, the cartwheel twists).
TRUNK_BENDS = {'cmu_131_01': 0.06, 'amp_cartwheel': 0.035}
TRUNK_BONES = (('pelvis', 'neck'), ('neck', 'left_shoulder'), ('neck', 'right_shoulder'))


@functools.cache
def motion(name, height=HEIGHT):
    return catalogue.load_motion(name, height)


def bone_length_ranges(joints):
    """{(parent, child): max − min length over the frames [m]} of the body model's 14 bones."""
    return {(a, b): np.ptp(np.linalg.norm(joints[:, JOINT_INDEX[b]] - joints[:, JOINT_INDEX[a]], axis=-1))
            for a, b in BONES}


def test_catalogue_names_and_sets():
    assert catalogue.MOTIONS == ('07_01', '07_02', '08_08', 'cmu_131_01', 'amp_run', 'amp_hop', 'amp_cartwheel',
                                 'amp_backflip', 'turn_on_the_spot', 'walk_backwards', 'bend_down_and_up',
                                 'arms_overhead_and_wave', 'sit_down_and_stand_up')
    sets = (catalogue.TUNING_MOTIONS, catalogue.HELD_OUT_MOTIONS, catalogue.STRESS_MOTIONS)
    assert sorted(sum(sets, ())) == sorted(catalogue.MOTIONS)  # each motion in exactly one set
    for name in catalogue.MOTIONS:
        line = catalogue.describe(name)
        assert line and '\n' not in line
    for call in (catalogue.describe, catalogue.load_motion):
        with pytest.raises(MotionFileError, match='07_01.*sit_down_and_stand_up'):
            call('moonwalk')


def test_load_motion_is_cached_and_read_only():
    first = catalogue.load_motion('07_01')
    assert catalogue.load_motion('07_01') is first
    with pytest.raises(ValueError):
        first.joints[0, 0, 0] = 1.0
    assert catalogue.load_motion('07_01', 1.6) is not first


@pytest.mark.parametrize('name', catalogue.MOTIONS)
def test_motion_is_a_long_enough_person(name):
    clip = motion(name)
    count = len(clip.joints)
    assert clip.frame_rate == 25.0 and clip.first_frame == 0
    assert (count - 1) / clip.frame_rate >= 4.0
    assert clip.joints.shape == (count, 15, 3) and clip.toes.shape == clip.hand_tips.shape == (count, 2, 3)
    assert clip.head_forward.shape == (count, 3)
    for points in (clip.joints, clip.toes, clip.hand_tips, clip.head_forward):
        assert np.isfinite(points).all()
    np.testing.assert_allclose(np.linalg.norm(clip.head_forward, axis=-1), 1.0, atol=1e-9)
    np.testing.assert_allclose(clip.joints[:, JOINT_INDEX['pelvis']],
                               clip.joints[:, [JOINT_INDEX['left_hip'], JOINT_INDEX['right_hip']]].mean(axis=1),
                               atol=1e-9)


@pytest.mark.parametrize('name', catalogue.MOTIONS)
def test_bones_keep_their_lengths(name):
    ranges = bone_length_ranges(motion(name).joints)
    for bone, spread in ranges.items():
        limit = TRUNK_BENDS.get(name, 0.02) if bone in TRUNK_BONES else 0.02
        assert spread < limit, f'{name}: {bone} changes by {spread:.3f} m'


@pytest.mark.parametrize('name', catalogue.MOTIONS)
def test_feet_are_on_the_floor(name):
    clip = motion(name)
    lower = clip.joints[:, ANKLES, 2].min(axis=1)
    assert 0.03 <= lower.min() <= 0.15
    assert clip.toes[..., 2].min() > -0.05  # a pointed foot's toes dip a little at most (131_01: 4 cm)
    if name not in AIRBORNE:
        assert lower.max() < 0.16  # always a foot on the floor
    elif name in ('amp_run', 'amp_hop'):
        assert np.mean(lower < 0.15) > 0.5   # flight phases between stances


@pytest.mark.parametrize('name', [name for name in catalogue.MOTIONS if name != 'amp_cartwheel'])
def test_standing_height(name):
    """The head's highest point over the frames with the trunk upright and a foot down is the requested
    height within 3 % (the walks: mid-stance; 131_01, the backflip and the actions: their first frame).
    The cartwheel never stands: see test_amp_rest_pose_stands_the_requested_height."""
    clip = motion(name)
    trunk = clip.joints[:, JOINT_INDEX['neck']] - clip.joints[:, JOINT_INDEX['pelvis']]
    upright = trunk[:, 2] > np.cos(np.radians(25)) * np.linalg.norm(trunk, axis=1)
    foot_down = clip.joints[:, ANKLES, 2].min(axis=1) < ANKLE_HEIGHT + 0.04
    standing = clip.joints[upright & foot_down, JOINT_INDEX['head'], 2]
    assert abs(standing.max() - HEIGHT) < 0.03 * HEIGHT
    if name in ('cmu_131_01', 'amp_backflip') + catalogue.ACTIONS:
        assert abs(clip.joints[0, JOINT_INDEX['head'], 2] - HEIGHT) < 0.03 * HEIGHT


@pytest.mark.parametrize('name', ['07_02', 'cmu_131_01', 'amp_hop', 'sit_down_and_stand_up'])
def test_motions_scale_with_the_height(name):
    tall, short = motion(name), motion(name, 1.6)
    np.testing.assert_allclose(short.joints[:, :, 2].max(), tall.joints[:, :, 2].max() * 1.6 / HEIGHT, rtol=1e-9)


def test_amp_bodies_map_to_the_joints():
    for name in catalogue.AMP_MOTIONS:
        clip = motion(name)
        head = np.linalg.norm(clip.joints[:, JOINT_INDEX['head']] - clip.joints[:, JOINT_INDEX['neck']], axis=-1)
        assert 0.2 < head.min() and head.max() < 0.3   # the vertex 0.27 m up the head body, scaled
    for name in ('amp_run', 'amp_hop'):  # they go along +x, the way the humanoid faces at rest
        clip = motion(name)
        assert np.mean(clip.head_forward[:, 0]) > 0.8
        assert clip.joints[-1, JOINT_INDEX['pelvis'], 0] - clip.joints[0, JOINT_INDEX['pelvis'], 0] > 2.0
        ahead = np.einsum('fsi,fi->fs', clip.toes - clip.joints[:, ANKLES], clip.head_forward)
        stance = clip.joints[:, ANKLES, 2] < ANKLE_HEIGHT + 0.03
        assert ahead[stance].min() > 0.05   # a foot on the floor points where the face looks


def test_amp_rest_pose_stands_the_requested_height():
    clip = amp.amp_clip('amp_hop')
    rest = dataclasses.replace(clip, rotations=np.tile([0.0, 0.0, 0.0, 1.0], (2, 15, 1)), root=np.zeros((2, 3)))
    standing = amp.body_motion(rest, height=1.6)
    assert standing.joints[0, JOINT_INDEX['head'], 2] == pytest.approx(1.6, abs=1e-9)
    assert standing.joints[0, ANKLES, 2] == pytest.approx(mocap.ANKLE_HEIGHT_PER_HEIGHT * 1.6, abs=1e-9)
    np.testing.assert_allclose(standing.toes[0, :, 2], 0.0, atol=1e-9)   # the sole on the floor
    np.testing.assert_allclose(standing.head_forward[0], [1.0, 0.0, 0.0])


def test_amp_files_load():
    run = amp.amp_clip('amp_run')
    assert run.frame_count == 41 and run.frame_time == pytest.approx(1 / 30)   # 60 fps stored, every frame twice
    flip = amp.amp_clip('amp_backflip')
    assert flip.frame_count == 29 and flip.frame_time == pytest.approx(1 / 16)
    with pytest.raises(MotionFileError, match='amp_hop, amp_run'):
        amp.amp_clip('amp_swim')


def test_malformed_amp_file_is_a_motion_file_error(tmp_path):
    path = tmp_path / 'broken.npy'
    np.save(path, np.array({'skeleton_tree': {'node_names': ['pelvis']}}, dtype=object), allow_pickle=True)
    with pytest.raises(MotionFileError, match=f'{path}: bodies pelvis'):
        amp.load_amp(path)
    (tmp_path / 'text.npy').write_text('not numpy')
    with pytest.raises(MotionFileError, match='cannot read'):
        amp.load_amp(tmp_path / 'text.npy')


def test_3ds_max_clip_retargets_every_frame():
    bvh = mocap.load_bvh(amp.motions_directory() / 'cmu_131_01.bvh')
    assert not mocap.has_tpose(bvh) and bvh.frame_count == 994
    assert all(mocap.has_tpose(mocap.load_bvh(mocap.cmu_clip(name))) for name in catalogue.CMU_CLIPS)
    clip = motion('cmu_131_01')
    assert len(clip.joints) == int(np.floor(993 / 120 * 25)) + 1   # every row: no T-pose to drop
    # The neck is the base of the neck, level with the shoulders (lowerneck is 8 cm below them).
    shoulders = clip.joints[:, [JOINT_INDEX['left_shoulder'], JOINT_INDEX['right_shoulder']], 2].mean(axis=1)
    assert np.abs(clip.joints[:, JOINT_INDEX['neck'], 2] - shoulders).max() < 0.03
    assert 0.8 < mocap.neck_fraction(bvh) < 0.9


def test_3ds_max_clip_starts_standing():
    """131_01 starts standing, not quite still: in its first 0.35 s the left foot is re-placed (the pelvis
    moves at 0.2–0.3 m/s), then it stands (< 0.1 m/s) until it moves again at 0.65 s (its first high step
    is at 1.1 s); it walks at 1.2 m/s later."""
    pelvis = motion('cmu_131_01').joints[:, JOINT_INDEX['pelvis'], :2]
    speed = np.linalg.norm(np.diff(pelvis, axis=0), axis=1) * 25
    assert speed[:20].mean() < 0.2 and speed[10:16].max() < 0.1
    assert speed[100:160].mean() > 0.8
    head = motion('cmu_131_01').joints[:16, JOINT_INDEX['head'], 2]
    assert np.ptp(head) < 0.02


@pytest.mark.parametrize('name', catalogue.ACTIONS)
def test_actions_stay_within_the_joint_limits(name):
    clip = motion(name)
    angles = np.array([inverse_kinematics(joints) for joints in clip.joints])
    for parameter, (low, high) in JOINT_LIMITS.items():
        values = angles[:, PARAMETER_INDEX[parameter]]
        assert low - 1e-6 <= values.min() and values.max() <= high + 1e-6, parameter


@pytest.mark.parametrize('name', catalogue.ACTIONS)
def test_actions_planted_feet_do_not_slide(name):
    ankles = motion(name).joints[:, ANKLES]
    on_floor = ankles[..., 2] < ANKLE_HEIGHT + 0.002
    planted = on_floor[1:] & on_floor[:-1]
    slide = np.linalg.norm(np.diff(ankles[..., :2], axis=0), axis=-1)
    assert planted.mean() > 0.5 and slide[planted].max() < 0.002


def test_sitting_reaches_the_seat():
    clip = motion('sit_down_and_stand_up')
    pelvis = clip.joints[:, JOINT_INDEX['pelvis'], 2]
    assert pelvis.min() < 0.6
    seated = pelvis < pelvis.min() + 0.01
    knees = clip.joints[seated][:, [JOINT_INDEX['left_knee'], JOINT_INDEX['right_knee']], 2]
    assert 0.35 < seated.sum() / 25 and np.abs(pelvis[seated][:, None] - knees).max() < 0.1  # thighs near level


def test_walk_backwards_goes_backwards():
    clip = motion('walk_backwards')
    pelvis = clip.joints[:, JOINT_INDEX['pelvis'], :2]
    travel = pelvis[-1] - pelvis[0]
    facing = clip.head_forward[:, :2].mean(axis=0)
    assert np.linalg.norm(travel) > 2.0 and np.dot(travel, facing) < -0.95 * np.linalg.norm(travel) * np.linalg.norm(facing)


def test_turn_on_the_spot_turns_once():
    clip = motion('turn_on_the_spot')
    facing = np.unwrap(np.arctan2(clip.head_forward[:, 1], clip.head_forward[:, 0]))
    assert facing[-1] - facing[0] == pytest.approx(2 * np.pi, abs=0.1)
    pelvis = clip.joints[:, JOINT_INDEX['pelvis'], :2]
    assert np.linalg.norm(pelvis - pelvis[0], axis=1).max() < 0.1


def test_actions_follow_their_keyframes():
    times = np.array([0.0, 0.5, 1.0, 2.0])
    tracks = actions.eased([(0.0, {}), (1.0, {'torso_rx': -30, 'down': 0.2})], times)
    np.testing.assert_allclose(tracks['torso_rx'], [0.0, -15.0, -30.0, -30.0])
    np.testing.assert_allclose(tracks['down'], [0.0, 0.1, 0.2, 0.2])
    assert 'left_upper_arm_ry' not in tracks
    rest = actions.eased([(0.0, {}), (1.0, {'left_upper_arm_ry': 90})], times)['left_upper_arm_ry']
    assert rest[0] == actions.REST['left_upper_arm_ry']
