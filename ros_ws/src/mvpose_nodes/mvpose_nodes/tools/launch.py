"""Start the processes of a ros2 launch YAML file and supervise them (a stand-in for `ros2 launch`).

Run as `./mvpose launch FILE [NAME:=VALUE...]` or `./mvpose launch PACKAGE FILE [NAME:=VALUE...]`
(FILE then found in PACKAGE's share directory, as `ros2 launch` finds it); NAME:=VALUE sets launch
argument NAME. The file is in ros2 launch's YAML format, of which this subset is read (docs/launch.md):

  launch:
    - arg: {name: camera_a, default: '3', description: first camera}
    - node:
        pkg: mvpose_nodes                # the package, and its executable (PREFIX/lib/PKG/EXEC)
        exec: camera_features
        name: camera_features            # required here; namespace/name is unique and prefixes the output
        namespace: /cam$(var camera_a)   # optional
        param:                           # optional: params files and name/value pairs
          - from: $(find-pkg-share mvpose_nodes)/config/camera_features.yaml
          - {name: cameras, value: [$(var camera_a), 5, 7]}
        remap: [{from: image, to: image_raw}]   # optional
        args: --verbose                  # optional: extra arguments, placed before --ros-args
        output: screen                   # optional: screen or both (all output is printed anyway)
        on_exit: shutdown                # optional: when it ends (any code), stop all the others
        respawn: 'true'                  # optional, not with on_exit: when it ends, start it again after
        respawn_delay: '2.0'             # this many seconds (default 0), at most respawn_max_retries
        respawn_max_retries: '5'         # times (default -1: no limit), as ros2 launch does
    - executable:
        name: player
        cmd: bag play bags/x             # a plain command line, no --ros-args added; its first word is
        on_exit: shutdown                # a mvpose_nodes executable if one has that name, else on PATH

Substitutions: $(var NAME [DEFAULT]), $(env NAME [DEFAULT]), $(find-pkg-share PKG), $(find-pkg-prefix PKG),
$(exec-in-pkg EXEC PKG), $(dirname). A node runs, in this order:

  EXEC ARGS... --ros-args -r __node:=NAME [-r __ns:=NAMESPACE]
      [--params-file FILE | -p NAME:=VALUE]... (in `param` order) [-r FROM:=TO]...

with values written as compact YAML (-p cameras:=[3, 5, 7]). Relative paths resolve against the current
directory. The whole file is checked before anything starts (any other key is a one-line error naming
it and its place); --dry-run prints the command lines instead, --show-args the launch arguments.

Each process gets its own session (so a terminal Ctrl-C reaches only the launcher), the launcher's
environment plus PYTHONUNBUFFERED=1, and its stdout and stderr merged and printed as `[NAME] line`.
On Ctrl-C or SIGTERM to the launcher, or when a process with on_exit: shutdown ends, the launcher sends
SIGINT to the processes still running, SIGTERM after --sigint-timeout seconds, SIGKILL after
--sigterm-timeout more. A process with respawn is started again when it ends, unless the launch is
stopping, until its respawn_max_retries are used up (`[launch] respawning NAME in D s (restart K of N)`).
A negative code in `[launch] NAME exited with code C` means the process was ended by signal -C.

Exit codes:
  0      every process ended with code 0, or SIGTERM to the launcher and all stopped on SIGINT
  1      a process ended with a non-zero code and none had on_exit: shutdown, or after Ctrl-C or
         SIGTERM some process did not stop within --sigint-timeout and needed SIGTERM or SIGKILL
  2      bad launch file or command line (nothing was started)
  100+K  the on_exit: shutdown process at position K (1-based, counting the file's nodes and
         executables in order) ended; the others were stopped
  130    Ctrl-C, and every process stopped on SIGINT within --sigint-timeout
"""
import argparse
import contextlib
import math
import os
import shlex
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from mvpose_nodes.tools.cli import ArgumentParser, end_with_parent, exit_on_user_error, UserError, without_ros_args
from mvpose_nodes.tools.launch_file import (  # noqa: F401 (the launcher's API, for its users)
    DEFAULT_PACKAGE, ProcessSpec, declared_arguments, load_launch_file, package_executable,
    package_launch_file, process_specs, yaml_value)

EXIT_PROCESS_FAILED = 1  # also: stopping needed more than SIGINT
EXIT_REQUIRED_ENDED = 100  # + the 1-based position of the required process
EXIT_INTERRUPTED = 130
POLL_INTERVAL = 0.05  # seconds between looks at the children: short enough that reactions feel immediate
DRAIN_TIMEOUT = 1.0  # a grandchild may hold an ended child's output pipe open; don't wait for it for ever
SIGINT_TIMEOUT = 5.0  # [s] the defaults of --sigint-timeout and --sigterm-timeout (ros2 launch's)
SIGTERM_TIMEOUT = 5.0


class Launch:
    """Runs process specs (from load_launch_file or process_specs) and supervises them.

        with Launch(load_launch_file('launch/demo.launch.yaml', {'camera_a': '2'})) as launch:   # start()
            code = launch.wait(timeout=30)   # the exit code once it is over, None if still running
        # leaving the block stop()s whatever still runs

    wait() does the supervising (reporting exits, stopping the rest when a required process ends),
    so call it, or stop(), rather than just sleeping. Exit codes are those of the launch command.
    """

    def __init__(self, specs, sigint_timeout=SIGINT_TIMEOUT, sigterm_timeout=SIGTERM_TIMEOUT, output=None):
        """output: a text file for the children's and the launch's lines (default: standard output)."""
        self.specs = list(specs)
        self.output = output
        self.sigint_timeout = sigint_timeout
        self.sigterm_timeout = sigterm_timeout
        self.exit_code = None
        self._popens = []  # in the order of self.specs, as far as started (the newest of a respawned one)
        self._readers = []
        self._reported = set()  # indices of the processes whose exit has been printed
        self._restarts = [0] * len(self.specs)   # respawns so far, per spec
        self._respawn_at = {}   # index -> monotonic time its respawn is due
        self._clean_stop_code = None  # set by request_stop: the exit code if everything stops on SIGINT
        self._print_lock = threading.Lock()

    def start(self):
        for spec in self.specs:
            try:
                popen, reader = self._spawn(spec)
            except OSError as error:
                self.stop()
                raise UserError(f"cannot start '{spec.name}': {error.strerror}") from None
            self._popens.append(popen)
            self._readers.append(reader)
        return self

    def _spawn(self, spec):
        popen = subprocess.Popen(spec.command, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                 stderr=subprocess.STDOUT, env={**os.environ, 'PYTHONUNBUFFERED': '1'}, text=True,
                                 errors='replace', start_new_session=True, preexec_fn=end_with_parent)
        reader = threading.Thread(target=self._forward_output, args=(spec.name, popen.stdout), daemon=True)
        reader.start()
        self.say(f'started {spec.name} (pid {popen.pid})')
        return popen, reader

    def _respawn(self):
        """Start again, once their respawn_delay has passed, the ended processes with respawn and retries left
        (never while the launch stops); True while any is due."""
        for index, (spec, popen) in enumerate(zip(self.specs, self._popens)):
            retries_left = spec.respawn_max_retries < 0 or self._restarts[index] < spec.respawn_max_retries
            if not spec.respawn or popen.returncode is None or not retries_left or self._clean_stop_code is not None:
                continue
            if index not in self._respawn_at:
                self._respawn_at[index] = time.monotonic() + spec.respawn_delay
                limit = '' if spec.respawn_max_retries < 0 else f' of {spec.respawn_max_retries}'
                self.say(f'respawning {spec.name} in {spec.respawn_delay:g} s (restart {self._restarts[index] + 1}{limit})')
            elif time.monotonic() >= self._respawn_at[index]:
                del self._respawn_at[index]
                self._restarts[index] += 1
                try:
                    self._popens[index], self._readers[index] = self._spawn(spec)
                except OSError as error:
                    self.say(f"cannot start '{spec.name}' again: {error.strerror}")
                    continue
                self._reported.discard(index)
        return bool(self._respawn_at)

    def wait(self, timeout=None):
        """Supervise until the launch is over and return its exit code; None if `timeout` seconds pass first."""
        deadline = math.inf if timeout is None else time.monotonic() + timeout
        while self.exit_code is None:
            self._report_exits()
            respawning = self._respawn()
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
            elif not respawning and all(popen.returncode is not None for popen in self._popens):
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
                            usage='%(prog)s [options] [PACKAGE] FILE [NAME:=VALUE ...]',
                            formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('words', nargs='+', metavar='[PACKAGE] FILE [NAME:=VALUE ...]',
                        help="the launch file (or a package and its launch file's name), then launch arguments")
    parser.add_argument('--dry-run', action='store_true',
                        help='print the command line of every process and exit without starting any')
    parser.add_argument('-s', '--show-args', action='store_true',
                        help="print the launch file's arguments (name, description, default) and exit")
    parser.add_argument('--sigint-timeout', type=seconds, default=SIGINT_TIMEOUT, metavar='S',
                        help=f'seconds to wait after SIGINT before sending SIGTERM (default {SIGINT_TIMEOUT:g})')
    parser.add_argument('--sigterm-timeout', type=seconds, default=SIGTERM_TIMEOUT, metavar='S',
                        help=f'seconds to wait after SIGTERM before sending SIGKILL (default {SIGTERM_TIMEOUT:g})')
    return parser


def launch_file_and_arguments(words):
    """(launch file path, {argument: value}) from the command line's words, read as `ros2 launch` reads
    them: FILE [NAME:=VALUE...], or PACKAGE FILE [NAME:=VALUE...] when the second word is no NAME:=VALUE."""
    if len(words) > 1 and ':=' not in words[1]:
        path, rest = package_launch_file(words[0], words[1]), words[2:]
    else:
        path, rest = Path(words[0]), words[1:]
    arguments = {}
    for word in rest:
        name, assigns, value = word.partition(':=')
        if not assigns or not name:
            raise UserError(f"expected a launch argument as NAME:=VALUE, got '{word}'")
        arguments[name] = value
    return path, arguments


def show_arguments(path):
    arguments = declared_arguments(path)
    if not arguments:
        print(f'{path} declares no launch arguments')
    else:
        print("Arguments (pass arguments as '<name>:=<value>'):")
    for argument in arguments:
        print(f"\n    '{argument.name}':\n        {argument.description or 'no description given'}")
        if argument.default is not None:
            print(f"        (default: '{argument.default}')")


def main(argv=None, prog='launch'):
    args = build_parser(prog).parse_intermixed_args(without_ros_args(sys.argv[1:] if argv is None else argv))
    with exit_on_user_error(prog):
        path, arguments = launch_file_and_arguments(args.words)
        if args.show_args:
            show_arguments(path)
            return 0
        specs = load_launch_file(path, arguments)
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
