"""`./mvpose bench`: its statistics on constructed numbers. Its one-line errors: test_front_door.py; one run of
the real graph: test_graph.py."""
import dataclasses
import math
import os
import re

import pytest

from mvpose_nodes.app.reports import benchmark as bench

pytestmark = pytest.mark.pure


def test_median_and_p95_interpolate_like_numpy():
    assert bench.median_p95(range(1, 101)) == pytest.approx((50.5, 95.05))
    assert bench.median_p95([7.0]) == (7.0, 7.0)
    assert bench.median_p95([3, 1, 2]) == pytest.approx((2.0, 2.9))
    median, p95 = bench.median_p95([])
    assert math.isnan(median) and math.isnan(p95)


def test_stage_latencies_from_wall_times():
    sent = {100: 10.0, 200: 11.0, 300: 12.0}
    features = {100: {3: 10.05, 5: 10.10, 7: 10.20},
                200: {3: 11.30, 5: 11.10, 7: 11.20},
                300: {3: 12.40}}                       # 300: two contours never came, no skeleton
    skeletons = {100: (10.50, 0.25), 200: (11.90, 0.40)}
    stages = bench.stage_latencies(sent, features, skeletons)
    assert sorted(stages['features']) == pytest.approx([50, 100, 100, 200, 200, 300, 400])
    assert stages['fit'] == pytest.approx([250, 400])
    assert stages['end to end'] == pytest.approx([500, 900])
    # skeleton - fit - last contour: 10.50 - 0.25 - 10.20 and 11.90 - 0.40 - 11.30
    assert stages['sync wait'] == pytest.approx([50, 200])


def test_throughput_counts_fitted_sets_from_first_send_to_last_skeleton():
    sent = {1: 10.0, 2: 10.1, 3: 10.2, 4: 10.3, 5: 10.4}
    skeletons = {1: (10.5, 0.2), 2: (11.0, 0.2), 3: (11.5, 0.2), 4: (12.0, 0.2)}   # 5 never fitted
    assert bench.throughput(sent, skeletons) == pytest.approx(4 / 2.0)
    assert bench.throughput(sent, {}) == 0.0


def test_decode_only_rate_is_one_over_cameras_times_median_decode():
    assert bench.decode_only_rate([10.0, 10.0, 40.0], cameras=3) == pytest.approx(1000 / 30)
    assert bench.decode_only_rate([5.0, 4.0, 6.0, 100.0], cameras=2) == pytest.approx(1000 / 11)


def test_cpu_ticks_and_peak_rss_from_proc_texts():
    stat = ('4242 (py thon) (x)) S 1 4242 4242 0 -1 4194560 9000 0 0 0 '
            '1234 567 0 0 20 0 5 0 100 900000 30000 18446744073709551615')
    assert bench.cpu_ticks(stat) == 1234 + 567
    status = 'Name:\tpython\nVmPeak:\t  900000 kB\nVmHWM:\t  204800 kB\nVmRSS:\t  150000 kB\n'
    assert bench.status_kib(status) == 204800
    assert bench.status_kib(status, 'VmRSS') == 150000
    assert bench.status_kib('Name:\tzombie\nState:\tZ (zombie)\n') is None


def test_sample_process_reads_this_process():
    ticks, peak = bench.sample_process(os.getpid())
    assert ticks >= 0 and peak > 1024          # a Python with numpy holds more than 1 MiB
    assert bench.sample_process(2 ** 22 + 1) is None   # above pid_max's default: no such process


def test_node_usage_over_the_run():
    before = {'/cam3/camera_features': (1000, 100000), 'skeleton_fitter': (500, 150000), 'gone': (10, 1)}
    after = {'/cam3/camera_features': (1200, 153600), 'skeleton_fitter': (1500, 204800), 'gone': None}
    usage = bench.node_usage(before, after, wall_seconds=20.0, ticks_per_second=100)
    assert usage['/cam3/camera_features'] == pytest.approx((2.0, 10.0, 150.0))
    assert usage['skeleton_fitter'] == pytest.approx((10.0, 50.0, 200.0))
    assert all(math.isnan(value) for value in usage['gone'])


def test_table_reports_rates_latencies_and_nodes():
    result = bench.BenchResult('bags/x', (3, 5, 7), 1920, 1080, 2, 4,
                               sent={1: 0.0, 2: 0.5, 3: 1.0, 4: 1.5},
                               features={s: {3: t + 0.05, 5: t + 0.06, 7: t + 0.07}
                                         for s, t in {1: 0.0, 2: 0.5, 3: 1.0, 4: 1.5}.items()},
                               skeletons={1: (0.4, 0.2), 2: (0.9, 0.2), 3: (2.0, 0.2)}, unfitted=1,
                               decode_ms=[4.0] * 12, usage={'skeleton_fitter': (1.5, 75.0, 200.0)},
                               wall_seconds=2.0, launched=-3.0, connected=-1.5)
    table = bench.format_table(result)
    assert 'start-up: launch -> graph connected 1.5 s, -> first images sent 3.0 s, -> first skeleton 3.4 s' in table
    assert '3 of 4 fitted, 1 with too few views' in table
    assert re.search(r'end-to-end\s+1\.50 frame sets/s', table)          # 3 fitted / (2.0 - 0.0) s
    assert re.search(r'decode only\s+83\.3 frame sets/s', table)         # 1000 / (3 x 4 ms)
    assert 'end-to-end / decode-only = 0.018' in table
    assert re.search(r'fit\s+200\.0\s+200\.0', table)
    assert re.search(r'skeleton_fitter\s+1\.5\s+75\s+200', table)


def test_cpu_split_from_two_diagnostics_statuses():
    before = {'process': 10.0, 'thread/executor': 4.0, 'thread/fitting': 3.0, 'stage/sync': 0.5, 'stage/fit': 2.0}
    after = {'process': 20.0, 'thread/executor': 6.0, 'thread/fitting': 9.0, 'stage/sync': 1.0, 'stage/fit': 7.0,
             'stage/publish': 0.25}                       # a stage first timed during the run
    split = bench.cpu_split(before, after)
    assert split == pytest.approx({'sync': 0.5, 'fit': 5.0, 'publish': 0.25,
                                   'rclpy (take, deserialise, executor)': 8.0 - 5.75,   # threads 2 + 6
                                   'DDS and other threads': 10.0 - 8.0, 'total': 10.0})
    # A thread pool's CPU (the fitter's hypotheses) is its own, not DDS's.
    pooled = bench.cpu_split({**before, 'pool/hypotheses': 1.0}, {**after, 'pool/hypotheses': 2.5})
    assert pooled['hypotheses pool'] == pytest.approx(1.5)
    assert pooled['DDS and other threads'] == pytest.approx(10.0 - 8.0 - 1.5)
    assert pooled['rclpy (take, deserialise, executor)'] == pytest.approx(8.0 - 5.75)


def test_backlog_growth_compares_the_first_and_last_quarter():
    sent = {stamp: float(stamp) for stamp in range(8)}
    steady = {stamp: (stamp + 0.1, 0.05) for stamp in range(8)}
    growing = {stamp: (stamp + 0.1 * (stamp + 1), 0.05) for stamp in range(8)}
    assert bench.backlog_growth(sent, steady) == pytest.approx((100.0, 100.0))
    assert bench.backlog_growth(sent, growing) == pytest.approx((150.0, 750.0))   # medians of (100, 200), (700, 800)


def test_fitted_share_by_quarter_of_the_frame_sets_sent():
    sent = {stamp: 0.04 * stamp for stamp in range(10)}   # quarters of 10: stamps 0-1, 2-4, 5-7, 8-9
    fitted = {stamp: (0.04 * stamp + 0.2, 0.05) for stamp in (0, 3, 4, 6, 7, 8, 9)}
    errors = {0: 30.0, 3: 20.0, 4: 40.0, 6: 25.0, 8: 100.0, 9: 200.0}   # stamp 7 without ground truth
    quarters = bench.fitted_by_quarter(sent, fitted, errors)
    assert [(done, count) for done, count, _ in quarters] == [(1, 2), (2, 3), (2, 3), (2, 2)]
    assert [error for _, _, error in quarters] == pytest.approx([30.0, 30.0, 25.0, 150.0])
    nothing = bench.fitted_by_quarter(sent, {}, {})
    assert [(done, count) for done, count, _ in nothing] == [(0, 2), (0, 3), (0, 3), (0, 2)]
    assert all(math.isnan(error) for _, _, error in nothing)


def test_open_loop_table_reports_share_fitted_skips_and_error():
    sent = {1: 0.0, 2: 0.04, 3: 0.08, 4: 0.12}
    result = bench.BenchResult('bags/x', (3, 5, 7), 1920, 1080, 2, 4, rate=1.0, sent=sent,
                               skeletons={1: (0.1, 0.05), 3: (0.2, 0.05)}, skipped=2, overtaken=1, dropped=1,
                               errors_mm={1: 30.0, 3: 40.0},
                               decode_ms=[4.0] * 12, split={'skeleton_fitter': {'fit': 0.2, 'total': 0.4}})
    table = bench.format_table(result)
    assert "open loop at 1× the bag's speed: 2 of 4 frame sets fitted (50 %), 2 skipped by the fitter as stale" in table
    assert '(2 of 4 fitted, 1 passed over (a later one was fitted), 1 dropped (no answer in 60 s))' in table
    with_lost = bench.format_table(dataclasses.replace(result, overtaken=0, lost=1))
    assert '(2 of 4 fitted, 1 lost (STATUS_LOST), 1 dropped (no answer in 60 s))' in with_lost
    assert 'mean joint error of the fitted frame sets: 35 mm (2 with ground truth)' in table
    assert ('fitted in each quarter of the frame sets sent (their mean joint error): 1 of 1 (30 mm), 0 of 1 (- mm), '
            '1 of 1 (40 mm), 0 of 1 (- mm)') in table
    assert re.search(r'skeleton_fitter\s+fit 50\.0\s+total 100\.0', table)      # ms per frame set sent


def test_soak_report_counts_every_outcome_memory_growth_and_latency_drift():
    samples = [bench.SoakSample(answered, 10.0 * index, {'skeleton_fitter': mib}, latency)
               for index, (answered, mib, latency) in enumerate([(50, 200.0, 90.0), (100, 240.0, 70.0),
                                                                   (150, 241.0, 75.0), (200, 242.5, 80.0)])]
    result = bench.BenchResult('bags/x', (3, 5, 7), 960, 540, 2, 200, sent={s: 0.0 for s in range(200)},
                               skeletons={s: (0.1, 0.05) for s in range(190)}, unfitted=1, lost=6, overtaken=2,
                               dropped=1, wall_seconds=30.0, samples=samples)
    report = bench.format_soak(result, warm_up=100)
    assert ('fitted 190; too few views 1; lost (STATUS_LOST) 6; passed over 2; skipped by the fitter 0; '
            'dropped (no answer in 60 s) 1') in report
    assert 'RSS growth from 100 to 200 frame sets [MiB]: skeleton_fitter 2.5' in report   # from the warm-up on
    assert 'median of the first sample after warm-up 75 ms, of the last 80 ms (range 75–80 ms)' in report


def test_transport_table_subtracts_the_bare_header_round_trip():
    from mvpose_nodes.tools.transport import TransportResult, format_transport
    results = [TransportResult('(a bare std_msgs/Header)', 'std_msgs/msg/Header', 35, 0.01, 0.01, [0.4, 0.5, 0.6]),
               TransportResult('/cam3/silhouette', 'sensor_msgs/msg/Image', 2073664, 0.2, 0.2,
                               [10.0, 16.0, 20.0], unanswered=1)]
    table = format_transport(results)
    row = next(line for line in table.splitlines() if line.startswith('  /cam3/silhouette'))
    # median 16.0 - the Header's median 0.5; p95 of [10, 16, 20]: 16 + 0.9 × (20 - 16)
    assert row.split()[3:8] == ['0.20', '0.20', '16.00', '19.60', '15.50']
    assert '(1 unanswered)' in row
    assert 'round trips: 3 per topic' in table
