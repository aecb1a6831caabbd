"""mocap: the BVH parser and forward kinematics, and the CMU walking clips retargeted to the body model."""
import functools

import numpy as np
import pytest

from mvpose_nodes.studio import mocap
from mvpose_nodes.body.model import JOINT_NAMES
from mvpose_nodes.studio.mocap import MotionFileError

pytestmark = pytest.mark.pure

CLIP_FRAMES = {'07_01': 317, '07_02': 330, '08_08': 284}
# 08_08 is a fast walk (2.2 m/s at 1.75 m) on a capture floor that rises by about 8 cm over the clip, so
# with the floor set by the lowest ankle its toe dips 3 cm below z = 0 in the first frame: the walking-speed
# and floor-contact checks use subject 7's clips.
EVEN_FLOOR_CLIPS = ('07_01', '07_02')
JOINT = {name: index for index, name in enumerate(JOINT_NAMES)}
TINY_BVH = """HIERARCHY
ROOT Base
{{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
  JOINT Arm
  {{
    OFFSET 1 0 0
    CHANNELS 3 {arm_channels}
    End Site
    {{
      OFFSET 2 0 0
    }}
  }}
}}
MOTION
Frames: 2
Frame Time: 0.5
0 0 0 0 0 0 0 0 0
10 20 30 0 0 0 {arm_values}
"""


@functools.cache
def clip(name):
    return mocap.load_bvh(mocap.cmu_clip(name))


@functools.cache
def walk(name, height=1.75):
    return mocap.retarget(clip(name), height=height)


@pytest.mark.parametrize('name', CLIP_FRAMES)
def test_cmu_clips_parse(name):
    bvh = clip(name)
    assert len(bvh.names) == 38 and bvh.names.count('Hips') == 1  # 31 joints + 7 End Sites
    assert {'Head_end', 'LeftToeBase_end', 'RightHandIndex1_end'} <= set(bvh.names)
    assert bvh.frame_count == CLIP_FRAMES[name]
    assert bvh.motion.shape == (CLIP_FRAMES[name], 96)
    assert bvh.frame_time == pytest.approx(1 / 120, rel=1e-4)


@pytest.mark.parametrize('name', CLIP_FRAMES)
def test_forward_kinematics_keeps_bone_lengths(name):
    bvh = clip(name)
    positions = bvh.global_positions()
    children = np.flatnonzero(bvh.parents >= 0)
    lengths = np.linalg.norm(positions[:, children] - positions[:, bvh.parents[children]], axis=-1)
    np.testing.assert_allclose(lengths, np.broadcast_to(np.linalg.norm(bvh.offsets[children], axis=-1), lengths.shape),
                               atol=1e-9)


@pytest.mark.parametrize('arm_channels, arm_values, expected_tip', [
    # Rz·Ry·Rx: Rx(90°) leaves the x offset alone, then Rz(90°) turns it to +y.
    ('Zrotation Yrotation Xrotation', '90 0 90', (11, 22, 30)),
    # Rx·Ry·Rz: Rz(90°) turns the x offset to +y, then Rx(90°) turns it to +z.
    ('Xrotation Yrotation Zrotation', '90 0 90', (11, 20, 32)),
    ('Zrotation Yrotation Xrotation', '90 0 0', (11, 22, 30)),
    ('Yrotation Xrotation Zrotation', '90 0 0', (11, 20, 28)),  # Ry(90°): +x → −z
])
def test_rotations_apply_in_channel_order(tmp_path, arm_channels, arm_values, expected_tip):
    path = tmp_path / 'tiny.bvh'
    path.write_text(TINY_BVH.format(arm_channels=arm_channels, arm_values=arm_values))
    bvh = mocap.load_bvh(path)
    assert bvh.names == ('Base', 'Arm', 'Arm_end') and list(bvh.parents) == [-1, 0, 1]
    np.testing.assert_allclose(bvh.global_positions(0)[0], [[0, 0, 0], [1, 0, 0], [3, 0, 0]], atol=1e-12)
    np.testing.assert_allclose(bvh.global_positions(1)[0], [[10, 20, 30], [11, 20, 30], expected_tip], atol=1e-12)


@pytest.mark.parametrize('broken, fragment', [
    (('OFFSET 1 0 0', 'CHANNELS 3 Zrotation Yrotation Xrotation', 1), 'line 8: expected OFFSET'),
    (('OFFSET 1 0 0', 'OFFSET 1 zero 0', 1), 'line 8: expected a number, found zero'),
    (('Zrotation Yrotation Xrotation', 'Zrotation Yrotation Wrotation', 1), 'line 5: expected Xposition'),
    (('Frames: 2', 'Frames: 3', 1), 'Frames: 3, but 2 rows'),
    (('10 20 30 0 0 0 0 0 0', '10 20 30 0 0 0 0 0', 1), 'line 20: expected 9 channel values, found 8'),
    (('End Site', 'End', 1), 'line 11: expected Site, found {'),
    (('}\nMOTION', 'MOTION', 1), 'line 15: expected JOINT or End or }, found MOTION'),
])
def test_malformed_bvh_is_a_one_line_user_error(tmp_path, broken, fragment):
    path = tmp_path / 'broken.bvh'
    path.write_text(TINY_BVH.format(arm_channels='Zrotation Yrotation Xrotation', arm_values='0 0 0')
                    .replace(*broken))
    with pytest.raises(MotionFileError) as error:
        mocap.load_bvh(path)
    message = str(error.value)
    assert message.startswith(f'{path}: ') and fragment in message and '\n' not in message


def test_missing_clip_names_the_folder():
    with pytest.raises(MotionFileError, match=str(mocap.cmu_directory())):
        mocap.cmu_clip('99_99')


@pytest.mark.parametrize('name', CLIP_FRAMES)
def test_retarget_scale_rate_and_skeleton(name):
    bvh, motion = clip(name), walk(name)
    tpose = mocap.world_scale(bvh, 1.6) * bvh.global_positions(0)[0] @ mocap.BVH_TO_WORLD.T
    toes = [bvh.index(tip) for tip in mocap.TOE_TIPS]
    assert tpose[bvh.index('Head_end'), 2] - tpose[toes, 2].min() == pytest.approx(1.6)
    assert np.argmax(tpose[:, 2]) == bvh.index('Head_end')  # z is up
    # Retargeting is linear in the height, floor included.
    np.testing.assert_allclose(walk(name, 1.6).joints, motion.joints * 1.6 / 1.75, atol=1e-12)

    duration = (bvh.frame_count - 2) * bvh.frame_time  # the motion after the T-pose
    assert len(motion.joints) == int(np.floor(duration * 25)) + 1
    assert motion.frame_rate == 25.0 and motion.first_frame == 0
    assert len(mocap.retarget(bvh, frame_rate=1 / bvh.frame_time).joints) == bvh.frame_count - 1
    assert motion.joints.shape[1:] == (15, 3) and motion.toes.shape[1:] == motion.hand_tips.shape[1:] == (2, 3)
    for points in (motion.joints, motion.toes, motion.hand_tips, motion.head_forward):
        assert np.isfinite(points).all()
    np.testing.assert_allclose(motion.joints[:, JOINT['pelvis']],
                               (motion.joints[:, JOINT['left_hip']] + motion.joints[:, JOINT['right_hip']]) / 2)
    z = motion.joints[..., 2]
    assert (z[:, JOINT['head']] > z[:, JOINT['neck']]).all() and (z[:, JOINT['neck']] > z[:, JOINT['pelvis']]).all()
    assert z[:, [JOINT['left_ankle'], JOINT['right_ankle']]].min() == pytest.approx(0.075)
    np.testing.assert_allclose(np.linalg.norm(motion.head_forward, axis=-1), 1.0)


@pytest.mark.parametrize('name', CLIP_FRAMES)
def test_placed_walk_heads_along_x_with_left_at_left(name):
    motion = walk(name).placed(center=(0.5, -1.0), heading=0.0)
    pelvis = motion.joints[:, JOINT['pelvis']]
    travel = pelvis[-1] - pelvis[0]
    assert travel[0] > 0 and abs(travel[1]) < 1e-9 * np.linalg.norm(travel) + 1e-12
    np.testing.assert_allclose(pelvis[:, :2].mean(axis=0), [0.5, -1.0], atol=1e-12)
    np.testing.assert_allclose(motion.joints[..., 2], walk(name).joints[..., 2])
    assert np.mean(motion.joints[:, JOINT['left_hip'], 1] - motion.joints[:, JOINT['right_hip'], 1]) > 0.1
    assert np.mean(motion.head_forward[:, 0]) > 0.7  # looks where it walks
    turned = walk(name).placed(heading=np.pi / 2)
    assert np.mean(turned.joints[:, JOINT['left_hip'], 0] - turned.joints[:, JOINT['right_hip'], 0]) < -0.1


@pytest.mark.parametrize('name', EVEN_FLOOR_CLIPS)
def test_walk_speed_and_floor_contact(name):
    motion = walk(name)
    pelvis = motion.joints[:, JOINT['pelvis'], :2]
    speed = np.linalg.norm(pelvis[-1] - pelvis[0]) * motion.frame_rate / (len(pelvis) - 1)
    assert 0.8 < speed < 2.0
    assert motion.toes[..., 2].min() > -0.01


def test_select_by_frame_number():
    motion = mocap.retarget(clip('07_01'), first_frame=100)
    assert list(motion.frame_numbers[[0, -1]]) == [100, 165]
    part = motion.select(110, 120)
    assert part.first_frame == 110 and list(part.frame_numbers) == list(range(110, 121))
    np.testing.assert_array_equal(part.joints, motion.joints[10:21])
    np.testing.assert_array_equal(part.head_forward, motion.head_forward[10:21])
    for first, last in ((99, 110), (150, 166), (120, 110)):
        with pytest.raises(MotionFileError, match=r'frames 100\.\.165'):
            motion.select(first, last)


def test_standing_motion():
    standing = mocap.standing_motion(clip('07_01'), frames=50, height=1.6, frame_rate=25.0, first_frame=7, seed=3)
    assert standing.joints.shape == (50, 15, 3) and list(standing.frame_numbers[[0, -1]]) == [7, 56]
    head = standing.joints[:, JOINT['head'], 2]
    assert abs(head.mean() - 1.6) < 0.05
    assert standing.joints[:, [JOINT['left_ankle'], JOINT['right_ankle']], 2].min() == pytest.approx(0.075 * 1.6 / 1.75)
    assert standing.toes[..., 2].min() > -1e-9
    sway = np.abs(standing.joints - standing.joints.mean(axis=0)).max()
    assert 0 < sway < 0.01
    assert (standing.joints[:, JOINT['left_hip'], 1] > standing.joints[:, JOINT['right_hip'], 1]).all()
    assert (standing.joints[:, JOINT['left_wrist'], 1] > standing.joints[:, JOINT['left_shoulder'], 1]).all()
    np.testing.assert_array_equal(standing.head_forward[:, 0], 1.0)
    again = mocap.standing_motion(clip('07_01'), frames=50, height=1.6, first_frame=7, seed=3)
    np.testing.assert_array_equal(again.joints, standing.joints)
    # Standing still, placing turns by the facing: heading +y puts the left side at −x.
    turned = standing.placed(heading=np.pi / 2)
    assert (turned.joints[:, JOINT['left_hip'], 0] < turned.joints[:, JOINT['right_hip'], 0]).all()


@pytest.mark.parametrize('clip', ['07_01', '07_02', '08_08'])
def test_retargeted_floor_is_level(clip):
    """The stance ankle is as high at the end of the walk as at its start (the BVH floor is tilted)."""
    motion = mocap.retarget(mocap.load_bvh(mocap.cmu_clip(clip)))
    stance = np.minimum(motion.joints[:, 3, 2], motion.joints[:, 6, 2])
    quarter = len(stance) // 4
    assert abs(stance[:quarter].min() - stance[-quarter:].min()) < 0.015
