"""The fitter's real-time queue (fitting.sync.PendingSets) and the per-stage CPU clock (ros.diagnostics):
pure tests with threads. The skeleton_fitter node skipping stale frame sets over DDS: test_real_time.py."""
import threading
import time

import pytest

from mvpose_nodes.fitting.sync import PendingSets
from mvpose_nodes.ros.diagnostics import StageClock, thread_cpu_seconds

pytestmark = pytest.mark.pure


def test_depth_one_keeps_the_newest_and_counts_the_skipped():
    pending = PendingSets(depth=1)
    for item in range(5):
        pending.put(item)
    assert pending.take(timeout=0) == 4 and pending.skipped == 4
    assert pending.take(timeout=0.01) is None


def test_depth_zero_keeps_everything_in_order():
    pending = PendingSets(depth=0)
    for item in range(5):
        pending.put(item)
    assert [pending.take(timeout=0) for _ in range(5)] == list(range(5)) and pending.skipped == 0


def test_a_slow_worker_never_has_more_than_one_waiting():
    pending, taken, waiting = PendingSets(depth=1), [], []

    def worker():
        while True:
            item = pending.take(timeout=1.0)
            if item is None:
                return
            waiting.append(len(pending._waiting))
            taken.append(item)
            time.sleep(0.01)          # slower than the producer
    thread = threading.Thread(target=worker)
    thread.start()
    for item in range(100):
        pending.put(item)
        time.sleep(0.001)
    thread.join()
    assert taken == sorted(taken) and taken[-1] == 99, 'in order, ending with the newest'
    assert len(taken) + pending.skipped == 100 and pending.skipped > 50
    assert max(waiting) == 0


def test_close_wakes_a_waiting_worker():
    pending = PendingSets()
    found = []
    thread = threading.Thread(target=lambda: found.append(pending.take(timeout=30)))
    thread.start()
    pending.close()
    thread.join(timeout=5)
    assert not thread.is_alive() and found == [None]


def test_stage_clock_counts_the_calling_threads_cpu_not_its_sleep():
    clock = StageClock()
    with clock('spin'):
        deadline = time.thread_time() + 0.05
        while time.thread_time() < deadline:
            pass
    with clock('sleep'):
        time.sleep(0.05)
    seconds = {stage: value for stage, (value, _) in clock.snapshot().items()}
    assert seconds['spin'] >= 0.05 and seconds['sleep'] < 0.01
    assert clock.snapshot()['spin'][1] == 1
    assert thread_cpu_seconds(threading.current_thread()) >= 0.05
