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


def test_demo_runs_the_graph_on_a_bag_and_writes_its_results(tmp_path):
    """The demo's whole path on a 4-frame bag: the graph over DDS fits every frame set, Table 2 is printed,
    and the output folder gets the recorded skeletons, the pictures, the animation and the BVH."""
    bag = tmp_path / 'walk'
    run_mvpose('synth', '--cameras', 3, 5, 7, '--frames', '70-73', '--resolution', '960x540', '-o', bag, timeout=300)
    output = tmp_path / 'results'
    result = run_mvpose('demo', '--bag', bag, '-o', output, '--rate', 0.1, timeout=240)
    frames = [line for line in result.stdout.splitlines() if line.startswith('[demo] frame')]
    assert sorted(int(line.split()[2]) for line in frames) == [70, 71, 72, 73], result.stdout
    assert 'fitted 4 of its 4 frame sets' in result.stdout
    assert '(4 frames matched by stamp)' in result.stdout and 'Eq. 12 per frame' in result.stdout
    for name in ('error_per_frame.png', 'fit_over_cam5.mp4', 'fitted.bvh', 'graph.log', 'fitted/metadata.yaml'):
        assert (output / name).is_file(), name
    assert len(list(output.glob('contact_sheet_frame7?.png'))) == 1

