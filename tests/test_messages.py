"""The package against the ROS message definitions: its label and status constants are the messages',
MarkerTracks converts both ways, and a bag whose messages do not decode is one line naming bag and topic."""
import numpy as np
import pytest
from mvpose_msgs.msg import LabelledContour, Skeleton

from mvpose_nodes.body import model
from mvpose_nodes.io.motion_export import STATUS_NAMES
from mvpose_nodes.markers.detection import FLAG_DETECTED

pytestmark = pytest.mark.cli


def test_part_labels_equal_the_message_constants():
    for name, value in model.PART_LABELS.items():
        assert getattr(LabelledContour, f'LABEL_{name.upper()}') == value


def test_status_names_are_the_message_constants():
    assert STATUS_NAMES == {Skeleton.STATUS_OK: 'OK', Skeleton.STATUS_INITIALISING: 'INITIALISING',
                            Skeleton.STATUS_DEGRADED: 'DEGRADED', Skeleton.STATUS_LOST: 'LOST'}


def test_marker_tracks_message_round_trip_and_bad_messages():
    from std_msgs.msg import Header
    from mvpose_nodes.ros.conversions import marker_tracks, tracks_from_message
    rng = np.random.default_rng(0)
    positions, flags = rng.uniform(0, 1000, (15, 2)), rng.integers(0, 2, 15)
    message = marker_tracks(Header(), positions, flags)
    back, back_flags = tracks_from_message(message)
    np.testing.assert_array_equal(back, positions)
    np.testing.assert_array_equal(back_flags, flags)
    message.names = message.names[::-1]                  # another order: read back by name
    message.x, message.y, message.flags = message.x[::-1], message.y[::-1], message.flags[::-1]
    np.testing.assert_array_equal(tracks_from_message(message)[0], positions)
    message.flags = message.flags[:3]
    with pytest.raises(ValueError, match='differ in length'):
        tracks_from_message(message)


def test_a_bag_whose_markers_do_not_decode_is_refused_in_one_line(tmp_path):
    """A MarkerTracks recorded with another definition (here its last bytes cut off, as an older
    MarkerTracks without blobs reads) gives a one-line error naming the bag and topic, not a traceback."""
    from rclpy.serialization import serialize_message
    from std_msgs.msg import Header
    from mvpose_nodes.io.bagfile import BagWriter
    from mvpose_nodes.ros.camera_bag import frame_sets
    from mvpose_nodes.io.bagfile import BagError
    from mvpose_nodes.ros.conversions import marker_tracks
    data = serialize_message(marker_tracks(Header(), np.zeros((15, 2)), [FLAG_DETECTED] * 15, blobs=[[1.0, 2.0]]))
    with BagWriter(tmp_path / 'old') as bag:
        bag.add_topic('/cam3/ground_truth/markers', 'mvpose_msgs/msg/MarkerTracks')
        bag.write('/cam3/ground_truth/markers', data[:-12], 0)
    with pytest.raises(BagError, match=r"mvpose_msgs/msg/MarkerTracks on /cam3/ground_truth/markers does not decode") as error:
        list(frame_sets(tmp_path / 'old'))
    assert str(tmp_path / 'old') in str(error.value) and '\n' not in str(error.value)
