"""The input-order rules of the per-camera nodes, without ROS: marker_tracker's start from the labelled
frame (the labelling and its image race), its turns with the fused tracks, and camera_features'
background learning."""
import numpy as np
import pytest

from mvpose_nodes.markers.sequencing import FusedTurns, LabelledStart
from mvpose_nodes.vision.silhouette import BackgroundLearner, BackgroundModel

pytestmark = pytest.mark.pure


def test_a_labelling_that_comes_first_waits_for_its_image():
    start = LabelledStart()
    assert start.add_labelling(100, 'labels@100') == []
    assert start.labelling_for(100, 'image@100') == 'labels@100'


def test_images_that_come_first_are_held_and_released_in_stamp_order_from_the_labelled_one():
    start = LabelledStart(images_kept=3)
    for stamp in (120, 80, 100):
        assert start.labelling_for(stamp, f'image@{stamp}') is None
    # 80 came before the labelled frame: it cannot be tracked from it and is not released
    assert start.add_labelling(100, 'labels@100') == ['image@100', 'image@120']
    assert start.waiting == {}


def test_only_the_last_images_are_held():
    start = LabelledStart(images_kept=2)
    for stamp in (10, 20, 30):
        start.labelling_for(stamp, stamp)
    assert sorted(start.waiting) == [20, 30]
    assert start.add_labelling(10, 'late labels') == []   # its image was forgotten


def test_old_labellings_are_forgotten_and_a_rejected_one_is_gone():
    start = LabelledStart(labellings_kept=2)
    for stamp in (1, 2, 3):
        start.add_labelling(stamp, stamp)
    assert sorted(start.labellings) == [2, 3]
    start.reject(3)
    assert start.labelling_for(3, 'image') is None
    start.started()
    assert start.labellings == {} and start.waiting == {}


def test_each_image_waits_for_the_fusion_of_the_one_before():
    turns = FusedTurns(fused_wait=1.0)
    turns.push('a')
    turns.push('b')
    assert turns.next_item(now=0.0, fusion_published=True) == 'a'
    turns.sent(stamp=1, now=0.0)
    assert turns.next_item(now=0.5, fusion_published=True) is None, 'a\'s fusion is awaited'
    assert not turns.fused(stamp=7), 'not the awaited stamp'
    assert turns.fused(stamp=1)
    assert turns.next_item(now=0.6, fusion_published=True) == 'b'


def test_the_wait_ends_after_fused_wait_or_at_once_without_a_fusion_publisher():
    turns = FusedTurns(fused_wait=1.0)
    for item in 'abc':
        turns.push(item)
    assert turns.next_item(0.0, True) == 'a'
    turns.sent(1, now=0.0)
    assert turns.next_item(0.99, True) is None
    assert turns.next_item(1.0, True) == 'b', 'fused_wait has passed'
    turns.sent(2, now=1.0)
    assert turns.next_item(1.1, False) == 'c', 'nobody publishes fused tracks'
    assert turns.next_item(5.0, False) is None
    assert not turns.fused(1), 'late fusion of an earlier image'


def test_the_queue_drops_the_oldest_beyond_its_bound():
    turns = FusedTurns(fused_wait=0.0, queue_kept=2)
    assert not turns.push(1) and not turns.push(2)
    assert turns.push(3)
    assert list(turns.queue) == [2, 3]


def test_background_learning_gives_the_model_of_the_first_frames_then_starts_again():
    rng = np.random.default_rng(3)
    frames = [rng.integers(0, 255, (6, 8, 3), dtype=np.uint8) for _ in range(3)]
    learner = BackgroundLearner(frames_needed=3)
    assert learner.add(frames[0]) is None and learner.add(frames[1]) is None
    model = learner.add(frames[2])
    expected = BackgroundModel.from_frames(frames)
    np.testing.assert_array_equal(model.mean, expected.mean)
    np.testing.assert_array_equal(model.variance, expected.variance)
    assert learner.frames == []
