"""The fitter's real-time queue (fitting.sync.PendingSets), its frame requests (fitting.sync.FrameRequests)
and the per-stage CPU clock (ros.diagnostics): pure tests, some with threads. Over DDS: the
skeleton_fitter skipping stale frame sets in test_skeleton_fitter_node.py, a camera following requests
in test_camera_features_node.py."""
import threading
import time
from concurrent.futures import ThreadPoolExecutor

import pytest

from mvpose_nodes.fitting.sync import FrameRequests, PendingSets, SyncedSet, ready_to_request
from mvpose_nodes.ros.diagnostics import StageClock, pool_cpu_seconds, thread_cpu_seconds

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


def test_a_thread_pools_cpu_is_the_sum_of_its_threads():
    """pool_cpu_seconds adds up the CPU of a ThreadPoolExecutor's threads (named by its thread_name_prefix),
    not that of other threads whose name only begins alike."""
    def spin(seconds):
        deadline = time.thread_time() + seconds
        while time.thread_time() < deadline:
            pass
        return threading.current_thread().name, time.thread_time()
    assert pool_cpu_seconds('spinners') == 0.0
    with ThreadPoolExecutor(2, thread_name_prefix='spinners') as pool:
        clocks = {}   # each pool thread's CPU clock at the end of its last task
        for name, seconds in pool.map(spin, [0.05, 0.05]):
            clocks[name] = max(seconds, clocks.get(name, 0.0))
        spent = sum(clocks.values())
        assert spent >= 0.1
        others = threading.Thread(target=spin, args=(0.05,), name='spinnersX')
        others.start()
        assert pool_cpu_seconds('spinners') == pytest.approx(spent, abs=0.01)
        others.join()


def announced(stamp_ms, cameras=(3, 5, 7)):
    """A SyncedSet of announcements, each camera 1 ms after the one before."""
    stamps = {(k, 'frame_available'): (stamp_ms + i) * 10**6 for i, k in enumerate(cameras)}
    return SyncedSet(max(stamps.values()), dict(stamps), stamps, frozenset())


def test_requests_ask_for_the_newest_announced_set_once_ready_and_count_the_passed_over():
    requests = FrameRequests(timeout=1.0)
    assert requests.next_request(0.0, ready=True) is None, 'nothing announced'
    for stamp in (0, 40, 80):
        requests.announce(announced(stamp))
    assert requests.next_request(0.0, ready=False) is None, 'the fitter is busy'
    assert requests.next_request(0.1, ready=True) == announced(80) and requests.skipped == 2
    requests.announce(announced(120))
    assert requests.next_request(0.2, ready=True) is None, 'one request outstanding at a time'
    requests.received(82 * 10**6)   # the features of the set requested (its newest stamp)
    assert requests.next_request(0.2, ready=True) == announced(120) and requests.skipped == 2
    assert requests.next_request(0.3, ready=True) is None, 'each announced set requested once'


def test_a_request_without_an_answer_is_given_up_after_the_timeout():
    requests = FrameRequests(timeout=1.0)
    requests.announce(announced(0))
    assert requests.next_request(10.0, ready=True) == announced(0)
    requests.received(-1)   # an older set does not answer it
    requests.announce(announced(40))
    assert requests.next_request(10.9, ready=True) is None and requests.unanswered == 0
    assert requests.next_request(11.1, ready=True) == announced(40) and requests.unanswered == 1
    assert requests.skipped == 0


def test_a_request_given_up_is_asked_once_more_when_nothing_newer_came():
    """A request lost at start-up (before a camera's subscription matched) in a stream that then stops
    (a bench's closed loop, the end of a bag): asked again once, not for ever; a newer announcement or the
    late answer itself cancels the second asking."""
    requests = FrameRequests(timeout=1.0)
    requests.announce(announced(0))
    assert requests.next_request(10.0, ready=True) == announced(0)
    assert requests.next_request(11.1, ready=False) is None and requests.unanswered == 1   # busy: kept
    assert requests.next_request(11.2, ready=True) == announced(0)
    assert requests.next_request(12.3, ready=True) is None and requests.unanswered == 2    # once only
    assert requests.next_request(20.0, ready=True) is None and requests.skipped == 0

    requests.announce(announced(40))
    assert requests.next_request(30.0, ready=True) == announced(40)
    requests.announce(announced(80))
    assert requests.next_request(31.1, ready=True) == announced(80)   # the newer set, not the retry
    assert requests.next_request(32.2, ready=False) is None and requests.retry == announced(80)
    requests.received(82 * 10**6)   # its features came late after all
    assert requests.next_request(32.3, ready=True) is None and requests.retry is None


def test_request_overlap_names_the_stages_that_may_still_be_busy():
    """request_overlap 2 asks as soon as nothing waits, 1 once the distance maps are free (the fit may still
    run), 0 once both stages are free; nothing waiting before the stages comes first in every case."""
    for maps_busy in (False, True):
        for fit_busy in (False, True):
            stages = (maps_busy, fit_busy)
            assert ready_to_request(False, stages, 2)
            assert ready_to_request(False, stages, 1) == (not maps_busy)
            assert ready_to_request(False, stages, 0) == (not maps_busy and not fit_busy)
            assert not any(ready_to_request(True, stages, overlap) for overlap in (0, 1, 2))


def test_no_set_is_asked_for_while_a_start_is_fitted():
    """A start fits every labelling (several fits' time): whatever request_overlap says, the next set is asked
    for only once both stages are free, as with overlap 0."""
    for maps_busy in (False, True):
        for fit_busy in (False, True):
            stages = (maps_busy, fit_busy)
            for overlap in (0, 1, 2):
                assert ready_to_request(False, stages, overlap, starting=True) == (not maps_busy and not fit_busy)
                assert not ready_to_request(True, stages, overlap, starting=True)
