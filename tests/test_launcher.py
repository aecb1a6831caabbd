"""The launcher of ros2 launch YAML files: command lines, launch arguments and substitutions, output
prefixes, stopping, exit codes, launch-file errors, and the shipped launch files against the format.

Runtime tests start the launcher as a subprocess (it installs signal handlers) with small Python
scripts as its processes, so no ROS node is needed.
"""
import json
import os
import re
import shlex
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import yaml

from mvpose_nodes.tools.launch import Launch, load_launch_file, main, process_specs
from mvpose_nodes.tools.launch_file import package_prefix

pytestmark = pytest.mark.cli

LAUNCH_DIR = Path(__file__).resolve().parent.parent / 'ros_ws' / 'src' / 'mvpose_nodes' / 'launch'

# A stand-in process: prints 'ready' once its signal handling is in place, then exits or waits.
CHILD = '''
import argparse, pathlib, signal, sys, time
parser = argparse.ArgumentParser()
parser.add_argument('--lines', type=int, default=0)
parser.add_argument('--exit', type=int)
parser.add_argument('--ignore', nargs='*', default=[])
parser.add_argument('--ready-file')
parser.add_argument('--exit-when-exists')
args = parser.parse_args()

def on_signal(signum, frame):
    print('got', signal.Signals(signum).name)
    sys.exit(0)

for signum in (signal.SIGINT, signal.SIGTERM):
    signal.signal(signum, signal.SIG_IGN if signum.name in args.ignore else on_signal)
for number in range(args.lines):
    print('line', number)
print('ready')
if args.ready_file:
    pathlib.Path(args.ready_file).touch()
while args.exit_when_exists and not pathlib.Path(args.exit_when_exists).exists():
    time.sleep(0.02)
if args.exit is not None:
    sys.exit(args.exit)
time.sleep(60)
'''
TIMEOUTS = ['--sigint-timeout', '1', '--sigterm-timeout', '1']


@pytest.fixture
def child(tmp_path):
    """Writes child.py; gives the command line `python child.py ARGS...` as a YAML string for `cmd:`."""
    script = tmp_path / 'child.py'
    script.write_text(CHILD)
    return lambda *args: json.dumps(shlex.join(str(word) for word in (sys.executable, script, *args)))  # YAML too


def write_launch_file(tmp_path, text):
    path = tmp_path / 'launch.yaml'
    path.write_text(text)
    return path


def start_launcher(path, *options):
    launcher = subprocess.Popen([sys.executable, '-m', 'mvpose_nodes.tools.launch', str(path), *options],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    watchdog = threading.Timer(20, launcher.kill)  # a hanging launcher fails the test instead of blocking it
    watchdog.daemon = True
    watchdog.start()
    return launcher


def read_until(launcher, wanted):
    """Launcher output lines up to and including the last of `wanted` to appear."""
    lines, missing = [], set(wanted)
    while missing:
        line = launcher.stdout.readline()
        assert line, f'launcher ended before printing {missing}; output: {lines}'
        lines.append(line.rstrip('\n'))
        missing.discard(lines[-1])
    return lines


def run_launcher(path, *options):
    launcher = start_launcher(path, *options)
    stdout, stderr = launcher.communicate()
    return launcher.returncode, stdout.splitlines(), stderr


def test_dry_run_prints_the_ros_command_line_of_a_node_and_an_executable(tmp_path, capsys):
    (tmp_path / 'config').mkdir()
    (tmp_path / 'config' / 'features.yaml').write_text('camera_features:\n  ros__parameters: {}\n')
    marker = tmp_path / 'started'
    path = write_launch_file(tmp_path, f'''
launch:
  - node:
      pkg: mvpose_nodes
      exec: bag
      name: camera_features
      namespace: /cam3
      param:
        - from: $(dirname)/config/features.yaml
        - {{name: cameras, value: [3, 5, 7]}}
        - {{name: overlay, value: false}}
        - {{name: label, value: 'true'}}
      remap: [{{from: from, to: to}}]
      args: --verbose 3 true
      output: screen
  - node: {{pkg: mvpose_nodes, exec: bag, name: camera_features, namespace: cam5}}
  - executable:
      name: player
      cmd: {json.dumps(shlex.join([sys.executable, '-c', f"open('{marker}', 'w')", 'bags/x']))}
''')
    assert main([str(path), '--dry-run']) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 3 and lines[0].startswith('[/cam3/camera_features] ')  # one node name, told apart by namespace
    assert lines[1].startswith('[/cam5/camera_features] ')  # a relative namespace made absolute, as ros2 launch does
    command = shlex.split(lines[0].removeprefix('[/cam3/camera_features] '))
    assert command[0].endswith('/lib/mvpose_nodes/bag')
    assert command[1:] == ['--verbose', '3', 'true', '--ros-args', '-r', '__node:=camera_features', '-r', '__ns:=/cam3',
                           '--params-file', str(tmp_path / 'config' / 'features.yaml'),
                           '-p', 'cameras:=[3, 5, 7]', '-p', 'overlay:=false', '-p', "label:='true'",
                           '-r', 'from:=to']
    assert shlex.split(lines[1])[-2:] == ['-r', '__ns:=/cam5']
    assert shlex.split(lines[2]) == ['[player]', sys.executable, '-c', f"open('{marker}', 'w')", 'bags/x']
    assert not marker.exists()


ARGUMENTS_FILE = '''
launch:
  - arg: {name: camera_a, default: '3', description: first camera}
  - arg: {name: camera_b, default: '5'}
  - arg: {name: topic, default: image_raw}
  - arg: {name: label, default: 'cam$(var camera_a) view'}   # a default built from an earlier arg
  - node:
      pkg: mvpose_nodes
      exec: bag
      name: features
      namespace: /cam$(var camera_a)
      param:
        - {name: cameras, value: [$(var camera_a), $(var camera_b)]}
        - {name: label, value: $(var label)}
      remap: [{from: image, to: $(var topic)}, {from: info, to: camera_info}]
      args: --title $(var label) --id=$(var camera_b)x
'''


@pytest.mark.parametrize('overrides, cameras, topic, label', [
    ([], (3, 5), 'image_raw', 'cam3 view'),
    (['camera_a:=2', 'topic:=image_color'], (2, 5), 'image_color', 'cam2 view'),
    (['label:=x', 'camera_b:=8'], (3, 8), 'image_raw', 'x'),
])
def test_launch_arguments_take_their_defaults_or_name_value_from_the_command_line(
        tmp_path, capsys, overrides, cameras, topic, label):
    path = write_launch_file(tmp_path, ARGUMENTS_FILE)
    assert main([str(path), *overrides[:1], '--dry-run', *overrides[1:]]) == 0   # NAME:=VALUE anywhere, as ros2 launch
    line, = capsys.readouterr().out.splitlines()
    assert line.startswith(f'[/cam{cameras[0]}/features] ')
    # A substitution's result is one word, whatever it holds; text glued to it stays glued.
    assert shlex.split(line)[2:] == [
        '--title', label, f'--id={cameras[1]}x', '--ros-args', '-r', '__node:=features', '-r', f'__ns:=/cam{cameras[0]}',
        '-p', f'cameras:=[{cameras[0]}, {cameras[1]}]', '-p', f'label:={label}', '-r', f'image:={topic}',
        '-r', 'info:=camera_info']


def test_param_values_follow_launch_ros_typing_and_find_pkg_share_finds_the_params_file(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv('MVPOSE_TEST_RATE', '2.5')
    path = write_launch_file(tmp_path, '''
launch:
  - arg: {name: flag, default: 'true'}
  - arg: {name: number, default: '3'}
  - arg: {name: cameras, default: '[1, 2]'}
  - node:
      pkg: mvpose_nodes
      exec: bag
      name: typed
      param:
        - from: $(find-pkg-share mvpose_nodes)/config/camera_features.yaml
        - {name: plain_int, value: 3}
        - {name: quoted_int, value: '3'}            # a string stays a string
        - {name: substituted_int, value: $(var number)}   # a substitution is read as YAML
        - {name: substituted_flag, value: $(var flag)}
        - {name: text, value: cam$(var number)}
        - {name: rate, value: $(env MVPOSE_TEST_RATE)}
        - {name: fallback, value: $(env MVPOSE_TEST_UNSET_VARIABLE 7)}
        - {name: numbers, value: [1.0, 2.5]}
        - {name: names, value: [a, $(var flag)x]}
        - {name: substituted_list, value: $(var cameras)}   # read as YAML: a list
  - executable: {name: player, cmd: $(exec-in-pkg bag mvpose_nodes) play bags/x}
''')
    assert main([str(path), '--dry-run']) == 0
    node, player = capsys.readouterr().out.splitlines()
    command = shlex.split(node)[1:]
    params_file, prefix = command[command.index('--params-file') + 1], package_prefix('mvpose_nodes')
    assert params_file == str(prefix / 'share' / 'mvpose_nodes' / 'config' / 'camera_features.yaml')
    assert Path(params_file).is_file()
    values = [word for word in command if ':=' in word and not word.startswith('__')]
    assert values == ['plain_int:=3', "quoted_int:='3'", 'substituted_int:=3', 'substituted_flag:=true', 'text:=cam3',
                      'rate:=2.5', 'fallback:=7', 'numbers:=[1.0, 2.5]', 'names:=[a, truex]',
                      'substituted_list:=[1, 2]']
    assert shlex.split(player)[1:] == [str(prefix / 'lib' / 'mvpose_nodes' / 'bag'), 'play', 'bags/x']


def test_show_args_lists_the_launch_arguments(tmp_path, capsys):
    path = write_launch_file(tmp_path, ARGUMENTS_FILE)
    assert main([str(path), '--show-args']) == 0
    text = capsys.readouterr().out
    assert "'camera_a':\n        first camera\n        (default: '3')" in text
    assert "'label':\n        no description given\n        (default: 'cam$(var camera_a) view')" in text


def test_every_process_ending_with_0_exits_0_with_all_output_prefixed(tmp_path, child):
    path = write_launch_file(tmp_path, f'''
launch:
  - executable: {{name: talker, cmd: {child('--lines', '20000', '--exit', '0')}}}
  - executable: {{name: other, cmd: {child('--exit', '0')}}}
''')
    code, lines, stderr = run_launcher(path, *TIMEOUTS)
    assert code == 0, (lines, stderr)
    assert [line for line in lines if line.startswith('[talker] line')] == [f'[talker] line {n}' for n in range(20000)]
    assert '[other] ready' in lines
    assert any(line.startswith('[launch] started talker (pid ') for line in lines)
    assert lines.index('[talker] ready') < lines.index('[launch] talker exited with code 0')
    assert '[launch] other exited with code 0' in lines


def test_a_failing_process_that_is_not_required_makes_exit_code_1(tmp_path, child):
    path = write_launch_file(tmp_path, f'''
launch:
  - executable: {{name: fine, cmd: {child('--exit', '0')}}}
  - executable: {{name: broken, cmd: {child('--exit', '4')}}}
''')
    code, lines, _ = run_launcher(path, *TIMEOUTS)
    assert code == 1
    assert '[launch] broken exited with code 4' in lines
    assert '[launch] fine exited with code 0' in lines


def test_a_process_with_respawn_is_started_again_until_its_retries_are_used_up(tmp_path, child):
    """Issue 15: respawn, respawn_delay and respawn_max_retries as ros2 launch reads them: a process that
    keeps failing is started 1 + 2 times, each restart after the delay, then the launch ends with code 1."""
    path = write_launch_file(tmp_path, f'''
launch:
  - executable: {{name: flaky, cmd: {child('--exit', '3')}, respawn: 'true', respawn_delay: '0.3',
                  respawn_max_retries: '2'}}
''')
    started = time.monotonic()
    code, lines, _ = run_launcher(path, *TIMEOUTS)
    assert code == 1
    assert time.monotonic() - started > 0.6                  # two delays
    launch_lines = [re.sub(r'pid \d+', 'pid N', line) for line in lines if line.startswith('[launch] ')]
    assert launch_lines == ['[launch] started flaky (pid N)', '[launch] flaky exited with code 3',
                            '[launch] respawning flaky in 0.3 s (restart 1 of 2)',
                            '[launch] started flaky (pid N)', '[launch] flaky exited with code 3',
                            '[launch] respawning flaky in 0.3 s (restart 2 of 2)',
                            '[launch] started flaky (pid N)', '[launch] flaky exited with code 3']
    assert lines.count('[flaky] ready') == 3


def test_a_respawning_process_is_not_started_again_when_the_launch_stops(tmp_path, child):
    ready = tmp_path / 'ready'
    path = write_launch_file(tmp_path, f'''
launch:
  - executable: {{name: server, cmd: {child('--ready-file', ready)}, respawn: true}}
''')
    launcher = start_launcher(path, *TIMEOUTS)
    read_until(launcher, ['[server] ready'])
    launcher.send_signal(signal.SIGINT)
    stdout, _ = launcher.communicate()
    assert launcher.returncode == 130
    assert 'respawning' not in stdout


@pytest.mark.parametrize('key, value, message', [
    ('respawn', "'yes please'", "'respawn' must be true or false"),
    ('respawn_delay', "'-1'", "'respawn_delay' must be seconds >= 0"),
    ('respawn_max_retries', "'1.5'", "'respawn_max_retries' must be a count, or -1 for no limit"),
    ('on_exit', 'shutdown', "'respawn' and 'on_exit: shutdown' exclude each other")])
def test_bad_respawn_keys_are_one_line_errors(tmp_path, key, value, message):
    path = write_launch_file(tmp_path, f'''
launch:
  - executable: {{name: x, cmd: 'true', respawn: 'true', {key}: {value}}}
''')
    code, lines, stderr = run_launcher(path)
    assert code == 2 and not lines
    assert message in stderr and 'launch[0].executable' in stderr and len(stderr.strip().splitlines()) == 1


def test_a_required_process_ending_stops_the_others_with_exit_code_100_plus_its_position(tmp_path, child):
    ready = tmp_path / 'server-ready'
    path = write_launch_file(tmp_path, f'''
launch:
  - arg: {{name: unused, default: x}}   # not a process: K counts nodes and executables only
  - executable: {{name: server, cmd: {child('--ready-file', ready)}}}
  - executable: {{name: other, cmd: {child()}}}
  - executable: {{name: player, cmd: {child('--exit-when-exists', ready, '--exit', '3')}, on_exit: shutdown}}
''')
    started = time.monotonic()
    code, lines, _ = run_launcher(path, *TIMEOUTS)
    assert code == 103
    assert time.monotonic() - started < 10
    assert "[launch] required process 'player' ended with code 3; stopping the others" in lines
    assert '[server] got SIGINT' in lines
    assert '[launch] server exited with code 0' in lines
    assert any(line.startswith('[launch] other exited with code ') for line in lines)


@pytest.mark.parametrize('signum, expected_code', [(signal.SIGINT, 130), (signal.SIGTERM, 0)])
def test_a_signal_to_the_launcher_stops_every_process_with_sigint(tmp_path, child, signum, expected_code):
    path = write_launch_file(tmp_path, f'''
launch:
  - executable: {{name: first, cmd: {child()}}}
  - executable: {{name: second, cmd: {child()}}}
''')
    launcher = start_launcher(path, *TIMEOUTS)
    read_until(launcher, ['[first] ready', '[second] ready'])
    launcher.send_signal(signum)
    rest, stderr = launcher.communicate()
    assert launcher.returncode == expected_code, (rest, stderr)
    assert '[first] got SIGINT' in rest.splitlines()
    assert '[second] got SIGINT' in rest.splitlines()
    assert 'Traceback' not in stderr


def test_a_killed_launcher_leaves_no_process_behind(tmp_path, child):
    """Its processes run in sessions of their own (a terminal's Ctrl-C reaches them through the
    launcher); if the launcher is SIGKILLed they still end (SIGTERM on the parent's death)."""
    path = write_launch_file(tmp_path, f'''
launch:
  - executable: {{name: first, cmd: {child()}}}
''')
    launcher = start_launcher(path, *TIMEOUTS)
    lines = read_until(launcher, ['[first] ready'])
    pid = int(next(line for line in lines if line.startswith('[launch] started first')).split('pid ')[1].rstrip(')'))
    launcher.kill()
    launcher.communicate()
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline and os.path.exists(f'/proc/{pid}') and \
            open(f'/proc/{pid}/stat').read().split()[2] != 'Z':
        time.sleep(0.05)
    alive = os.path.exists(f'/proc/{pid}') and open(f'/proc/{pid}/stat').read().split()[2] != 'Z'
    if alive:
        os.kill(pid, signal.SIGKILL)
    assert not alive, 'the launched process outlived its killed launcher'


def test_processes_ignoring_sigint_get_sigterm_then_sigkill_and_exit_code_is_1(tmp_path, child):
    path = write_launch_file(tmp_path, f'''
launch:
  - executable: {{name: polite, cmd: {child()}}}
  - executable: {{name: deaf, cmd: {child('--ignore', 'SIGINT')}}}
  - executable: {{name: stubborn, cmd: {child('--ignore', 'SIGINT', 'SIGTERM')}}}
''')
    launcher = start_launcher(path, '--sigint-timeout', '0.5', '--sigterm-timeout', '0.5')
    read_until(launcher, ['[polite] ready', '[deaf] ready', '[stubborn] ready'])
    launcher.send_signal(signal.SIGINT)
    lines = launcher.communicate()[0].splitlines()
    assert launcher.returncode == 1
    assert '[polite] got SIGINT' in lines
    assert '[launch] sending SIGTERM to deaf, stubborn' in lines
    assert '[deaf] got SIGTERM' in lines
    assert '[launch] sending SIGKILL to stubborn' in lines
    assert '[launch] stubborn exited with code -9' in lines


def test_launch_library_stops_its_processes_when_the_block_ends(tmp_path, child, capsys):
    specs = process_specs([{'executable': {'name': 'waiter', 'cmd': shlex.join([sys.executable, str(tmp_path / 'child.py')])}}],
                          tmp_path)
    with Launch(specs, sigint_timeout=1, sigterm_timeout=1) as launch:
        assert launch.wait(timeout=0.2) is None
    assert launch.exit_code == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[-3:] == ['[launch] sending SIGINT to waiter', '[waiter] got SIGINT',
                          '[launch] waiter exited with code 0']


NODE = 'pkg: mvpose_nodes, exec: bag, name: a'


@pytest.mark.parametrize('text, message', [
    (None, "file not found"),
    ('launch: [', 'not valid YAML (line '),
    ('- node: {name: a}', "expected ros2 launch's YAML format: a mapping with just a 'launch' list"),
    ('nodes: [{name: a, cmd: [echo]}]', "expected ros2 launch's YAML format: a mapping with just a 'launch' list"),
    ('launch: 3', "'launch' must be a list of actions (arg, node, executable)"),
    ('launch: [{arg: {name: x, default: a}}]', 'no node or executable to start'),
    ('launch: [{node: {}, executable: {}}]', 'launch[0]: must be a mapping with one key, the action'),
    ('launch: [{group: [{node: {name: a}}]}]', "launch[0]: unsupported action 'group' (supported: arg, node, "),
    ('launch: [{executable: {name: a, cmd: echo, colour: red}}]',
     "launch[0].executable: unsupported key 'colour' (supported: cmd, name, output, on_exit, respawn, respawn_delay, "
     "respawn_max_retries)"),
    (f'launch: [{{arg: {{name: x, default: a}}}}, {{node: {{{NODE}, sigterm_timeout: 2}}}}]',
     "launch[1].node: unsupported key 'sigterm_timeout' (supported: pkg, exec, name, namespace, param, remap, "
     "args, output, on_exit, respawn, respawn_delay, respawn_max_retries)"),
    ('launch: [{arg: {name: x, default: a, choice: [{value: a}]}}]', "launch[0].arg: unsupported key 'choice' ("),
    (f'launch: [{{node: {{{NODE}, param: [{{name: x, type: int}}]}}}}]', "launch[0].node: param[0]: unsupported key 'type'"),
    (f'launch: [{{node: {{{NODE}, remap: [{{from: x, via: z}}]}}}}]', "launch[0].node: remap[0]: unsupported key 'via'"),
    (f'launch: [{{node: {{{NODE}, remap: {{x: y}}}}}}]', "launch[0].node: 'remap' must be a list of mappings (from, to)"),
    ('launch: [{executable: {cmd: echo}}]', "launch[0].executable: needs 'name'"),
    ('launch: [{executable: {name: a, cmd: echo}}, {executable: {name: a, cmd: echo}}]',
     "launch[1].executable: duplicate name 'a' (also launch[0].executable)"),
    ('launch: [{executable: {name: a, cmd: echo, exec: bag}}]', "launch[0].executable: unsupported key 'exec'"),
    ('launch: [{executable: {name: a}}]', "launch[0].executable: needs 'cmd'"),
    ('launch: [{node: {pkg: mvpose_nodes, name: a}}]', "launch[0].node: needs 'exec'"),
    ('launch: [{node: {exec: bag, name: a}}]', "launch[0].node: needs 'pkg'"),
    ('launch: [{node: {pkg: mvpose_nodes, exec: no_such_node, name: a}}]', "launch[0].node: no executable 'no_such_node' "
     'in package mvpose_nodes'),
    (f'launch: [{{node: {{{NODE}, param: [{{from: missing.yaml}}]}}}}]', 'launch[0].node: param[0]: parameters file not found'),
    (f'launch: [{{node: {{{NODE}, param: [{{name: x, value: [1, 2.5]}}]}}}}]',   # so does launch_ros
     "launch[0].node: param[0]: a list value's items must all have one type"),
    (f'launch: [{{node: {{{NODE}, namespace: /cam 3}}}}]', "launch[0].node: 'namespace' is not a ROS"),
    ('launch: [{executable: {name: a, cmd: no-such-program-here}}]', "launch[0].executable: command not found"),
    ('launch: [{executable: {name: a, cmd: echo, namespace: /x}}]', "launch[0].executable: unsupported key 'namespace'"),
    ('launch: [{executable: {name: a, cmd: [echo, hi]}}]', "launch[0].executable: 'cmd' must be a string"),
    ('launch: [{arg: {name: x, default: 3}}]', "launch[0].arg: 'default' must be a string (quote it: '3')"),
    ('launch: [{executable: {name: a, cmd: echo, on_exit: restart}}]',
     "launch[0].executable: 'on_exit' must be shutdown, the only value ros2 launch takes"),
    ('launch: [{executable: {name: a, cmd: echo, output: log}}]', "launch[0].executable: 'output' must be "),
    ('launch: [{executable: {name: a, cmd: echo $(command ls)}}]',
     "launch[0].executable: 'cmd': unsupported substitution '$(command)' (supported: var, env, "),
    ('launch: [{executable: {name: a, cmd: echo $(var x}}]', "launch[0].executable: 'cmd': unclosed substitution in "),
    ('launch: [{executable: {name: a, cmd: echo $(var x)}}, {arg: {name: x, default: a}}]',
     "launch[0].executable: 'cmd': $(var x): no launch argument 'x' declared before this point"),
    ('launch: [{arg: {name: x}}, {executable: {name: a, cmd: echo}}]',
     "launch[0].arg: launch argument 'x' has no default: give it as x:=VALUE"),
    ('launch: [{arg: {name: x, default: a}}, {arg: {name: x, default: b}}]',
     "launch[1].arg: launch argument 'x' declared twice (also launch[0].arg)"),
])
def test_a_bad_launch_file_is_one_line_on_stderr_and_exit_code_2(tmp_path, monkeypatch, capsys, text, message):
    monkeypatch.chdir(tmp_path)
    if text is not None:
        (tmp_path / 'launch.yaml').write_text(text)
    assert one_line_error(capsys, ['launch.yaml']).startswith(f'launch: error: launch.yaml: {message}')


def one_line_error(capsys, argv):
    """What main(argv) prints on stderr, once it has exited with code 2 printing one line and no traceback."""
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    stderr = capsys.readouterr().err
    assert stderr.count('\n') == 1 and 'Traceback' not in stderr
    return stderr


@pytest.mark.parametrize('words, message', [
    (['launch.yaml', 'nope:=1'], "launch.yaml: no launch argument 'nope' (declared: x)"),
    (['launch.yaml', 'x:=1', 'oops'], "expected a launch argument as NAME:=VALUE, got 'oops'"),
    (['no_such_package', 'x.launch.yaml'], "package 'no_such_package' not found"),
    (['mvpose_nodes', 'no_such.launch.yaml'], "no file named 'no_such.launch.yaml' in "),
])
def test_bad_launch_arguments_are_one_line_on_stderr_and_exit_code_2(tmp_path, monkeypatch, capsys, words, message):
    monkeypatch.chdir(tmp_path)
    (tmp_path / 'launch.yaml').write_text('launch: [{arg: {name: x, default: a}}, {executable: {name: a, cmd: echo}}]')
    assert one_line_error(capsys, [*words, '--dry-run']).startswith(f'launch: error: {message}')


# ros2 launch's YAML format as ROS 2 Jazzy reads it (ros2/launch jazzy 09403fc, ros2/launch_ros jazzy 62c56e5):
# every key each entity's parse method reads. The frontend rejects any other key of an action
# (launch/frontend/expose.py: assert_entity_completely_parsed after parse) and of a param or remap.
EXECUTE_PROCESS_KEYS = {  # launch/actions/execute_process.py ExecuteProcess.parse, with Action.parse's if/unless
    'cmd', 'cwd', 'name', 'on_exit', 'launch-prefix', 'output', 'respawn', 'respawn_max_retries', 'respawn_delay',
    'sigkill_timeout', 'sigterm_timeout', 'shell', 'emulate_tty', 'env', 'if', 'unless'}
FORMAT_KEYS = {
    'arg': {'name', 'default', 'description', 'choice', 'if', 'unless'},  # actions/declare_launch_argument.py parse
    'executable': EXECUTE_PROCESS_KEYS,
    'node': (EXECUTE_PROCESS_KEYS - {'cmd'}) | {  # launch_ros/actions/node.py Node.parse (ExecuteProcess's but cmd)
        'args', 'ros_args', 'node-name', 'name', 'exec_name', 'pkg', 'exec', 'namespace', 'remap', 'param'},
    'param': {'from', 'allow_substs', 'name', 'type', 'value', 'param'},  # node.py parse_nested_parameters
    'remap': {'from', 'to'},  # node.py Node.parse
}
STRING_KEYS = {  # read by Entity.get_attr with its default data_type=str: YAML numbers or lists there are errors
    'name', 'default', 'description', 'cmd', 'cwd', 'on_exit', 'output', 'args', 'pkg', 'exec', 'namespace', 'from', 'to'}


def format_problems(document):
    """What ros2 launch's YAML frontend (launch_yaml.Parser.load, then Parser.parse_description) would reject."""
    if not isinstance(document, dict) or list(document) != ['launch'] or not isinstance(document['launch'], list):
        return ["not a mapping with just a 'launch' list"]
    problems = []

    def check(entity, mapping, place):
        problems.extend(f'{place}: {key} is no key of {entity}' for key in mapping if key not in FORMAT_KEYS[entity])
        problems.extend(f'{place}: {key} is not a string' for key, value in mapping.items()
                        if key in STRING_KEYS and not isinstance(value, str))
        if mapping.get('on_exit', 'shutdown') != 'shutdown':
            problems.append(f'{place}: on_exit other than shutdown')

    for index, action in enumerate(document['launch']):
        (kind, body), = action.items()
        if kind not in ('arg', 'node', 'executable'):
            problems.append(f'launch[{index}]: {kind} is not used here')
            continue
        check(kind, body, f'launch[{index}].{kind}')
        for key in ('param', 'remap'):
            for item_index, item in enumerate(body.get(key, [])):
                check(key, item, f'launch[{index}].{kind}.{key}[{item_index}]')
                values = item.get('value') if isinstance(item.get('value'), list) else [item.get('value', '')]
                if not all(isinstance(value, (bool, int, float, str)) for value in values):
                    problems.append(f'launch[{index}].{kind}.{key}[{item_index}]: value not a scalar or list')
    return problems


def test_the_shipped_launch_files_use_only_keys_of_ros2_launch_yaml_format():
    for text, problem in [  # the check finds what ros2 launch rejects
            ('launch: [{node: {pkg: p, exec: e, colour: red}}]', 'launch[0].node: colour is no key of node'),
            ('launch: [{arg: {name: x, default: 3}}]', 'launch[0].arg: default is not a string'),
            ('launch: [{node: {exec: e, remap: [{from: a, too: b}]}}]', 'launch[0].node.remap[0]: too is no key of remap')]:
        assert problem in format_problems(yaml.safe_load(text))
    for file_name in ('mvpose.launch.yaml', 'mvpose8.launch.yaml', 'markers.launch.yaml', 'camera_host.launch.yaml',
                      'fitting_host.launch.yaml'):
        document = yaml.safe_load((LAUNCH_DIR / file_name).read_text())
        assert format_problems(document) == [], file_name
        assert {kind for action in document['launch'] for kind in action} <= {'arg', 'node'}


@pytest.mark.parametrize('file_name, tracker, fusion, remap', [
    ('mvpose.launch.yaml', 'camera_features', 'skeleton_fitter', []),
    ('markers.launch.yaml', 'marker_tracker', 'marker_skeleton', ['-r', 'initial_markers:=ground_truth/markers']),
])
def test_the_shipped_launch_files_start_a_node_per_camera_and_one_fusing_them(capsys, file_name, tracker, fusion, remap):
    params_file = package_prefix('mvpose_nodes') / 'share' / 'mvpose_nodes' / 'config' / f'{tracker}.yaml'
    for words, cameras in [([str(LAUNCH_DIR / file_name)], [3, 5, 7]),
                           (['mvpose_nodes', file_name], [3, 5, 7]),   # as `ros2 launch mvpose_nodes FILE`
                           ([str(LAUNCH_DIR / file_name), 'camera_b:=2', 'camera_c:=8'], [3, 2, 8])]:
        assert main([*words, '--dry-run']) == 0
        lines = [shlex.split(line) for line in capsys.readouterr().out.splitlines()]
        assert [line[0] for line in lines] == [f'[/cam{k}/{tracker}]' for k in cameras] + [f'[{fusion}]']
        assert [line[1].split('/')[-2:] for line in lines] == [['mvpose_nodes', tracker]] * 3 + [['mvpose_nodes', fusion]]
        assert [line[2:] for line in lines[:3]] == [['--ros-args', '-r', f'__node:={tracker}', '-r', f'__ns:=/cam{k}',
                                                     '--params-file', str(params_file), *remap] for k in cameras]
        fusion_params = params_file.with_name(f'{fusion}.yaml')   # its defaults first, then the launch's cameras
        assert lines[-1][2:] == ['--ros-args', '-r', f'__node:={fusion}', '--params-file', str(fusion_params),
                                 '-p', f'cameras:={cameras}']
    assert all(spec.required for spec in load_launch_file(LAUNCH_DIR / file_name))  # on_exit: shutdown, each


def test_the_eight_camera_and_the_host_launch_files(capsys):
    """mvpose8: a camera_features node in each of /cam1 ... /cam8 and the fitter with all 8; the split: one
    camera's node per camera host (camera:=K), the fitter with the cameras listed, both respawning."""
    assert main([str(LAUNCH_DIR / 'mvpose8.launch.yaml'), '--dry-run']) == 0
    lines = [shlex.split(line) for line in capsys.readouterr().out.splitlines()]
    assert [line[0] for line in lines] == [f'[/cam{k}/camera_features]' for k in range(1, 9)] + ['[skeleton_fitter]']
    assert lines[-1][-2:] == ['-p', 'cameras:=[1, 2, 3, 4, 5, 6, 7, 8]']
    assert main([str(LAUNCH_DIR / 'camera_host.launch.yaml'), 'camera:=4', '--dry-run']) == 0
    assert shlex.split(capsys.readouterr().out)[0] == '[/cam4/camera_features]'
    assert main([str(LAUNCH_DIR / 'fitting_host.launch.yaml'), 'cameras:=[2, 6]', '--dry-run']) == 0
    assert shlex.split(capsys.readouterr().out)[-4:] == ['-p', 'cameras:=[2, 6]', '-p', 'camera_timeout:=1.0']
    for file_name, arguments in (('camera_host.launch.yaml', {'camera': '3'}), ('fitting_host.launch.yaml', {})):
        assert [spec.respawn for spec in load_launch_file(LAUNCH_DIR / file_name, arguments)] == [True]


@pytest.mark.parametrize('options', [[], ['launch.yaml', '--sigint-timeout', '-1'], ['launch.yaml', '--bogus']])
def test_bad_usage_is_one_line_on_stderr_and_exit_code_2(capsys, options):
    assert one_line_error(capsys, options).startswith('launch: error: ')


def test_help_documents_the_format_and_exit_codes(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(['--help'], prog='./mvpose launch')
    assert exit_info.value.code == 0
    text = capsys.readouterr().out
    assert text.startswith('usage: ./mvpose launch')
    assert 'launch:' in text and 'node:' in text and 'on_exit: shutdown' in text and '$(var NAME' in text
    assert 'Exit codes:' in text and '100+K' in text and 'NAME:=VALUE' in text
