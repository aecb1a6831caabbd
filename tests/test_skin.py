"""Skin detection by the smoothed colour-histogram likelihood ratio (paper 000 Sec. 3.2), on seeded
synthetic images: skin colours around RGB (200, 140, 110), background blues, greys and dark reds.

SkinModel.likelihood of a random 1920×1080 image: median 5.5 ms over 30 runs pinned to one core
(taskset -c 0, NumPy 2.4, the development machine). Not asserted: timings vary between machines.
"""
import io

import cv2
import numpy as np
import pytest

from mvpose_nodes.vision.skin import (BINS, SkinModel, SkinModelError, detect_skin, mask_counts, scores_of_counts,
                                     skin_on_cloth, skin_regions, surround_contrast)

pytestmark = pytest.mark.pure


def f1_score(predicted, truth):
    """(precision, recall, F1) of a bool predicted mask against a bool truth mask of the same
    shape; each is 0.0 where its denominator is 0."""
    return scores_of_counts(*mask_counts(predicted, truth))


SKIN_MEAN, SKIN_SPREAD = (200, 140, 110), 12
BACKGROUND_MEANS = ((40, 70, 180), (110, 25, 30))  # blue, dark red; plus greys of any level
SHAPE = (120, 160)


def colours(rng, count, mean, spread):
    return np.clip(rng.normal(mean, spread, (count, 3)), 0, 255).astype(np.uint8)


def background(rng, shape=SHAPE):
    """RGB uint8 (H, W, 3): an even mix of blue, dark-red and grey pixels."""
    count = shape[0] * shape[1]
    greys = np.clip(rng.uniform(30, 230, (count, 1)) + rng.normal(0, 4, (count, 3)), 0, 255).astype(np.uint8)
    pixels = np.concatenate([colours(rng, count, mean, 15) for mean in BACKGROUND_MEANS] + [greys])
    return rng.permutation(pixels)[:count].reshape(*shape, 3)


def paint_skin(rng, image, mask):
    image[mask] = colours(rng, np.count_nonzero(mask), SKIN_MEAN, SKIN_SPREAD)
    return image


def scene(seed):
    """(image, skin mask): background with a few skin ellipses (face, hands, forearm)."""
    rng = np.random.default_rng(seed)
    rows, cols = np.mgrid[:SHAPE[0], :SHAPE[1]]
    mask = np.zeros(SHAPE, bool)
    for _ in range(4):
        (cy, cx), (ry, rx) = rng.uniform((15, 15), (SHAPE[0] - 15, SHAPE[1] - 15)), rng.uniform(5, 14, 2)
        mask |= ((rows - cy) / ry) ** 2 + ((cols - cx) / rx) ** 2 <= 1
    return paint_skin(rng, background(rng), mask), mask


@pytest.fixture(scope='module')
def model():
    trained = SkinModel.empty()
    for seed in range(6):
        trained.add(*scene(seed))
    return trained


def test_added_counts_sum_to_the_labelled_pixels():
    image, skin = scene(0)
    valid = np.zeros(SHAPE, bool)
    valid[10:90, 20:130] = True
    model = SkinModel.empty().add(image, skin).add(image, skin, valid)
    assert model.skin_counts.sum() == np.count_nonzero(skin) + np.count_nonzero(skin & valid)
    assert model.background_counts.sum() == np.count_nonzero(~skin) + np.count_nonzero(~skin & valid)
    r, g, b = image[skin][0] >> 3
    assert model.skin_counts[r, g, b] >= 2  # the pixel counted in its bin, by both adds if valid


def test_log_likelihood_is_the_smoothed_ratio(model):
    table, alpha, bins3 = model.log_likelihood, model.alpha, BINS ** 3
    n_skin, n_background = model.skin_counts.sum(), model.background_counts.sum()
    assert table.shape == (BINS,) * 3 and table.dtype == np.float32 and np.isfinite(table).all()
    assert model.log_likelihood is table  # cached
    skin_bin = tuple(np.array(SKIN_MEAN) >> 3)
    blue_bin = tuple(np.array(BACKGROUND_MEANS[0]) >> 3)
    empty_bin = (0, 31, 0)  # pure green: in neither histogram
    assert model.skin_counts[empty_bin] == model.background_counts[empty_bin] == 0
    for bin_ in (skin_bin, blue_bin, empty_bin):
        expected = (np.log((model.skin_counts[bin_] + alpha * n_skin / bins3) / (n_skin * (1 + alpha)))
                    - np.log((model.background_counts[bin_] + alpha * n_background / bins3)
                             / (n_background * (1 + alpha))))
        assert table[bin_] == pytest.approx(expected, rel=1e-5, abs=1e-6)
    assert table[empty_bin] == 0  # no evidence either way, however unequal the classes are
    assert table[skin_bin] > 3 and table[blue_bin] < -3


def test_likelihood_looks_up_the_bin_of_each_pixel(model):
    pixels = np.array([[[255, 8, 7], [0, 0, 0], [200, 140, 110]]], np.uint8)
    expected = [model.log_likelihood[31, 1, 0], model.log_likelihood[0, 0, 0], model.log_likelihood[25, 17, 13]]
    assert model.likelihood(pixels).tolist() == [expected]
    assert model.likelihood(pixels).dtype == np.float32


def test_adding_invalidates_the_cached_table():
    image, skin = scene(1)
    model = SkinModel.empty()
    assert (model.log_likelihood == 0).all()
    assert not (model.add(image, skin).log_likelihood == 0).all()


def test_merging_models_counts_as_adding_their_images_to_one():
    merged = SkinModel.empty().add(*scene(0))
    table = merged.log_likelihood
    merged.merge(SkinModel.empty().add(*scene(1)))
    together = SkinModel.empty().add(*scene(0)).add(*scene(1))
    assert np.array_equal(merged.skin_counts, together.skin_counts)
    assert np.array_equal(merged.background_counts, together.background_counts)
    assert merged.log_likelihood is not table and np.array_equal(merged.log_likelihood, together.log_likelihood)


def test_detection_on_a_fresh_image_has_f1_above_0_95(model):
    image, truth = scene(100)
    precision, recall, f1 = f1_score(detect_skin(model, image), truth)
    assert f1 > 0.95, (precision, recall)


def test_higher_threshold_gives_a_subset_of_the_skin(model):
    image, _ = scene(101)
    masks = [detect_skin(model, image, threshold) for threshold in (-4, -1, 0, 2, 5, 8)]
    for looser, stricter in zip(masks, masks[1:]):
        assert not (stricter & ~looser).any()
    assert np.count_nonzero(masks[0]) > np.count_nonzero(masks[-1])


def test_region_restricts_detection(model):
    image, _ = scene(102)
    everywhere = detect_skin(model, image)
    region = np.zeros(SHAPE, bool)
    region[:, :80] = True
    inside = detect_skin(model, image, region=region)
    assert everywhere[:, 80:].any() and inside.any() and not inside[:, 80:].any()
    assert (detect_skin(model, image, region=np.ones(SHAPE, bool)) == everywhere).all()
    assert not detect_skin(model, image, region=np.zeros(SHAPE, bool)).any()


def test_cropping_to_the_region_changes_nothing(model):
    """With the colours outside the region made non-skin, detecting everywhere gives the same mask
    (min_area off: it is applied after the region on one side and before it on the other)."""
    image, _ = scene(103)
    region = np.zeros(SHAPE, bool)
    region[30:90, 40:120] = True
    outside_blue = image.copy()
    outside_blue[~region] = BACKGROUND_MEANS[0]
    reference = detect_skin(model, outside_blue, min_area=0) & region
    assert reference.any() and (detect_skin(model, image, region=region, min_area=0) == reference).all()


def blobs_image():
    """(image, mask) with a 20×20 skin square at x 10..29, y 20..39 and a 4×4 one at x 100..103, y 80..83."""
    rng = np.random.default_rng(5)
    mask = np.zeros(SHAPE, bool)
    mask[20:40, 10:30] = True
    mask[80:84, 100:104] = True
    return paint_skin(rng, np.full((*SHAPE, 3), BACKGROUND_MEANS[0], np.uint8), mask), mask


def test_closing_does_not_bridge_into_gaps_of_the_region(model):
    image, _ = blobs_image()
    region = np.ones(SHAPE, bool)
    region[:, 19:21] = False  # a 2 px slit through the large square, which a radius-2 closing would fill
    detected = detect_skin(model, image, region=region)
    assert detected[25:35, 15:19].all() and not detected[:, 19:21].any()


def test_min_area_removes_a_small_blob_but_keeps_a_large_one(model):
    image, _ = blobs_image()
    detected = detect_skin(model, image, min_area=30)
    # The opening (radius 1: a 3×3 cross) trims the squares' corner pixels and nothing else.
    assert np.count_nonzero(detected[20:40, 10:30]) == 400 - 4 and not detected[80:84, 100:104].any()
    assert np.count_nonzero(detect_skin(model, image, min_area=10)[80:84, 100:104]) == 16 - 4


def test_skin_regions_largest_first_with_outer_contours():
    _, mask = blobs_image()
    large, small = skin_regions(mask, min_area=10)
    assert (large.area, large.bbox, small.area, small.bbox) == (400, (10, 20, 20, 20), 16, (100, 80, 4, 4))
    assert large.centroid == pytest.approx((19.5, 29.5))
    assert large.boundary.dtype == np.int32 and len(large.boundary) == 4 * 19
    assert mask[large.boundary[:, 1], large.boundary[:, 0]].all()
    assert tuple(large.boundary.min(axis=0)) == (10, 20) and tuple(large.boundary.max(axis=0)) == (29, 39)
    assert [region.area for region in skin_regions(mask)] == [400]


@pytest.mark.parametrize('counts_scale', [1.0, 0.5])
def test_save_load_round_trip(model, tmp_path, counts_scale):
    original = SkinModel(model.skin_counts * counts_scale, model.background_counts * counts_scale, 0.5)
    path = tmp_path / 'skin_model'  # no suffix: saved at exactly this path
    original.save(path)
    with np.load(path) as stored:
        assert stored['skin_counts'].dtype == (np.uint32 if counts_scale == 1.0 else np.float64)
    loaded = SkinModel.load(path)
    assert (loaded.skin_counts == original.skin_counts).all()
    assert (loaded.background_counts == original.background_counts).all()
    assert loaded.alpha == 0.5 and (loaded.log_likelihood == original.log_likelihood).all()


def npy_bytes(array):
    buffer = io.BytesIO()
    np.save(buffer, array)
    return buffer.getvalue()


def write_npz(path, **changes):
    fields = dict(skin_counts=np.zeros((BINS,) * 3, np.uint32), background_counts=np.zeros((BINS,) * 3, np.uint32),
                  alpha=1.0, version=1)
    np.savez(path, **{**fields, **changes})


@pytest.mark.parametrize('make_file', [
    lambda path: None,                                                    # missing
    lambda path: path.write_text('not a model\n'),                        # not an npz
    lambda path: path.write_bytes(npy_bytes(np.zeros(3))),                # a bare .npy
    lambda path: write_npz(path, skin_counts=np.zeros((16, 16, 16))),
    lambda path: write_npz(path, version=2),
    lambda path: write_npz(path, alpha=0.0),
    lambda path: write_npz(path, background_counts=None),     # pickled object array
], ids=['missing', 'text', 'npy', 'shape', 'version', 'alpha', 'object'])
def test_bad_model_file_is_a_one_line_user_error_naming_it(tmp_path, make_file):
    path = tmp_path / 'broken_model.npz'
    make_file(path)
    with pytest.raises(SkinModelError, match='broken_model.npz') as raised:
        SkinModel.load(path)
    assert '\n' not in str(raised.value)


def test_surround_contrast_tells_a_hand_from_a_patch_of_cloth_of_its_colour():
    # A tan sleeve with a skin-coloured patch in it (the cloth's colour, a little lighter) and a hand of
    # the same lightness but skin's chroma at its end; the rest is blue screen, which is not the person.
    rng = np.random.default_rng(3)
    cloth, hand = (150, 120, 90), (200, 140, 110)
    lab = cv2.cvtColor(np.array([[cloth, hand]], np.uint8), cv2.COLOR_RGB2LAB)[0].astype(float)
    chroma_distance = np.linalg.norm(lab[0, 1:] - lab[1, 1:])
    image = colours(rng, 100 * 200, (40, 70, 180), 4).reshape(100, 200, 3)
    silhouette = np.zeros((100, 200), bool)
    silhouette[30:70, 10:150] = True
    image[silhouette] = colours(rng, silhouette.sum(), cloth, 3)
    patch, hand_mask = np.zeros_like(silhouette), np.zeros_like(silhouette)
    patch[40:60, 40:60] = True
    image[patch] = colours(rng, patch.sum(), (165, 132, 100), 3)   # the cloth lit more brightly
    hand_mask[35:65, 150:185] = silhouette[35:65, 150:185] = True
    image[hand_mask] = colours(rng, hand_mask.sum(), hand, 3)
    skin = patch | hand_mask
    hand_region, patch_region = skin_regions(skin, min_area=10)   # largest first: the hand is 30×35 px
    assert surround_contrast(image, skin, patch_region, silhouette, 3) < 2
    assert surround_contrast(image, skin, hand_region, silhouette, 3) == pytest.approx(chroma_distance, abs=2)
    # With no person around it (the silhouette is the region itself) there is nothing to compare with.
    assert surround_contrast(image, skin, hand_region, hand_mask, 3) is None


def test_skin_on_cloth_keeps_the_hand_and_drops_the_sleeve_of_skin_colour():
    # A beige sleeve that the skin model takes for skin, shaded darker along its length, and a hand of the same
    # lightness but skin's redness at its end (CIE a* 130 and 138 + 128): one skin region, too large for a hand.
    rng = np.random.default_rng(5)
    sleeve, hand = np.zeros((100, 200), bool), np.zeros((100, 200), bool)
    sleeve[30:70, 10:150] = True
    hand[35:65, 150:185] = True
    image = colours(rng, 100 * 200, (40, 70, 180), 4).reshape(100, 200, 3)
    shading = np.linspace(0.7, 1.0, 140)[None, :, None]
    image[30:70, 10:150] = np.clip(shading * (194, 178, 152) + rng.normal(0, 3, (40, 140, 3)), 0, 255).astype(np.uint8)
    image[hand] = colours(rng, hand.sum(), (206, 170, 149), 3)
    skin = sleeve | hand
    regions = skin_regions(skin, min_area=10)
    assert len(regions) == 1
    kept, changed = skin_on_cloth(image, skin, regions, max_area=3000, redness=3, opening=2)
    assert changed and (kept & sleeve).sum() < 0.01 * sleeve.sum()
    assert (kept & hand).sum() > 0.9 * hand.sum()
    # A region no larger than max_area is left as it is.
    same, changed = skin_on_cloth(image, skin, regions, max_area=regions[0].area, redness=3, opening=2)
    assert same is skin and not changed


def test_f1_score_of_known_masks():
    truth = np.zeros((4, 4), bool)
    truth[0, :] = True
    truth[1, 0] = True  # 5 px
    predicted = np.zeros((4, 4), bool)
    predicted[0, 1:] = True
    predicted[3, 3] = True  # 4 px, 3 of them true
    precision, recall, f1 = f1_score(predicted, truth)
    assert (precision, recall) == (0.75, 0.6) and f1 == pytest.approx(2 / 3)
    assert f1_score(truth, truth) == (1.0, 1.0, 1.0)
    assert f1_score(np.zeros((4, 4), bool), truth) == (0.0, 0.0, 0.0)
    assert f1_score(np.zeros((4, 4), bool), np.zeros((4, 4), bool)) == (0.0, 0.0, 0.0)
