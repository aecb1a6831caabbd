"""Camera features step by step on synthetic images with known answers (seeded). The whole pipeline with
the shipped skin model: test_features_pipeline.py; `skin train`, `features eval` and `bench`: test_commands.py."""
import math

import cv2
import numpy as np
import pytest

from mvpose_nodes.vision.features import ellipse_of
from mvpose_nodes.vision.silhouette import (COUNTED_LABELS, BackgroundModel, chroma_key_foreground, clean_mask,
                                            component_box, components, silhouette_keypoints)

pytestmark = pytest.mark.pure

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


@pytest.mark.parametrize('connectivity', [4, 8])
@pytest.mark.parametrize('density, labels_counted', [(0.02, False), (0.001, True)])
def test_components_give_opencvs_labels_areas_and_boxes(connectivity, density, labels_counted):
    # components() replaces cv2.connectedComponentsWithStats (7x slower here): the same components, whether
    # each label's pixels are counted in a pass of its own (few labels) or by a bincount (many).
    rng = np.random.default_rng(connectivity)
    mask = cv2.dilate((rng.random((120, 90)) < density).astype(np.uint8), np.ones((3, 3), np.uint8))
    labels, areas = components(mask.astype(bool), connectivity)
    count, expected_labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=connectivity)
    assert len(areas) == count and (2 < count <= COUNTED_LABELS) == labels_counted
    assert areas.dtype == np.int64
    np.testing.assert_array_equal(labels, expected_labels)
    np.testing.assert_array_equal(areas, stats[:, cv2.CC_STAT_AREA])
    for label in range(1, count):
        assert component_box(labels, label) == tuple(int(v) for v in stats[label, :4])


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
