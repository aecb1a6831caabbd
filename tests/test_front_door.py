"""./mvpose, the front door: help for every subcommand, set-up that is skipped when nothing changed,
the environment it gives, and one-line errors."""
import os
import subprocess

import pytest
from conftest import ROOT, assert_one_line_error, mvpose_command, run_mvpose

SUBCOMMANDS = [['test'], ['demo'], ['run'], ['exec'], ['launch'], ['bag'], ['bag', 'record'], ['bag', 'play'],
               ['bag', 'info'], ['topic'], ['topic', 'echo'], ['topic', 'list'], ['topic', 'hz'], ['topic', 'pub']]


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


def test_demo_replays_a_bag_and_shows_every_skeleton(tmp_path):
    bag = tmp_path / 'walk'
    run_mvpose('synth', '--cameras', 3, 5, '--frames', '60-64', '--resolution', '320x180', '-o', bag, timeout=300)
    result = run_mvpose('demo', '--bag', bag, '-o', tmp_path / 'pictures', timeout=120)
    frames = [line for line in result.stdout.splitlines() if line.startswith('[demo] frame')]
    assert [int(line.split()[2]) for line in frames] == [60, 61, 62, 63, 64]
    assert 'shown: 5 of 5 skeletons' in result.stdout
    assert (tmp_path / 'pictures' / 'walk_preview.png').is_file()
