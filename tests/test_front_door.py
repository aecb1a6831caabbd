"""./mvpose, the front door: help for every subcommand, set-up that is skipped when nothing changed,
the environment it gives, and one-line errors: its own, and those of the bag and topic tools, bench and
the nodes on bad input that needs no running graph."""
import os
import subprocess

import pytest
from common import ROOT, assert_one_line_error, mvpose_command, run_mvpose

pytestmark = pytest.mark.cli

SUBCOMMANDS = [['test'], ['demo'], ['run'], ['exec'], ['launch'], ['bag'], ['bag', 'record'], ['bag', 'play'],
               ['bag', 'info'], ['topic'], ['topic', 'echo'], ['topic', 'list'], ['topic', 'hz'], ['topic', 'bw'], ['topic', 'pub'],
               ['doctor']]


def test_top_level_help_lists_every_subcommand():
    out = run_mvpose('--help').stdout
    for command in ('test', 'demo', 'run', 'exec', 'launch', 'bag', 'topic'):
        assert command in out


@pytest.mark.parametrize('words', SUBCOMMANDS, ids=' '.join)
def test_every_subcommand_has_help(words):
    result = run_mvpose(*words, '--help')
    assert 'usage' in result.stdout.lower()


def test_warm_call_does_no_set_up():
    result = run_mvpose('exec', 'true')
    assert 'set-up' not in result.stderr, result.stderr


def test_dds_stays_on_this_machine_unless_the_user_says_otherwise():
    show = ['exec', 'python', '-c', 'import os; print(os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"])']
    environment = {k: v for k, v in os.environ.items() if k != 'ROS_AUTOMATIC_DISCOVERY_RANGE'}
    default = subprocess.run(mvpose_command(*show), capture_output=True, text=True, env=environment, cwd=ROOT)
    assert default.stdout.strip() == 'LOCALHOST'
    chosen = subprocess.run(mvpose_command(*show), capture_output=True, text=True, cwd=ROOT,
                            env={**environment, 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET'})
    assert chosen.stdout.strip() == 'SUBNET'


def test_run_and_exec_see_the_workspace():
    result = run_mvpose('exec', 'python', '-c', 'import mvpose_msgs.msg, mvpose_nodes, rclpy; print("ok")')
    assert result.stdout.strip() == 'ok'
    assert 'usage' in run_mvpose('run', 'bag', '--help').stdout


def test_front_door_errors_are_one_line():
    assert_one_line_error(run_mvpose('run', 'no_such_node', check=False), 'no_such_node', 'bag')
    assert_one_line_error(run_mvpose('exec', 'no-such-program', check=False), 'no-such-program')
    assert_one_line_error(run_mvpose('launch', 'no_such_file.yaml', check=False), 'no_such_file.yaml')


# ---- bag and topic tools -------------------------------------------------------------------------

def test_non_mcap_file_is_one_line_error(tmp_path):
    text_file = tmp_path / 'notes.mcap'
    text_file.write_text('not a bag\n')
    for verb in ('info', 'play'):
        assert_one_line_error(run_mvpose('bag', verb, text_file, check=False), str(text_file), 'not an MCAP file')


def test_missing_bag_is_one_line_error(tmp_path):
    for verb in ('info', 'play'):
        assert_one_line_error(run_mvpose('bag', verb, tmp_path / 'nowhere', check=False), 'no such file')


def test_unknown_subcommands_are_one_line_errors():
    assert_one_line_error(run_mvpose('frobnicate', check=False), "invalid choice: 'frobnicate'")
    assert_one_line_error(run_mvpose('bag', 'frobnicate', check=False), "invalid choice: 'frobnicate'")
    assert_one_line_error(run_mvpose('topic', 'frobnicate', check=False), "invalid choice: 'frobnicate'")


def test_unknown_topic_type_is_one_line_error(tmp_path):
    from mcap.writer import Writer
    bag = tmp_path / 'foreign.mcap'
    with open(bag, 'wb') as stream:
        writer = Writer(stream)
        writer.start(profile='ros2', library='test')
        schema = writer.register_schema(name='nonexistent_msgs/msg/Thing', encoding='ros2msg', data=b'int32 a\n')
        channel = writer.register_channel(topic='/thing', message_encoding='cdr', schema_id=schema)
        writer.add_message(channel_id=channel, log_time=1, publish_time=1, data=b'\x00\x01\x00\x00\x07\x00\x00\x00')
        writer.finish()
    assert_one_line_error(run_mvpose('bag', 'play', bag, check=False), 'nonexistent_msgs/msg/Thing')
    info = run_mvpose('bag', 'info', bag)  # info needs no type support: it still describes the bag
    assert 'Type: nonexistent_msgs/msg/Thing | Count: 1' in info.stdout
    assert_one_line_error(run_mvpose('topic', 'echo', '/thing', 'nonexistent_msgs/msg/Thing', check=False),
                          'nonexistent_msgs')


def test_echo_without_publisher_times_out_cleanly():
    result = run_mvpose('topic', 'echo', '/test/nobody', '--timeout', 1, check=False)
    assert_one_line_error(result, '/test/nobody')


# ---- bench ---------------------------------------------------------------------------------------

def test_bad_input_is_one_line(tmp_path):
    assert_one_line_error(run_mvpose('bench', '--window', 0, check=False), '--window must be at least 1')
    assert_one_line_error(run_mvpose('bench', tmp_path / 'nothing', check=False), 'not found')
    (tmp_path / 'run').mkdir()
    assert_one_line_error(run_mvpose('bench', tmp_path, '-o', tmp_path / 'run', check=False), 'already exists')
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import CameraInfo
    from mvpose_nodes.io.bagfile import BagWriter
    with BagWriter(tmp_path / 'cam3_only') as out:
        out.add_topic('/cam3/camera_info', 'sensor_msgs/msg/CameraInfo')
        out.write('/cam3/camera_info', serialize_message(CameraInfo()), 1)
    assert_one_line_error(run_mvpose('bench', tmp_path / 'cam3_only', check=False),
                          'lacks', '/cam3/image_raw/compressed', '/cam5/image_raw/compressed')


# ---- nodes (they stop before they join a graph) --------------------------------------------------

def test_node_outside_a_camera_namespace_is_a_one_line_error():
    result = run_mvpose('run', 'camera_features', check=False, timeout=60)
    assert_one_line_error(result, '/cam<K>')


def test_bad_parameter_is_a_one_line_error():
    result = run_mvpose('run', 'camera_features', '--ros-args', '-r', '__ns:=/cam3', '-p', 'sleeves:=medium',
                        check=False, timeout=60)
    assert_one_line_error(result, 'sleeves')
