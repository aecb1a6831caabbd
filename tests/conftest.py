"""Shared set-up of the mvpose tests: the tiers, the environment each needs, and the shared fixtures.

Every test has exactly one tier marker (registered in pytest.ini; a file of one tier says
`pytestmark = pytest.mark.<tier>`); collection fails for a test with none or with two.

Through the front door (`./mvpose test`: MVPOSE_ROOT set, the workspace sourced) every tier runs, in a
DDS domain of its own on loopback. Anywhere else (plain `pytest`, `colcon test`) only the pure tier
can run: mvpose_nodes is imported from its source tree, ROS packages refuse to import, and the files
of the other tiers are not collected (the summary names them).

Fixtures: background (./mvpose processes beside the test), ros_context (rclpy for the test process),
synth_bag (./mvpose synth bags made once per session), cmu_walk (the CMU walk loaded once). Plain
helpers are in common.py."""
import ast
import configparser
import contextlib
import ctypes
import importlib.abc
import os
import re
import signal
import stat
import sys
import time
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
sys.path.insert(0, str(TESTS))  # common.py and samples.py, also for the scripts tests run in other processes

from common import ROOT, Background, run_mvpose  # noqa: E402 (after the sys.path entry it needs)

TIERS = ('pure', 'dds', 'graph', 'cli')
ROS_ENVIRONMENT = 'MVPOSE_ROOT' in os.environ   # set by ./mvpose for the commands it runs
# The top-level packages of ROS (in .venv too, but without a sourced workspace): not for the pure tier.
ROS_PACKAGE = re.compile(r'rclpy|rcl|rcl_\w+|rmw\w*|rosidl_\w+|rosbag2_py|ament_index_python|rpyutils|launch|'
                         r'launch_\w+|\w+_msgs|\w+_srvs|\w+_interfaces')


class RefuseRosImports(importlib.abc.MetaPathFinder):
    """Without the ROS environment: an import of a ROS package fails, naming the rule it breaks."""

    def find_spec(self, name, path=None, target=None):
        if '.' not in name and ROS_PACKAGE.fullmatch(name):
            raise ModuleNotFoundError(f"no ROS outside ./mvpose test: '{name}' may not be imported by a pure "
                                      'test (a test that needs ROS is marked cli, dds or graph)', name=name)
        return None


if ROS_ENVIRONMENT:
    # No DDS traffic leaves the machine in any test, and the tests do not see (or disturb) other
    # ROS graphs on it: a domain of their own, chosen per run.
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    os.environ['ROS_DOMAIN_ID'] = str(1 + os.getpid() % 100)
else:
    sys.path.insert(0, str(ROOT / 'ros_ws' / 'src' / 'mvpose_nodes'))
    sys.meta_path.insert(0, RefuseRosImports())

LEFT_OUT = []   # (test file or test, its tiers) not collected or deselected for want of ROS


# ---- the tiers ---------------------------------------------------------------------------------

def pytest_configure(config):
    """The tiers of pytest.ini also under another ini file (`colcon test` reads the package's setup.cfg)."""
    registered = {line.split(':')[0].strip() for line in config.getini('markers')}
    if not registered.issuperset(TIERS):
        ini = configparser.ConfigParser(interpolation=None)
        ini.read(TESTS / 'pytest.ini')
        for line in ini['pytest']['markers'].strip().splitlines():
            config.addinivalue_line('markers', line.strip())


def tiers_of(item):
    return {mark.name for mark in item.iter_markers() if mark.name in TIERS}


def tiers_named_in(path):
    """The tiers a test file names (`pytest.mark.<tier>` anywhere in it), read without importing it."""
    return {node.attr for node in ast.walk(ast.parse(path.read_bytes(), str(path)))
            if isinstance(node, ast.Attribute) and node.attr in TIERS
            and isinstance(node.value, ast.Attribute) and node.value.attr == 'mark'}


def pytest_ignore_collect(collection_path, config):
    """Without ROS, a test file with no pure test is not imported (its imports need ROS)."""
    if ROS_ENVIRONMENT or collection_path.suffix != '.py' or not collection_path.name.startswith('test_'):
        return None
    tiers = tiers_named_in(collection_path)
    if tiers and 'pure' not in tiers:
        LEFT_OUT.append((collection_path.name, tiers))
        return True
    return None


@pytest.hookimpl(wrapper=True)
def pytest_make_collect_report(collector):
    """A test file or class whose tests do not each have exactly one tier fails to collect."""
    report = yield
    if report.passed and isinstance(collector, (pytest.Module, pytest.Class)):
        wrong = {f'{item.originalname} ({", ".join(sorted(tiers_of(item))) or "no tier"})'
                 for item in report.result if isinstance(item, pytest.Function) and len(tiers_of(item)) != 1}
        if wrong:
            report.outcome, report.result = 'failed', []
            report.longrepr = (f'{collector.nodeid}: every test needs exactly one tier marker of '
                               f'{", ".join(TIERS)} (see tests/pytest.ini); not so: {", ".join(sorted(wrong))}')
    return report


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """Without ROS, the tests of other tiers than pure in a file with pure tests are deselected."""
    if ROS_ENVIRONMENT:
        return
    needing_ros = [item for item in items if tiers_of(item) != {'pure'}]
    if needing_ros:
        config.hook.pytest_deselected(items=needing_ros)
        items[:] = [item for item in items if tiers_of(item) == {'pure'}]
        LEFT_OUT.extend((item.nodeid, tiers_of(item)) for item in needing_ros)


FAILED_RUNS = ROOT / 'output' / 'test'   # where a failing run's failures are kept (README, "The two commands")
FAILURES = []   # the text of each failing test's report: its traceback and captured output


def pytest_runtest_logreport(report):
    if report.failed:
        captured = ''.join(f'\n--- {name} ---\n{text}' for name, text in report.sections)
        FAILURES.append(f'=== {report.nodeid} ({report.when}) ===\n{report.longreprtext}{captured}\n')


def pytest_terminal_summary(terminalreporter):
    if FAILURES:
        FAILED_RUNS.mkdir(parents=True, exist_ok=True)
        log = FAILED_RUNS / time.strftime('failed-%Y%m%d-%H%M%S.log')
        log.write_text(''.join(FAILURES))
        terminalreporter.write_line(f'The failures, with their captured output: {log}', red=True)
    if LEFT_OUT:
        names = ', '.join(f'{name} ({"/".join(sorted(tiers))})' for name, tiers in LEFT_OUT)
        terminalreporter.write_line(f'Not run through ./mvpose test (MVPOSE_ROOT unset), so without ROS: the pure '
                                    f'tier only; left out: {names}. `./mvpose test` runs every tier.', yellow=True)


# ---- no process outlives its test ---------------------------------------------------------------

PR_SET_CHILD_SUBREAPER = 36   # linux/prctl.h: orphaned descendants are re-parented to this process
LEFTOVER_GRACE = 5.0          # [s] for a test's processes to finish ending after it


def living_children():
    """{pid: command line} of this process's children that are not zombies (with the test process a child
    subreaper, that includes every orphaned descendant of a test: a pool worker whose parent was killed)."""
    children = {}
    for entry in os.listdir('/proc'):
        if not entry.isdigit():
            continue
        try:
            stat_fields = Path(f'/proc/{entry}/stat').read_text().rsplit(')', 1)[1].split()
            command = Path(f'/proc/{entry}/cmdline').read_bytes().replace(b'\0', b' ').decode(errors='replace')
        except OSError:   # ended meanwhile
            continue
        state, parent = stat_fields[0], int(stat_fields[1])
        if parent == os.getpid() and state != 'Z':
            children[int(entry)] = command.strip()
    return children


def pytest_sessionstart(session):
    ctypes.CDLL(None, use_errno=True).prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0)


@pytest.fixture(autouse=True)
def no_process_left_behind(request):
    """Fails a test (as an error in its teardown) that leaves a process running after it and its fixtures
    ended (issue 17), naming the processes, and kills them so that the tests after it run clean."""
    before = living_children()
    yield
    deadline = time.monotonic() + LEFTOVER_GRACE
    while (left := {pid: command for pid, command in living_children().items() if pid not in before}) \
            and time.monotonic() < deadline:
        time.sleep(0.1)
    for pid in left:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
    if left:
        pytest.fail(f'{request.node.nodeid} left {len(left)} process(es) running: '
                    + '; '.join(f'{pid} {command}' for pid, command in sorted(left.items())), pytrace=False)


def pytest_sessionfinish(session):
    """The whole run fails if a process started by it (or orphaned by one it started) still runs."""
    left = living_children()
    for pid in left:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
    with contextlib.suppress(ChildProcessError):
        while os.waitpid(-1, os.WNOHANG)[0]:   # the zombies of orphans re-parented here
            pass
    if left:
        session.exitstatus = pytest.ExitCode.TESTS_FAILED
        print(f'\n{len(left)} process(es) outlived the test run (killed now): '
              + '; '.join(f'{pid} {command}' for pid, command in sorted(left.items())), file=sys.stderr)


# ---- fixtures ----------------------------------------------------------------------------------

@pytest.fixture
def background():
    """Start `./mvpose ARGS` processes in the background; any still running are killed at the end."""
    started = []

    def start(*args):
        started.append(Background(*args))
        return started[-1]
    yield start
    for process in started:
        process.kill()


@pytest.fixture(scope='session')
def ros_context():
    """rclpy initialised once for the tests that talk over DDS from the test process itself."""
    import rclpy
    rclpy.init()
    yield
    rclpy.try_shutdown()


def make_read_only(path):
    for folder, _, files in os.walk(path):
        for name in files:
            os.chmod(Path(folder, name), stat.S_IRUSR | stat.S_IRGRP | stat.S_IROTH)
        os.chmod(folder, stat.S_IRUSR | stat.S_IXUSR | stat.S_IRGRP | stat.S_IXGRP | stat.S_IROTH | stat.S_IXOTH)


@pytest.fixture(scope='session')
def synth_bag(tmp_path_factory):
    """synth_bag(ARGS...): the bag `./mvpose synth ARGS -o BAG` writes, made the first time a test asks for
    these ARGS and shared for the rest of the session. It is read-only: a test that changes a bag copies it
    first (shutil.copytree). Not for the tests of synth itself that compare separate runs."""
    made = {}

    def make(*args):
        key = tuple(map(str, args))
        if key not in made:
            bag = tmp_path_factory.mktemp('synth') / 'bag'
            run_mvpose('synth', *key, '-o', bag, timeout=300)
            make_read_only(bag)
            made[key] = bag
        return made[key]
    return make


@pytest.fixture(scope='session')
def cmu_walk():
    """The CMU walk 07_01 retargeted to the body model (studio.mocap.retarget's defaults: 1.75 m, the
    studio's frame rate), loaded once. Its arrays are read-only: take .placed(), .select() or copies."""
    from mvpose_nodes.studio.mocap import cmu_clip, load_bvh, retarget
    return retarget(load_bvh(cmu_clip('07_01'))).read_only()
