"""The YAML launcher: command lines, output prefixes, stopping, exit codes and launch-file errors.

Runtime tests start the launcher as a subprocess (it installs signal handlers) with small Python
scripts as its processes, so no ROS node is needed.
"""
import os
import shlex
import signal
import subprocess
import sys
import threading
import time

import pytest

from mvpose_nodes.tools.launch import Launch, main, process_specs

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
    """Writes child.py; gives the YAML flow list `[python, child.py, ARGS...]` for a `cmd:` entry."""
    script = tmp_path / 'child.py'
    script.write_text(CHILD)
    return lambda *args: '[' + ', '.join(f"'{word}'" for word in (sys.executable, script, *args)) + ']'


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


def test_dry_run_prints_the_ros_command_line_of_an_executable_entry(tmp_path, capsys):
    (tmp_path / 'config').mkdir()
    (tmp_path / 'config' / 'features.yaml').write_text('camera_features:\n  ros__parameters: {}\n')
    marker = tmp_path / 'started'
    path = write_launch_file(tmp_path, f'''
nodes:
  - name: camera_features
    executable: bag
    package: mvpose_nodes
    namespace: /cam3
    parameters: [config/features.yaml, {{cameras: [3, 5, 7], overlay: false, label: 'true'}}]
    remappings: {{from: to}}
    arguments: [--verbose, 3, true]
  - name: camera_features
    executable: bag
    namespace: /cam5
  - name: player
    cmd: [{sys.executable}, -c, "open('{marker}', 'w')", bags/x]
''')
    assert main([str(path), '--dry-run']) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 3
    assert lines[0].startswith('[/cam3/camera_features] ')  # one node name, told apart by namespace
    assert lines[1].startswith('[/cam5/camera_features] ')
    command = shlex.split(lines[0].removeprefix('[/cam3/camera_features] '))
    assert command[0].endswith('/lib/mvpose_nodes/bag')
    assert command[1:] == ['--verbose', '3', 'true', '--ros-args', '-r', '__node:=camera_features', '-r', '__ns:=/cam3',
                           '--params-file', str(tmp_path / 'config' / 'features.yaml'),
                           '-p', 'cameras:=[3, 5, 7]', '-p', 'overlay:=false', '-p', "label:='true'",
                           '-r', 'from:=to']
    assert shlex.split(lines[2]) == ['[player]', sys.executable, '-c', f"open('{marker}', 'w')", 'bags/x']
    assert not marker.exists()


def test_every_process_ending_with_0_exits_0_with_all_output_prefixed(tmp_path, child):
    path = write_launch_file(tmp_path, f'''
nodes:
  - {{name: talker, cmd: {child('--lines', '20000', '--exit', '0')}}}
  - {{name: other, cmd: {child('--exit', '0')}}}
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
nodes:
  - {{name: fine, cmd: {child('--exit', '0')}}}
  - {{name: broken, cmd: {child('--exit', '4')}}}
''')
    code, lines, _ = run_launcher(path, *TIMEOUTS)
    assert code == 1
    assert '[launch] broken exited with code 4' in lines
    assert '[launch] fine exited with code 0' in lines


def test_a_required_process_ending_stops_the_others_with_exit_code_100_plus_its_position(tmp_path, child):
    ready = tmp_path / 'server-ready'
    path = write_launch_file(tmp_path, f'''
nodes:
  - {{name: server, cmd: {child('--ready-file', ready)}}}
  - {{name: other, cmd: {child()}}}
  - {{name: player, cmd: {child('--exit-when-exists', ready, '--exit', '3')}, required: true}}
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
nodes:
  - {{name: first, cmd: {child()}}}
  - {{name: second, cmd: {child()}}}
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
nodes:
  - {{name: first, cmd: {child()}}}
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
nodes:
  - {{name: polite, cmd: {child()}}}
  - {{name: deaf, cmd: {child('--ignore', 'SIGINT')}}}
  - {{name: stubborn, cmd: {child('--ignore', 'SIGINT', 'SIGTERM')}}}
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
    specs = process_specs([{'name': 'waiter', 'cmd': [sys.executable, str(tmp_path / 'child.py')]}], tmp_path)
    with Launch(specs, sigint_timeout=1, sigterm_timeout=1) as launch:
        assert launch.wait(timeout=0.2) is None
    assert launch.exit_code == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[-3:] == ['[launch] sending SIGINT to waiter', '[waiter] got SIGINT',
                          '[launch] waiter exited with code 0']


@pytest.mark.parametrize('text, message', [
    (None, "launch.yaml: file not found"),
    ('nodes: [', 'launch.yaml: not valid YAML (line '),
    ('- name: a', "launch.yaml: expected a mapping with just a 'nodes' list"),
    ('nodes: 3', "launch.yaml: 'nodes' must be a non-empty list"),
    ('nodes: [{name: a, cmd: [echo], colour: red}]', "launch.yaml: node 'a': unknown key 'colour'"),
    ('nodes: [{cmd: [echo]}]', "launch.yaml: node #1: needs a 'name'"),
    ('nodes: [{name: a, cmd: [echo]}, {name: a, cmd: [echo]}]', "launch.yaml: node 'a': duplicate name"),
    ('nodes: [{name: a, cmd: [echo], executable: bag}]', "launch.yaml: node 'a': needs exactly one of"),
    ('nodes: [{name: a}]', "launch.yaml: node 'a': needs exactly one of 'executable' and 'cmd'"),
    ('nodes: [{name: cam3_features, executable: no_such_node}]',
     "launch.yaml: node 'cam3_features': no executable 'no_such_node' in package mvpose_nodes"),
    ('nodes: [{name: a, executable: bag, parameters: [missing.yaml]}]',
     "launch.yaml: node 'a': parameters file not found: "),
    ('nodes: [{name: a, cmd: [no-such-program-here]}]', "launch.yaml: node 'a': command not found"),
    ('nodes: [{name: a, cmd: [echo], namespace: /x}]', "launch.yaml: node 'a': 'namespace' goes with 'executable'"),
])
def test_a_bad_launch_file_is_one_line_on_stderr_and_exit_code_2(tmp_path, monkeypatch, capsys, text, message):
    monkeypatch.chdir(tmp_path)
    if text is not None:
        (tmp_path / 'launch.yaml').write_text(text)
    with pytest.raises(SystemExit) as exit_info:
        main(['launch.yaml'])
    assert exit_info.value.code == 2
    stderr = capsys.readouterr().err
    assert stderr.count('\n') == 1
    assert stderr.startswith(f'launch: error: {message}')
    assert 'Traceback' not in stderr


@pytest.mark.parametrize('options', [[], ['launch.yaml', '--sigint-timeout', '-1'], ['launch.yaml', '--bogus']])
def test_bad_usage_is_one_line_on_stderr_and_exit_code_2(capsys, options):
    with pytest.raises(SystemExit) as exit_info:
        main(options)
    assert exit_info.value.code == 2
    stderr = capsys.readouterr().err
    assert stderr.count('\n') == 1 and stderr.startswith('launch: error: ')


def test_help_documents_the_format_and_exit_codes(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(['--help'], prog='./mvpose launch')
    assert exit_info.value.code == 0
    text = capsys.readouterr().out
    assert text.startswith('usage: ./mvpose launch')
    assert 'nodes:' in text and 'Exit codes:' in text and '100+K' in text
