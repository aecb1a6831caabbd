"""Camera features step by step on synthetic images with known answers (seeded), and the whole
pipeline on a rendered studio frame against its ground truth."""
import math

import cv2
import numpy as np
import pytest
from conftest import assert_one_line_error, run_mvpose

from mvpose_nodes.body.model import JOINT_NAMES
from mvpose_nodes.body.camera import studio_rig
from mvpose_nodes.ros.params import CAMERA_FEATURES, ParameterError, default_skin_model_path, load_feature_settings
from mvpose_nodes.vision.features import FeatureExtractor, FeatureSettings, ellipse_of
from mvpose_nodes.vision.silhouette import BackgroundModel, chroma_key_foreground, clean_mask, silhouette_keypoints
from mvpose_nodes.vision.skin import SkinModel

BLUE = (60, 100, 200)


def blue_screen(height=540, width=960, seed=0):
    rng = np.random.default_rng(seed)
    image = np.empty((height, width, 3), np.uint8)
    image[:] = BLUE
    return np.clip(image + rng.normal(0, 3, image.shape), 0, 255).astype(np.uint8)


def stick_person(image, colour=(90, 40, 40)):
    """Draw a standing person with legs apart on `image`; returns its keypoints (x, y)."""
    head, neck, hips = (480, 80), (480, 140), (480, 300)
    ankles = {'image_left': (440, 470), 'image_right': (530, 470)}
    cv2.ellipse(image, (480, 100), (22, 30), 0, 0, 360, colour, -1)
    cv2.rectangle(image, (445, 130), (515, 310), colour, -1)
    for foot in ankles.values():
        cv2.line(image, (foot[0], 300), foot, colour, 24)
        cv2.rectangle(image, (foot[0] - 12, foot[1]), (foot[0] + 22, foot[1] + 20), colour, -1)
    return head, neck, hips, ankles


def test_chroma_key_separates_the_person_from_blue_screen():
    image = blue_screen()
    stick_person(image)
    truth = np.zeros(image.shape[:2], np.uint8)
    stick_person(truth[..., None].repeat(3, axis=2).copy())
    foreground = chroma_key_foreground(image)
    drawn = np.any(image != blue_screen(), axis=2) & (np.abs(image.astype(int) - BLUE).sum(axis=2) > 40)
    assert np.array_equal(foreground, drawn)


def test_clean_mask_keeps_the_person_fills_small_holes_not_the_gap_between_legs():
    image = blue_screen()
    stick_person(image)
    foreground = chroma_key_foreground(image)
    person = foreground.copy()
    foreground[200:204, 470:474] = False           # a keying miss inside the torso
    foreground[20:26, 20:26] = True                # a speck elsewhere
    foreground[500:530, 850:880] = True            # a smaller blob
    cleaned = clean_mask(foreground, min_area=500)
    assert cleaned[201, 471], 'small hole filled'
    assert not cleaned[22, 22] and not cleaned[510, 860], 'only the largest blob is kept'
    assert not cleaned[420, 485], 'the gap between the legs stays open'
    assert np.logical_xor(cleaned, person).sum() < 0.02 * person.sum()
    assert not clean_mask(foreground, min_area=10 ** 6).any(), 'too small for a person: nothing'


def test_silhouette_keypoints_of_a_known_figure():
    image = blue_screen()
    _, _, _, ankles = stick_person(image)
    mask = clean_mask(chroma_key_foreground(image))
    points = silhouette_keypoints(mask)
    rows, columns = np.nonzero(mask)
    assert points.root == pytest.approx((columns.mean(), rows.mean()))
    assert len(points.legs) == 2
    for leg, truth in zip(points.legs, (ankles['image_left'], ankles['image_right'])):
        assert abs(leg['ankle'][0] - truth[0]) < 6 and abs(leg['ankle'][1] - truth[1]) < 20
        assert leg['knee'][1] < leg['ankle'][1]
    assert silhouette_keypoints(np.zeros_like(mask)) is None


def test_background_model_finds_a_new_object_and_follows_slow_light_changes():
    rng = np.random.default_rng(3)
    scene = rng.integers(0, 255, (120, 160, 3)).astype(np.uint8)
    frames = [np.clip(scene + rng.normal(0, 2, scene.shape), 0, 255).astype(np.uint8) for _ in range(10)]
    model = BackgroundModel.from_frames(frames)
    with_object = frames[0].copy()
    with_object[40:80, 60:100] = 255 - with_object[40:80, 60:100]
    foreground = model.foreground(with_object)
    assert foreground[45:75, 65:95].mean() > 0.95 and foreground[:30].mean() < 0.01
    brighter = np.clip(scene.astype(int) + 30, 0, 255).astype(np.uint8)
    for _ in range(200):
        model.update(brighter, np.zeros(scene.shape[:2], bool))
    assert model.foreground(brighter).mean() < 0.01


@pytest.mark.parametrize('angle', [0, 30, 75, 110, 160])
def test_direct_ellipse_fit_recovers_a_known_ellipse(angle):
    rng = np.random.default_rng(angle)
    boundary = cv2.ellipse2Poly((400, 300), (90, 35), angle, 0, 360, 2).astype(float)
    boundary += rng.normal(0, 0.3, boundary.shape)
    (cx, cy), major, minor, fitted = ellipse_of(boundary)
    assert (cx, cy) == pytest.approx((400, 300), abs=1) and (major, minor) == pytest.approx((90, 35), abs=1.5)
    difference = (fitted - math.radians(angle) + math.pi / 2) % math.pi - math.pi / 2
    assert abs(difference) < math.radians(2) and -math.pi / 2 <= fitted < math.pi / 2


@pytest.fixture(scope='module')
def studio_frame():
    """One 960×540 view of the synthetic studio with its ground truth, rendered here."""
    from mvpose_nodes.studio import scene
    from mvpose_nodes.studio.mocap import cmu_clip, load_bvh, retarget
    motion = retarget(load_bvh(cmu_clip('07_01'))).placed(heading=math.radians(45))
    i = len(motion.joints) // 2
    pose = scene.BodyPose(motion.joints[i], motion.toes[i], motion.hand_tips[i], motion.head_forward[i])
    camera = studio_rig((960, 540), cameras=[3])[0]
    view = scene.prepare_camera(camera)
    rendering = scene.render(view, pose, scene.Appearance(), scene.shadow_map(
        scene.body_primitives(pose, scene.Appearance()), pose.joints[0, :2]), pose.joints[0, :2])
    rgb, labels = scene.Realism().finish(rendering, view, 3, 0, 0)
    empty, _ = scene.Realism().finish(scene.Rendering(view.background, np.zeros_like(labels)), view, 3, 0, 0)
    return rgb, labels, camera, pose, empty


def extractor(settings=FeatureSettings(), background=None):
    return FeatureExtractor(settings, SkinModel.load(default_skin_model_path()), background)


def check_against_truth(features, labels, camera, pose, min_iou=0.95):
    from mvpose_nodes.studio.scene import SKIN_BIT
    truth_person = (labels & ~np.uint8(SKIN_BIT)) > 0
    iou = (features.silhouette & truth_person).sum() / (features.silhouette | truth_person).sum()
    assert iou > min_iou
    truth_skin = (labels & SKIN_BIT) > 0
    assert (features.skin & truth_skin).sum() > 0.8 * truth_skin.sum()
    pixels, _ = camera.project(pose.joints)
    head = features.keypoints['head']
    assert np.hypot(head.x - pixels[JOINT_NAMES.index('head')][0], head.y - pixels[JOINT_NAMES.index('head')][1]) < 8
    assert len(features.contour.points) > 100 and (features.contour.labels > 0).mean() > 0.5


def test_pipeline_on_a_studio_frame_against_its_ground_truth(studio_frame):
    rgb, labels, camera, pose, _ = studio_frame
    features = extractor()(rgb)
    assert features.person
    check_against_truth(features, labels, camera, pose)
    assert {e.role for e in features.ellipses} >= {1}, 'the face ellipse is found'


def test_pipeline_with_a_learned_background(studio_frame):
    rgb, labels, camera, pose, empty = studio_frame
    rng = np.random.default_rng(1)
    frames = [np.clip(empty + rng.normal(0, 2, empty.shape), 0, 255).astype(np.uint8) for _ in range(8)]
    features = extractor(FeatureSettings(silhouette_method='background'), BackgroundModel.from_frames(frames))(rgb)
    # Without the blue screen the edges are less clean (the person is only 15 000 px at this size), and
    # the floor shadow must be told from the person by its colour: a lower bar than the chroma key's.
    check_against_truth(features, labels, camera, pose, min_iou=0.9)


def test_no_person_gives_empty_features(studio_frame):
    features = extractor()(studio_frame[4])
    assert not features.person and not features.silhouette.any()
    assert not any(k.visible for k in features.keypoints.values())


def test_parameter_defaults_agree_and_bad_values_are_one_line_errors(tmp_path):
    defaults = {p.name: p.default for p in CAMERA_FEATURES}
    assert load_feature_settings() == FeatureSettings(**{k: v for k, v in defaults.items()
                                                 if k in FeatureSettings.__dataclass_fields__})
    for text, fragment in (("/**: {ros__parameters: {sleeves: medium}}", 'sleeves'),
                           ("/**: {ros__parameters: {blueness_threshold: 999}}", 'blueness_threshold'),
                           ("/**: {ros__parameters: {colour: 3}}", 'unknown parameter'),
                           ("just text", 'not a ROS params file')):
        path = tmp_path / 'params.yaml'
        path.write_text(text)
        with pytest.raises(ParameterError, match=fragment):
            load_feature_settings(path)


def test_skin_train_command_and_its_errors(tmp_path):
    folder = tmp_path / 'pairs'
    folder.mkdir()
    image = np.full((60, 80, 3), BLUE[::-1], np.uint8)
    image[20:40, 30:50] = (110, 140, 200)  # BGR skin-like patch
    mask = np.zeros((60, 80), np.uint8)
    mask[20:40, 30:50] = 255
    cv2.imwrite(str(folder / 'a.png'), image)
    cv2.imwrite(str(folder / 'a_skin.png'), mask)
    run_mvpose('skin', 'train', folder, '-o', tmp_path / 'model.npz')
    model = SkinModel.load(tmp_path / 'model.npz')
    assert model.skin_counts.sum() == 400
    assert model.likelihood(cv2.cvtColor(image, cv2.COLOR_BGR2RGB))[30, 40] > 0
    assert_one_line_error(run_mvpose('skin', 'train', tmp_path / 'nothing', '-o', tmp_path / 'x.npz', check=False),
                          'nothing')


def test_eval_and_bench_commands_print_their_tables(tmp_path):
    bag = tmp_path / 'small'
    run_mvpose('synth', '--cameras', 5, '--frames', '70-71', '--resolution', '640x360', '-o', bag, timeout=300)
    table = run_mvpose('features', 'eval', bag).stdout
    assert 'silhouette IoU' in table and 'skin' in table and 'contour labels' in table
    head_row = next(line for line in table.splitlines() if line.split()[:1] == ['head'])
    assert head_row.split()[1] == '2/2'
    bench = run_mvpose('features', 'bench', bag).stdout
    assert 'pipeline (all stages)' in bench and 'JPEG decode' in bench
