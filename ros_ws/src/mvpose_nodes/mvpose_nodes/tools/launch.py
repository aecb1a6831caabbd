"""Start the processes of a launch YAML file and supervise them (a small stand-in for `ros2 launch`).

Run as `./mvpose launch FILE.yaml` (or the `launch` executable). The file lists the processes to start:

  nodes:
    - name: camera_features        # required: the node name; namespace/name is unique and prefixes its output
      executable: camera_features  # a console script of `package` (PREFIX/lib/PACKAGE/NAME, as `ros2 run`)
      package: mvpose_nodes        # optional, default mvpose_nodes
      namespace: /cam3             # optional
      parameters:                  # optional: params files (relative to this file's folder) and mappings
        - ../config/camera_features.yaml
        - {publish_overlay: false, cameras: [3, 5, 7]}
      remappings: {image: image_raw}   # optional: from: to
      arguments: [--verbose]       # optional: extra arguments, placed before --ros-args
      required: true               # optional, default false: when it ends (any code), stop all the others
    - name: player
      cmd: [bag, play, bags/x]     # instead of executable: a plain command, no --ros-args added; its first
      required: true               # word is a mvpose_nodes executable if one has that name, else a program on PATH

An `executable` entry runs, in this order:

  EXECUTABLE ARGUMENTS... --ros-args -r __node:=NAME [-r __ns:=NAMESPACE]
      [--params-file FILE | -p KEY:=VALUE]... (in `parameters` order) [-r FROM:=TO]...

with inline values written as compact YAML (-p cameras:=[3, 5, 7]). Paths inside `cmd` and
`arguments` are passed as written, so relative ones resolve against the current directory.
The whole file is checked before anything starts; --dry-run prints the command lines instead.

Each process gets its own session (so a terminal Ctrl-C reaches only the launcher), the launcher's
environment plus PYTHONUNBUFFERED=1, and its stdout and stderr merged and printed as `[NAME] line`.
On Ctrl-C or SIGTERM to the launcher, or when a required process ends, the launcher sends SIGINT to
the processes still running, SIGTERM after --sigint-timeout seconds, SIGKILL after --sigterm-timeout more.
A negative code in `[launch] NAME exited with code C` means the process was ended by signal -C.

Exit codes:
  0      every process ended with code 0, or SIGTERM to the launcher and all stopped on SIGINT
  1      a process ended with a non-zero code and none was required, or after Ctrl-C or SIGTERM
         some process did not stop within --sigint-timeout and needed SIGTERM or SIGKILL
  2      bad launch file or command line (nothing was started)
  100+K  the required process at position K (1-based, in file order) ended; the others were stopped
  130    Ctrl-C, and every process stopped on SIGINT within --sigint-timeout
"""
import argparse
import contextlib
import ctypes
import math
import os
import shlex
import shutil
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import yaml

from mvpose_nodes.tools.cli import ArgumentParser, exit_on_user_error, UserError

DEFAULT_PACKAGE = 'mvpose_nodes'
NODE_KEYS = ('name', 'executable', 'cmd', 'package', 'namespace', 'parameters', 'remappings', 'arguments',
             'required')
EXECUTABLE_ONLY_KEYS = ('package', 'namespace', 'parameters', 'remappings', 'arguments')
EXIT_PROCESS_FAILED = 1  # also: stopping needed more than SIGINT
EXIT_REQUIRED_ENDED = 100  # + the 1-based position of the required process
EXIT_INTERRUPTED = 130
POLL_INTERVAL = 0.05  # seconds between looks at the children: short enough that reactions feel immediate
PR_SET_PDEATHSIG = 1     # linux/prctl.h
DRAIN_TIMEOUT = 1.0  # a grandchild may hold an ended child's output pipe open; don't wait for it for ever


@dataclass
class ProcessSpec:
    """One checked entry of a launch description: what to run and whether its end stops the launch."""
    name: str
    command: list
    required: bool = False


def package_executable(package, name):
    """Where `ros2 run PACKAGE NAME` finds NAME (PREFIX/lib/PACKAGE/NAME, PREFIX in AMENT_PREFIX_PATH), or None."""
    for prefix in filter(None, os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep)):
        candidate = Path(prefix, 'lib', package, name)
        if candidate.is_file() and os.access(candidate, os.X_OK):
            return candidate
    return None


def yaml_value(value):
    """VALUE of `-p KEY:=VALUE`: compact YAML, which is how ROS reads it ([3, 5, 7], true, 'true')."""
    return yaml.safe_dump(value, default_flow_style=True, width=math.inf).strip().removesuffix('\n...')


def load_launch_file(path):
    """The checked process specs of launch YAML file `path`; a one-line UserError for any mistake in it."""
    path = Path(path)
    try:
        document = yaml.safe_load(path.read_text())
    except FileNotFoundError:
        raise UserError(f'{path}: file not found') from None
    except OSError as error:
        raise UserError(f'{path}: cannot read: {error.strerror}') from None
    except yaml.YAMLError as error:
        mark = getattr(error, 'problem_mark', None)
        where = f' (line {mark.line + 1}: {error.problem})' if mark else ''
        raise UserError(f'{path}: not valid YAML{where}') from None
    if not isinstance(document, dict) or set(document) != {'nodes'}:
        raise UserError(f"{path}: expected a mapping with just a 'nodes' list (see --help)")
    return process_specs(document['nodes'], path.parent, source=str(path))


def process_specs(entries, base_dir='.', source='launch description'):
    """Check launch entries (dicts, as in a launch file's `nodes` list) and build their command lines.

    Relative params-file paths resolve against base_dir. Errors name `source` and the entry."""
    if not isinstance(entries, list) or not entries:
        raise UserError(f"{source}: 'nodes' must be a non-empty list of node entries")
    specs = []
    for position, entry in enumerate(entries, 1):
        name = entry.get('name') if isinstance(entry, dict) else None
        label = f"node '{name}'" if isinstance(name, str) and name else f'node #{position}'
        try:
            spec = _process_spec(entry, Path(base_dir))
            if spec.name in (earlier.name for earlier in specs):
                raise UserError('duplicate name')
        except UserError as error:
            raise UserError(f'{source}: {label}: {error}') from None
        specs.append(spec)
    return specs


def _process_spec(entry, base_dir):
    if not isinstance(entry, dict):
        raise UserError("must be a mapping with a 'name' and an 'executable' or a 'cmd'")
    unknown = [str(key) for key in entry if key not in NODE_KEYS]
    if unknown:
        raise UserError(f"unknown key '{unknown[0]}' (known: {', '.join(NODE_KEYS)})")
    name = entry.get('name')
    if not isinstance(name, str) or not name:
        raise UserError("needs a 'name' (a non-empty string)")
    required = entry.get('required', False)
    if not isinstance(required, bool):
        raise UserError("'required' must be true or false")
    if ('executable' in entry) == ('cmd' in entry):
        raise UserError("needs exactly one of 'executable' and 'cmd'")
    if 'cmd' in entry:
        misplaced = [key for key in EXECUTABLE_ONLY_KEYS if key in entry]
        if misplaced:
            raise UserError(f"'{misplaced[0]}' goes with 'executable', not with 'cmd'")
        command = _words(entry['cmd'], 'cmd')
        if not command:
            raise UserError("'cmd' is empty")
        return ProcessSpec(name, [_program_path(command[0]), *command[1:]], required)

    package, executable = entry.get('package', DEFAULT_PACKAGE), entry['executable']
    if not isinstance(package, str) or not isinstance(executable, str) or '/' in executable:
        raise UserError("'executable' and 'package' must be names, e.g. executable: camera_features")
    path = package_executable(package, executable)
    if path is None:
        raise UserError(f"no executable '{executable}' in package {package}")
    command = [str(path), *_words(entry.get('arguments', []), 'arguments'), '--ros-args', '-r', f'__node:={name}']
    namespace = entry.get('namespace')
    if namespace is not None:
        if not isinstance(namespace, str) or not namespace.startswith('/'):
            raise UserError("'namespace' must start with '/', e.g. /cam3")
        command += ['-r', f'__ns:={namespace}']
        name = f"{namespace.rstrip('/')}/{name}"  # the node's full name: unique where the plain name need not be
    command += _parameter_arguments(entry.get('parameters', []), base_dir)
    remappings = entry.get('remappings', {})
    if not isinstance(remappings, dict):
        raise UserError("'remappings' must be a mapping of from: to")
    for original, replacement in remappings.items():
        command += ['-r', f'{original}:={replacement}']
    return ProcessSpec(name, command, required)


def _words(value, key):
    if not isinstance(value, list) or not all(isinstance(word, (str, int, float)) for word in value):
        raise UserError(f"'{key}' must be a list of words, e.g. [--verbose]")
    return [word if isinstance(word, str) else yaml_value(word) for word in value]  # true stays true, not True


def _program_path(word):
    """The program a `cmd` starts with: a mvpose_nodes executable of that name, else one on PATH (or a path)."""
    found = ('/' not in word and package_executable(DEFAULT_PACKAGE, word)) or shutil.which(word)
    if not found:
        raise UserError(f"command not found: '{word}' (not an executable of {DEFAULT_PACKAGE}, not on PATH)")
    return str(found)


def _parameter_arguments(parameters, base_dir):
    if not isinstance(parameters, list):
        raise UserError("'parameters' must be a list of params-file paths and mappings")
    arguments = []
    for item in parameters:
        if isinstance(item, str):
            path = (base_dir / item).resolve()
            if not path.is_file():
                raise UserError(f'parameters file not found: {path}')
            arguments += ['--params-file', str(path)]
        elif isinstance(item, dict):
            for key, value in item.items():
                arguments += ['-p', f'{key}:={yaml_value(value)}']
        else:
            raise UserError("'parameters' items must be params-file paths or mappings of name: value")
    return arguments


def _end_with_parent():
    """In a child before exec: SIGTERM it when the launching process dies, however it dies (Linux
    prctl PR_SET_PDEATHSIG), so that a killed launch leaves no nodes behind in their own sessions."""
    ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)


class Launch:
    """Runs process specs (from load_launch_file or process_specs) and supervises them.

        with Launch(load_launch_file('launch/demo.yaml')) as launch:   # start()
            code = launch.wait(timeout=30)   # the exit code once it is over, None if still running
        # leaving the block stop()s whatever still runs

    wait() does the supervising (reporting exits, stopping the rest when a required process ends),
    so call it, or stop(), rather than just sleeping. Exit codes are those of the launch command.
    """

    def __init__(self, specs, sigint_timeout=5.0, sigterm_timeout=5.0, output=None):
        """output: a text file for the children's and the launch's lines (default: standard output)."""
        self.specs = list(specs)
        self.output = output
        self.sigint_timeout = sigint_timeout
        self.sigterm_timeout = sigterm_timeout
        self.exit_code = None
        self._popens = []  # in the order of self.specs, as far as started
        self._readers = []
        self._reported = set()  # indices of the processes whose exit has been printed
        self._clean_stop_code = None  # set by request_stop: the exit code if everything stops on SIGINT
        self._print_lock = threading.Lock()

    def start(self):
        environment = {**os.environ, 'PYTHONUNBUFFERED': '1'}
        for spec in self.specs:
            try:
                popen = subprocess.Popen(spec.command, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                         stderr=subprocess.STDOUT, env=environment, text=True, errors='replace',
                                         start_new_session=True, preexec_fn=_end_with_parent)
            except OSError as error:
                self.stop()
                raise UserError(f"cannot start '{spec.name}': {error.strerror}") from None
            reader = threading.Thread(target=self._forward_output, args=(spec.name, popen.stdout), daemon=True)
            reader.start()
            self._popens.append(popen)
            self._readers.append(reader)
            self.say(f'started {spec.name} (pid {popen.pid})')
        return self

    def wait(self, timeout=None):
        """Supervise until the launch is over and return its exit code; None if `timeout` seconds pass first."""
        deadline = math.inf if timeout is None else time.monotonic() + timeout
        while self.exit_code is None:
            self._report_exits()
            started = list(zip(self.specs, self._popens))
            ended_required = next((position for position, (spec, popen) in enumerate(started, 1)
                                   if spec.required and popen.returncode is not None), None)
            if self._clean_stop_code is not None:
                self.exit_code = self._clean_stop_code if self._stop_all() else EXIT_PROCESS_FAILED
            elif ended_required is not None:
                spec, popen = started[ended_required - 1]
                self.say(f"required process '{spec.name}' ended with code {popen.returncode}; stopping the others")
                self._stop_all()
                self.exit_code = EXIT_REQUIRED_ENDED + ended_required
            elif all(popen.returncode is not None for popen in self._popens):
                self.exit_code = 0 if all(popen.returncode == 0 for popen in self._popens) else EXIT_PROCESS_FAILED
            elif time.monotonic() >= deadline:
                return None
            else:
                time.sleep(POLL_INTERVAL)
        return self.exit_code

    def pids(self):
        """{process name: process id} of the processes started."""
        return {spec.name: popen.pid for spec, popen in zip(self.specs, self._popens)}

    def request_stop(self, clean_exit_code=0):
        """Make wait() stop everything, then return clean_exit_code if SIGINT sufficed; fine in a signal handler."""
        if self._clean_stop_code is None:
            self._clean_stop_code = clean_exit_code

    def stop(self):
        """Stop every process still running (SIGINT, then SIGTERM, then SIGKILL) and return the exit code."""
        self.request_stop()
        return self.wait()

    def __enter__(self):
        return self.start()

    def __exit__(self, *exception):
        self.stop()

    def say(self, text):
        self._print(f'[launch] {text}')

    def _print(self, line):
        with self._print_lock:  # whole lines only, whichever reader thread prints
            print(line, file=self.output or sys.stdout, flush=True)

    def _forward_output(self, name, stream):
        for line in stream:
            line = line.rstrip('\n')
            self._print(f'[{name}] {line}')

    def _report_exits(self):
        for index, (spec, popen) in enumerate(zip(self.specs, self._popens)):
            if index not in self._reported and popen.poll() is not None:
                self._readers[index].join(DRAIN_TIMEOUT)  # its last output lines come before its exit line
                self._reported.add(index)
                self.say(f'{spec.name} exited with code {popen.returncode}')

    def _stop_all(self):
        """SIGINT, then SIGTERM, then SIGKILL to what still runs; True if SIGINT was enough."""
        escalation = ((signal.SIGINT, self.sigint_timeout), (signal.SIGTERM, self.sigterm_timeout),
                      (signal.SIGKILL, math.inf))
        sigint_was_enough = True
        for signum, grace in escalation:
            running = [(spec, popen) for spec, popen in zip(self.specs, self._popens) if popen.poll() is None]
            if not running:
                break
            sigint_was_enough = signum == signal.SIGINT
            self.say(f"sending {signum.name} to {', '.join(spec.name for spec, _ in running)}")
            for _, popen in running:
                # The whole process group, as a terminal Ctrl-C would: helpers the process started stop too.
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(popen.pid, signum)
            deadline = time.monotonic() + grace
            while any(popen.poll() is None for _, popen in running) and time.monotonic() < deadline:
                time.sleep(POLL_INTERVAL)
            self._report_exits()
        return sigint_was_enough


def seconds(text):
    value = float(text)
    if not value >= 0:
        raise argparse.ArgumentTypeError(f'not a number of seconds >= 0: {text}')
    return value


def build_parser(prog):
    parser = ArgumentParser(prog=prog, description=__doc__.split('\n', 1)[0], epilog=__doc__.split('\n\n', 1)[1],
                            formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('file', type=Path, metavar='FILE.yaml', help='the launch file')
    parser.add_argument('--dry-run', action='store_true',
                        help='print the command line of every process and exit without starting any')
    parser.add_argument('--sigint-timeout', type=seconds, default=5.0, metavar='S',
                        help='seconds to wait after SIGINT before sending SIGTERM (default 5)')
    parser.add_argument('--sigterm-timeout', type=seconds, default=5.0, metavar='S',
                        help='seconds to wait after SIGTERM before sending SIGKILL (default 5)')
    return parser


def main(argv=None, prog='launch'):
    args = build_parser(prog).parse_args(sys.argv[1:] if argv is None else argv)
    with exit_on_user_error(prog):
        specs = load_launch_file(args.file)
        if args.dry_run:
            for spec in specs:
                print(f'[{spec.name}] {shlex.join(spec.command)}')
            return 0
        launch = Launch(specs, sigint_timeout=args.sigint_timeout, sigterm_timeout=args.sigterm_timeout)
        # Installed before start(): the children then begin with default signal handling, not an inherited ignore.
        signal.signal(signal.SIGINT, lambda *_: launch.request_stop(EXIT_INTERRUPTED))
        signal.signal(signal.SIGTERM, lambda *_: launch.request_stop(0))
        launch.start()
        return launch.wait()


if __name__ == '__main__':
    sys.exit(main())
