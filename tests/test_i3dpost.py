"""mvpose_nodes.studio.i3dpost: the i3DPost layout (calibration text file, camera folders of PNG frames)
written and read back, and the user errors of bad files."""
import numpy as np
import pytest

from mvpose_nodes.body.camera import studio_rig
from mvpose_nodes.studio.i3dpost import I3dpostError
from mvpose_nodes.studio.i3dpost import (available, find_sequence, frame_path, parse_frame_range, read_calibration,
                                  read_frame, write_calibration, write_frame)

pytestmark = pytest.mark.pure


def distorted_rig():
    """The 8-camera studio with k1 on cameras 2 and 5 (the only distortion term the format holds)."""
    return [camera.with_distortion([-0.12345678901 * camera.number, 0, 0, 0, 0]) if camera.number in (2, 5)
            else camera for camera in studio_rig()]


@pytest.mark.parametrize('units', ['m', 'mm'])
def test_calibration_round_trip(tmp_path, units):
    rig = distorted_rig()
    path = tmp_path / 'calibration.txt'
    write_calibration(path, rig, units=units)
    cameras = read_calibration(path, units=units, image_size=(1920, 1080))
    assert [camera.number for camera in cameras] == list(range(1, 9))
    for written, read in zip(rig, cameras):
        assert (read.width, read.height) == (written.width, written.height)
        for name in 'KDRt':
            np.testing.assert_allclose(getattr(read, name), getattr(written, name), rtol=0, atol=1e-12,
                                       err_msg=name)


def test_units_scale_t(tmp_path):
    path = tmp_path / 'calibration.txt'
    write_calibration(path, studio_rig(), units='mm')
    in_metres = read_calibration(path, units='m')
    np.testing.assert_allclose(in_metres[0].t, studio_rig()[0].t * 1000, rtol=1e-15)


def test_calibration_with_comments_and_blank_lines(tmp_path):
    rig = studio_rig(cameras=[1, 2])
    bare, commented = tmp_path / 'bare.txt', tmp_path / 'commented.txt'
    write_calibration(bare, rig)
    numbers = [line for line in bare.read_text().splitlines() if line and not line.startswith('#')]
    assert len(' '.join(numbers).split()) == 2 * 21
    bare.write_text(' '.join(numbers))  # no comments, no line structure at all
    commented.write_text('# my rig\n\n' + '\n\n'.join(f'{line}   # trailing note' for line in numbers) + '\n')
    for path in bare, commented:
        cameras = read_calibration(path, camera_numbers=[3, 4])
        assert [camera.number for camera in cameras] == [3, 4]
        np.testing.assert_array_equal(cameras[1].R, rig[1].R)


def expect_user_error(path, match):
    """The I3dpostError raised inside the with-block names the file and says `match`."""
    return pytest.raises(I3dpostError, match=rf'{path.name}.*{match}')


def test_calibration_errors(tmp_path):
    path = tmp_path / 'broken.txt'
    camera = studio_rig(cameras=[1])[0]
    write_calibration(path, [camera])
    good = path.read_text()
    focal = '%.17g' % camera.K[0, 0]

    path.write_text(good + '0.5\n')
    with expect_user_error(path, '22 numbers'):
        read_calibration(path)

    path.write_text(good.replace(f'{focal} {focal}', f'{focal} fourteen', 1))
    with expect_user_error(path, "'fourteen' is not a finite number"):
        read_calibration(path)

    lines = good.splitlines()
    r_row = next(index for index, line in enumerate(lines) if line.startswith('# camera')) + 4
    lines[r_row] = '2 0 0'  # first row of R scaled: not orthonormal
    path.write_text('\n'.join(lines))
    with expect_user_error(path, 'R is not a rotation'):
        read_calibration(path)
    lines[r_row:r_row + 3] = ['-1 0 0', '0 1 0', '0 0 1']  # orthonormal, but a reflection
    path.write_text('\n'.join(lines))
    with expect_user_error(path, 'R is not a rotation'):
        read_calibration(path)

    path.write_text(good)
    with expect_user_error(path, '1920×1080 px, the frames are 640×480'):
        read_calibration(path, image_size=(640, 480))

    with expect_user_error(path, 'k1 only'):
        write_calibration(path, [studio_rig()[0].with_distortion([0.1, 0.01, 0, 0, 0])])
    with expect_user_error(path, r'camera numbers \[2\]'):
        write_calibration(path, studio_rig(cameras=[2]))
    with expect_user_error(tmp_path / 'missing.txt', 'cannot read'):
        read_calibration(tmp_path / 'missing.txt')


def test_frames_layout(tmp_path):
    sequence = tmp_path / 'actor1' / 'take2' / 'walk'
    rng = np.random.default_rng(0)
    frames = {(camera, frame): rng.integers(0, 256, (6, 8, 3), dtype=np.uint8)
              for camera in (1, 4) for frame in (52, 53, 60)}
    for (camera, frame), rgb in frames.items():
        write_frame(sequence, camera, frame, rgb)
    (sequence / '003' / 'notes.txt').write_text('not a frame')

    assert frame_path(sequence, 4, 52) == sequence / '003' / '00052.png'
    assert find_sequence(tmp_path) == sequence
    assert find_sequence(sequence) == sequence
    assert available(sequence) == {1: [52, 53, 60], 4: [52, 53, 60]}
    for (camera, frame), rgb in frames.items():
        read = read_frame(frame_path(sequence, camera, frame))
        assert read.dtype == np.uint8
        np.testing.assert_array_equal(read, rgb)  # lossless, and RGB (not OpenCV's BGR) both ways

    with pytest.raises(I3dpostError, match='00054.png'):
        read_frame(frame_path(sequence, 1, 54))
    (sequence / '000' / '00054.png').write_bytes(b'not a png')
    with pytest.raises(I3dpostError, match='00054.png'):
        read_frame(frame_path(sequence, 1, 54))


def test_find_sequence_errors(tmp_path):
    with pytest.raises(I3dpostError, match='no i3DPost sequence'):
        find_sequence(tmp_path)
    for take in 'take1', 'take2':
        write_frame(tmp_path / 'actor1' / take / 'walk', 1, 0, np.zeros((2, 2, 3), np.uint8))
    with pytest.raises(I3dpostError, match='2 sequences.*point at one.*take1/walk.*take2/walk'):
        find_sequence(tmp_path)


@pytest.mark.parametrize('text, frames', [('52-101', (52, 101)), ('60', (60, 60)), (' 7 - 7 ', (7, 7))])
def test_parse_frame_range(text, frames):
    assert parse_frame_range(text) == frames


@pytest.mark.parametrize('text', ['', '52-', '-5', 'a-b', '1-2-3', '101-52', '5.5'])
def test_parse_frame_range_errors(text):
    with pytest.raises(I3dpostError, match='frame range'):
        parse_frame_range(text)
