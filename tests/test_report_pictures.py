"""The demo's evaluation pictures (app/reports): error plot (paper 000 Fig. 12), contact sheet
(Fig. 10) and the skeleton animation, read back and checked pixel by pixel where it matters."""
import numpy as np
import cv2
import pytest

from mvpose_nodes.app.reports import animation as animation_module
from mvpose_nodes.body.model import PARAMETER_NAMES
from mvpose_nodes.body.camera import studio_rig
from mvpose_nodes.body.kinematics import JOINT_INDEX, PARAMETER_INDEX, bone_lengths, forward_kinematics
from mvpose_nodes.app.reports.animation import animation
from mvpose_nodes.app.reports.drawing import COLOURS, JOINT_DOT, draw_skeleton
from mvpose_nodes.app.reports.plots import error_plot
from mvpose_nodes.app.reports.sheets import NO_IMAGE_GREY, contact_sheet

pytestmark = pytest.mark.pure

BLUE = (30, 60, 200)  # RGB of the test images


def standing_pose(x=0.0, y=0.0, height=1.75):
    """Joints (15, 3) [m] of the template standing at (x, y) [m] on the floor."""
    parameters = np.zeros(len(PARAMETER_NAMES))
    parameters[[PARAMETER_INDEX['torso_x'], PARAMETER_INDEX['torso_y'], PARAMETER_INDEX['torso_z']]] = x, y, 0.93
    parameters[PARAMETER_INDEX['left_thigh_ry']] = 0.3   # a step, so the legs' bones separate in every view
    parameters[PARAMETER_INDEX['right_thigh_ry']] = -0.3
    return forward_kinematics(parameters, bone_lengths(height))[0]


def read_rgb(path):
    image = cv2.imread(str(path))
    assert image is not None, f'{path} is not a readable image'
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


def near(pixel, colour, tolerance=12):
    return np.abs(np.asarray(pixel, dtype=int) - colour).max() <= tolerance


def rows_of_colour(image, colour, minimum):
    """Rows with at least `minimum` pixels of exactly `colour` (RGB)."""
    return np.flatnonzero(np.all(image == colour, axis=2).sum(axis=1) >= minimum)


def test_error_plot_png_with_reference_lines_where_the_values_say(tmp_path):
    rng = np.random.default_rng(12)
    per_joint = rng.uniform(10, 70, (40, 15))
    per_joint[8:11] = np.nan  # three frames without a fit
    errors = per_joint.mean(axis=1)
    path = error_plot(errors, np.arange(52, 92), tmp_path / 'new' / 'errors.png', paper_mean=40.0, target=20.0,
                      per_joint=per_joint)
    assert path == tmp_path / 'new' / 'errors.png'
    image = read_rgb(path)
    assert image.shape == (600, 1200, 3)
    assert (image[5, 5] == 255).all()  # white background
    frame_rows = rows_of_colour(image, (0, 0, 0), 800)  # the plot's frame: its top and bottom lines
    bottom = frame_rows.max()
    paper_row = rows_of_colour(image, (214, 39, 40), 400)
    target_row = rows_of_colour(image, (44, 160, 44), 400)
    assert len(paper_row) and len(target_row)
    # y is linear from 0 at the bottom line: 40 mm twice as high as 20 mm
    assert (bottom - paper_row.mean()) / (bottom - target_row.mean()) == pytest.approx(2.0, rel=0.03)
    assert np.all(image == (31, 119, 180), axis=2).sum() > 500  # the error line
    assert np.all(image == (252, 226, 226), axis=2).sum() > 2000  # the frames without fit, shaded
    for colour in ((255, 127, 14), (148, 103, 189), (140, 86, 75)):  # arms, legs, torso curves
        assert np.all(np.abs(image.astype(int) - colour) < 8, axis=2).sum() > 100


def test_error_plot_single_frame_all_gaps_and_bad_input(tmp_path):
    assert read_rgb(error_plot([31.0], [60], tmp_path / 'one.png')).shape == (600, 1200, 3)
    assert read_rgb(error_plot([np.nan, np.nan], [1, 2], tmp_path / 'none.png')).shape == (600, 1200, 3)
    assert read_rgb(error_plot([1.0, 2.0], None, tmp_path / 'small.png', size=(800, 400))).shape == (400, 800, 3)
    with pytest.raises(ValueError):
        error_plot([1.0, 2.0], [1], tmp_path / 'bad.png')


def test_contact_sheet_draws_the_skeletons_where_the_cameras_see_them(tmp_path):
    rig = studio_rig((640, 360))
    pose = standing_pose(0.3, -0.2)
    images = {3: np.full((360, 640, 3), BLUE, np.uint8)}
    path = contact_sheet(images, rig, pose, None, tmp_path / 'sheet' / 'fitted.png', columns=4, tile_width=320,
                         used_cameras={3, 5})
    sheet = read_rgb(path)
    assert sheet.shape == (2 * 180, 4 * 320, 3)  # 8 tiles of 320×180 in 2 rows of 4

    def at(camera_index, point):
        """The sheet pixel showing world `point` in camera rig[camera_index]'s tile."""
        pixel = rig[camera_index].project(point[None])[0][0]
        x, y = np.round((pixel + 0.5) * 0.5 - 0.5).astype(int)  # the 640×360 camera's pixel on its 320×180 tile
        row, column = divmod(camera_index, 4)
        return sheet[row * 180 + y, column * 320 + x]

    for index in (2, 6):  # cam 3 (with its image) and cam 7 (without), which see the legs apart
        assert near(at(index, pose[JOINT_INDEX['left_knee']]), JOINT_DOT)
        assert near(at(index, (pose[JOINT_INDEX['left_knee']] + pose[JOINT_INDEX['left_ankle']]) / 2), COLOURS['left'])
        assert near(at(index, (pose[JOINT_INDEX['right_knee']] + pose[JOINT_INDEX['right_ankle']]) / 2), COLOURS['right'])
        assert near(at(index, (pose[JOINT_INDEX['pelvis']] + pose[JOINT_INDEX['neck']]) / 2), COLOURS['centre'])
    cam3 = sheet[:180, 640:960]
    assert near(cam3[100, 40], BLUE, 0)  # the image itself away from the skeleton
    assert near(cam3[1, 160], COLOURS['centre'], 0)  # used for the fit: yellow frame
    cam1 = sheet[:180, :320]
    assert np.all(cam1 == NO_IMAGE_GREY, axis=2).mean() > 0.5  # no image: grey, with the floor grid
    assert np.any(cam1[:, :, 0] > 100)
    assert not near(sheet[1, 160], COLOURS['centre'], 40)  # cam 1 was not used: no yellow frame

    truth_sheet = read_rgb(contact_sheet(images, rig, None, pose, tmp_path / 'truth.png', tile_width=320))
    x, y = np.round((rig[2].project(pose[JOINT_INDEX['head']][None])[0][0] + 0.5) * 0.5 - 0.5).astype(int)
    assert near(truth_sheet[y, 640 + x], COLOURS['truth'])


def test_contact_sheet_with_a_title_and_dict_of_cameras(tmp_path):
    rig = {camera.number: camera for camera in studio_rig((320, 240), cameras=[3, 5, 7])}
    sheet = read_rgb(contact_sheet({}, rig, standing_pose(), standing_pose(0.05), tmp_path / 't.png', columns=2,
                                   tile_width=200, title='frame 60'))
    assert sheet.shape == (40 + 2 * 150, 2 * 200, 3)
    assert (sheet[40 + 150:, 200:] == 0).all()  # no fourth tile


def test_draw_skeleton_skips_nan_joints_and_joints_behind_the_camera():
    camera = studio_rig((320, 180), cameras=[1])[0]
    image = np.zeros((180, 320, 3), np.uint8)
    pose = standing_pose()
    pose[JOINT_INDEX['left_wrist']] = np.nan
    draw_skeleton(image, camera, pose, truth=False)
    assert image.any()
    behind = np.zeros_like(image)
    draw_skeleton(behind, camera, standing_pose(8.0, 0.0), truth=True)  # behind cam 1 at x = 4 m
    assert not behind.any()


def read_video(path):
    capture = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, frame = capture.read()
        if not ok:
            break
        frames.append(cv2.cvtColor(frame, cv2.COLOR_BGR2RGB))
    count = capture.get(cv2.CAP_PROP_FRAME_COUNT)
    capture.release()
    return frames, count


def walk(count):
    return np.array([standing_pose(-1.0 + 0.05 * i, 0.2) for i in range(count)])


def test_animation_3d_orbit_mp4(tmp_path):
    poses = walk(12)
    poses[4] = np.nan  # a frame without a fit
    path = animation(poses, tmp_path / 'anim' / 'walk.mp4', truth=walk(12), frame_numbers=range(52, 64))
    assert path == tmp_path / 'anim' / 'walk.mp4' and path.stat().st_size > 0
    frames, count = read_video(path)
    assert len(frames) == 12 and count == 12
    assert frames[0].shape == (360, 640, 3)
    assert all(np.any(frame.min(axis=2) > 200) for frame in frames)  # the truth (white) in every frame


def test_animation_over_camera_images(tmp_path):
    camera = studio_rig((640, 360), cameras=[3])[0]
    poses = walk(6)
    images = [np.full((360, 640, 3), BLUE, np.uint8) if i % 2 else None for i in range(6)]
    path = animation(poses, tmp_path / 'cam3', camera=camera, images=images, fps=10, truth=poses)
    assert path.suffix == '.mp4' and path.stat().st_size > 0
    frames, count = read_video(path)
    assert len(frames) == 6 and count == 6 and frames[0].shape == (360, 640, 3)
    # the fitted pelvis dot (dark) where camera 3 sees it, despite the lossy video
    for frame, pose in zip(frames, poses):
        (x, y), = np.round(camera.project(pose[JOINT_INDEX['pelvis']][None])[0]).astype(int)
        assert frame[y, x].max() < 90
    assert near(frames[1][200, 20], BLUE, 25)  # the image behind


def test_animation_falls_back_to_a_png_strip_without_mp4(tmp_path, monkeypatch):
    class NoVideo:
        def __init__(self, *args):
            pass

        def isOpened(self):
            return False

        def release(self):
            pass

    monkeypatch.setattr(animation_module.cv2, 'VideoWriter', NoVideo)
    path = animation(walk(20), tmp_path / 'walk.mp4')
    assert path == tmp_path / 'walk.png' and not (tmp_path / 'walk.mp4').exists()
    strip = read_rgb(path)
    assert strip.shape == (180, 8 * 320, 3)  # 8 frames of 640×360 at half size


def test_marker_sheet_draws_estimates_by_flag_and_joins_the_ones_off(tmp_path):
    from mvpose_nodes.app.reports.sheets import MARKER_FLAG_COLOURS, marker_label, marker_sheet
    rng = np.random.default_rng(3)
    truth = rng.uniform(100, 500, (15, 2))
    estimate, flags = truth.copy(), np.zeros(15, np.uint8)
    estimate[11] += (0.0, 60.0)                                  # left wrist predicted 60 px low
    flags[11] = 1
    image = np.full((600, 600, 3), BLUE, np.uint8)
    path = marker_sheet({3: image}, {3: (estimate, flags)}, {3: (truth, np.ones(15, bool))}, tmp_path / 'm.png',
                        tile_width=600, title='test')
    rgb = read_rgb(path)
    assert rgb.shape[1] == 600 and marker_label('left_wrist') == 'LW' and marker_label('pelvis') == 'P'

    tiles = rgb[:-34]                                   # above the legend

    def count(colour):
        return int(np.sum(np.all(np.abs(tiles.astype(int) - colour) < 12, axis=2)))
    assert count(MARKER_FLAG_COLOURS[0]) > 14 * 40    # 14 detected dots
    assert count(MARKER_FLAG_COLOURS[1]) > 40         # the predicted wrist
    assert count((230, 40, 40)) > 60                   # its red line to the truth, about 60 px × crop scale
    exact = read_rgb(marker_sheet({3: image}, {3: (truth, flags)}, {3: (truth, np.ones(15, bool))},
                                  tmp_path / 'exact.png', tile_width=600))[:-34]
    assert not np.any(np.all(np.abs(exact.astype(int) - (230, 40, 40)) < 12, axis=2))   # nothing off: no line
