"""The statistics and the printed table of `./mvpose bench` (app/bench.py), pure: tested on constructed
numbers (tests/test_bench.py)."""
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

TARGET_RATE, AIM_RATE = 12.5, 25     # [frame sets/s] issue 14: half the cameras' 25 fps, and real time
STALL_TIMEOUT = 60.0                # [s] without a skeleton for a frame set sent: it counts as dropped


def median_p95(values):
    """(median, 95th percentile) of `values` (linear interpolation, as numpy); (nan, nan) when empty."""
    values = np.asarray(list(values), dtype=float)
    if values.size == 0:
        return float('nan'), float('nan')
    return float(np.median(values)), float(np.percentile(values, 95))


def stage_latencies(sent, features, skeletons):
    """Per-stage latencies [ms] from the wall times [s] of one run.

    sent: {stamp: time the frame set's images were published}; features: {stamp: {camera: time its
    labelled_contour arrived}}; skeletons: {stamp: (time the skeleton arrived, its fit_time [s])}.
    Returns {'features': [...] (one per camera and frame set), 'sync wait': [...], 'fit': [...],
    'end to end': [...]}; sync wait and end to end only for frame sets with every camera's contour."""
    out = {'features': [], 'sync wait': [], 'fit': [], 'end to end': []}
    for stamp, t_sent in sent.items():
        arrived = features.get(stamp, {})
        out['features'].extend(1e3 * (t - t_sent) for t in arrived.values())
        if stamp not in skeletons:
            continue
        t_skeleton, fit_time = skeletons[stamp]
        out['fit'].append(1e3 * fit_time)
        out['end to end'].append(1e3 * (t_skeleton - t_sent))
        if arrived:
            out['sync wait'].append(1e3 * (t_skeleton - fit_time - max(arrived.values())))
    return out


def throughput(sent, skeletons):
    """Frame sets fitted per second: fitted / (last skeleton arrival - first images published); 0 if none."""
    if not skeletons or not sent:
        return 0.0
    span = max(t for t, _ in skeletons.values()) - min(sent.values())
    return len(skeletons) / span if span > 0 else float('inf')


def decode_only_rate(decode_ms, cameras):
    """Frame sets per second one core decoding only: 1 / (cameras x median decode time of one image)."""
    median, _ = median_p95(decode_ms)
    return 1e3 / (cameras * median) if median > 0 else float('nan')


def cpu_ticks(stat_text):
    """utime + stime [clock ticks] of a /proc/PID/stat line (the command name may hold spaces and ')')."""
    fields = stat_text.rsplit(')', 1)[1].split()
    return int(fields[11]) + int(fields[12])   # fields 14 and 15 of proc(5), counted from 'state' = 3


def status_kib(status_text, key='VmHWM'):
    """A size [kB] of a /proc/PID/status text (VmHWM: peak RSS, VmRSS: RSS now), or None when it has none
    (e.g. a zombie)."""
    for line in status_text.splitlines():
        if line.startswith(f'{key}:'):
            return int(line.split()[1])
    return None


def resident_mib(pid):
    """RSS [MiB] of a running process now, or NaN when it is gone."""
    try:
        kib = status_kib(Path(f'/proc/{pid}/status').read_text(), 'VmRSS')
    except OSError:
        kib = None
    return kib / 1024 if kib is not None else float('nan')


def sample_process(pid):
    """(cpu ticks, peak RSS kB) of a running process, or None when it is gone."""
    try:
        return (cpu_ticks(Path(f'/proc/{pid}/stat').read_text()),
                status_kib(Path(f'/proc/{pid}/status').read_text()))
    except (OSError, IndexError, ValueError):
        return None


def node_usage(before, after, wall_seconds, ticks_per_second):
    """Per node: (CPU s, CPU % of wall_seconds, peak RSS MiB) from two samples {node: (ticks, peak kB)}
    taken at the start and the end of the run; None entries (process gone) give NaNs."""
    rows = {}
    for name, end in after.items():
        start = before.get(name)
        if end is None or start is None:
            rows[name] = (float('nan'), float('nan'), float('nan'))
            continue
        seconds = (end[0] - start[0]) / ticks_per_second
        percent = 100.0 * seconds / wall_seconds if wall_seconds > 0 else float('nan')
        rows[name] = (seconds, percent, end[1] / 1024 if end[1] is not None else float('nan'))
    return rows


# ---------------------------------------------------------------- the report

def cpu_split(before, after):
    """Where a node's CPU went between two of its /diagnostics statuses, each as ros.diagnostics.stage_cpu
    gives its CPU: {'process': s, 'thread/<name>': s, 'pool/<name>': s, 'stage/<stage>': s}. Returns
    {label: CPU s}: each stage; 'rclpy (take, deserialise, executor)': what no stage covers in the node's
    threads; '<name> pool': each thread pool's threads (the skeleton_fitter's 'hypotheses' pool does part
    of its fit); 'DDS and other threads': what no thread or pool covers in the process; 'total': the
    process."""
    def delta(key):
        return after.get(key, 0.0) - before.get(key, 0.0)
    stages = {key[6:]: delta(key) for key in after if key.startswith('stage/')}
    threads = sum(delta(key) for key in after if key.startswith('thread/'))
    pools = {f'{key[5:]} pool': delta(key) for key in after if key.startswith('pool/')}
    process = delta('process')
    return {**stages, 'rclpy (take, deserialise, executor)': threads - sum(stages.values()), **pools,
            'DDS and other threads': process - threads - sum(pools.values()), 'total': process}


def backlog_growth(sent, skeletons):
    """(median latency [ms] of the first quarter of the fitted frame sets, of the last quarter), in stamp
    order: a backlog that grows shows as the second far above the first."""
    latencies = [1e3 * (skeletons[stamp][0] - sent[stamp]) for stamp in sorted(skeletons) if stamp in sent]
    quarter = max(1, len(latencies) // 4)
    return median_p95(latencies[:quarter])[0], median_p95(latencies[-quarter:])[0]


def fitted_by_quarter(sent, skeletons, errors_mm):
    """[(frame sets fitted, frame sets sent, mean joint error [mm] of the fitted ones with ground truth, NaN
    without)] in each quarter of the frame sets sent, in stamp order: how the share fitted and the error
    change over an open-loop run (a start, which fits every labelling of the body, costs the first quarter
    of the 50 frame sets of the default bag most; a fit lost across skipped frame sets shows as one
    quarter's error). errors_mm: {stamp: mean joint error [mm]} of fitted frame sets."""
    stamps = sorted(sent)
    bounds = np.linspace(0, len(stamps), 5).round().astype(int)
    quarters = []
    for first, last in zip(bounds[:-1], bounds[1:]):
        part = stamps[first:last]
        errors = [errors_mm[stamp] for stamp in part if stamp in errors_mm]
        quarters.append((sum(stamp in skeletons for stamp in part), len(part),
                         float(np.mean(errors)) if errors else float('nan')))
    return quarters


@dataclass
class BenchResult:
    bag: str
    cameras: tuple
    width: int
    height: int
    window: int
    frame_sets: int
    rate: float = None                              # open loop at this multiple of the bag's speed; None: closed loop
    sent: dict = field(default_factory=dict)        # stamp -> t published
    features: dict = field(default_factory=dict)    # stamp -> {camera: t contour received}
    skeletons: dict = field(default_factory=dict)   # stamp -> (t received, fit_time)
    messages: dict = field(default_factory=dict)    # stamp -> the fitted Skeleton message (bench -o only)
    unfitted: int = 0                               # frame sets the fitter had too few views for
    lost: int = 0                                   # frame sets answered STATUS_LOST (the fit lost the person)
    dropped: int = 0                                # frame sets without any answer within STALL_TIMEOUT
    overtaken: int = 0                              # frame sets unanswered when a later one was fitted (skipped)
    skipped: int = 0                                # frame sets the fitter skipped as stale (its /diagnostics)
    errors_mm: dict = field(default_factory=dict)   # stamp -> mean joint error [mm] of a fitted frame set
    decode_ms: list = field(default_factory=list)
    usage: dict = field(default_factory=dict)       # node -> (CPU s, CPU %, peak RSS MiB)
    split: dict = field(default_factory=dict)       # node -> cpu_split over the run
    wall_seconds: float = 0.0
    launched: float = None                          # t the graph's processes were started
    connected: float = None                         # t every node's topics had matched (graph_run.wait_for_connections)
    samples: list = field(default_factory=list)     # SoakSample, every sample_every frame sets answered (soak)


@dataclass
class SoakSample:
    """The graph part-way through a soak: frame sets answered so far, seconds since the first was sent,
    each node's RSS [MiB] now, and the median end-to-end latency [ms] of the frame sets fitted since the
    sample before."""
    answered: int
    seconds: float
    resident_mib: dict
    latency_ms: float


def _number(value, width=8, digits=1):
    return f'{value:{width}.{digits}f}' if np.isfinite(value) else f'{"-":>{width}}'


def format_table(result):
    """The printed table of a BenchResult."""
    fitted = len(result.skeletons)
    rate = throughput(result.sent, result.skeletons)
    floor_rate = decode_only_rate(result.decode_ms, len(result.cameras))
    missing = result.frame_sets - fitted
    unsent = missing - result.unfitted - result.lost - result.overtaken - result.dropped
    if not missing:
        outcome = 'none dropped'
    else:
        outcome = ', '.join(part for part in (
            f'{result.unfitted} with too few views' if result.unfitted else '',
            f'{result.lost} lost (STATUS_LOST)' if result.lost else '',
            f'{result.overtaken} passed over (a later one was fitted)' if result.overtaken else '',
            f'{result.dropped} dropped (no answer in {STALL_TIMEOUT:.0f} s)' if result.dropped else '',
            f'{unsent} not sent' if unsent else '') if part)
    ratio = rate / floor_rate if floor_rate and np.isfinite(floor_rate) else float('nan')
    lines = [
        f'bench: {result.bag}  ({result.frame_sets} frame sets, cameras {" ".join(map(str, result.cameras))}, '
        f'{result.width}×{result.height}, window {result.window})',
        f'  end-to-end    {_number(rate, 6, 2)} frame sets/s   ({fitted} of {result.frame_sets} fitted, {outcome})'
        f'     target {TARGET_RATE:g}/s, aim {AIM_RATE}/s',
        f'  decode only   {_number(floor_rate, 6, 1)} frame sets/s on one core (1 / ({len(result.cameras)} × median '
        f'decode));  end-to-end / decode-only = {ratio:.3f}',
        '  latency [ms]          median      p95',
    ]
    stages = stage_latencies(result.sent, result.features, result.skeletons)
    notes = {'decode': '(decode_image of one image, as the nodes decode, this process)',
             'features': '(images sent -> contour received, per camera)',
             'sync wait': '(skeleton received - fit - last contour received; includes queueing behind the previous fit)',
             'fit': '(Skeleton.fit_time)',
             'end to end': '(images sent -> skeleton received)'}
    for stage, values in (('decode', result.decode_ms), *stages.items()):
        median, p95 = median_p95(values)
        lines.append(f'    {stage:<16}{_number(median, 9)}{_number(p95, 9)}   {notes[stage]}')
    if result.rate is not None:
        first, last = backlog_growth(result.sent, result.skeletons)
        errors = list(result.errors_mm.values())
        lines += [f'  open loop at {result.rate:g}× the bag\'s speed: {fitted} of {len(result.sent)} frame sets fitted '
                  f'({100 * fitted / max(1, len(result.sent)):.0f} %), {result.skipped} skipped by the fitter as stale',
                  '    fitted in each quarter of the frame sets sent (their mean joint error): ' + ', '.join(
                      f'{done} of {count} ({_number(error, 0, 0)} mm)'
                      for done, count, error in fitted_by_quarter(result.sent, result.skeletons, result.errors_mm)),
                  f'    end-to-end latency, median of the first and the last quarter fitted: {_number(first, 0, 0)} and '
                  f'{_number(last, 0, 0)} ms (a growing backlog would show as the second far above the first)',
                  f'    mean joint error of the fitted frame sets: {_number(float(np.mean(errors)) if errors else np.nan, 0, 0)} '
                  f'mm ({len(errors)} with ground truth)']
    if result.launched is not None and result.skeletons:
        first_sent, first_skeleton = min(result.sent.values()), min(t for t, _ in result.skeletons.values())
        lines.append(f'  start-up: launch -> graph connected {result.connected - result.launched:.1f} s, -> first images '
                     f'sent {first_sent - result.launched:.1f} s, -> first skeleton {first_skeleton - result.launched:.1f} s')
    lines.append(f'  node                        CPU s    CPU %   peak RSS MiB   (CPU over the {result.wall_seconds:.1f} s run)')
    for name, (seconds, percent, mib) in result.usage.items():
        lines.append(f'    {name:<24}{_number(seconds, 7)}{_number(percent, 9, 0)}{_number(mib, 15, 0)}')
    if result.split:
        sets = max(1, len(result.sent))
        lines.append('  where each node\'s CPU goes [ms per frame set sent] (its /diagnostics over the run)')
        for name, split in result.split.items():
            parts = '  '.join(f'{label} {1e3 * seconds / sets:.1f}' for label, seconds in split.items())
            lines.append(f'    {name:<24}{parts}')
    return '\n'.join(lines)




def format_soak(result, warm_up):
    """The printed report of a soak (a BenchResult with samples): memory of each node and latency over
    time, and what was not fitted. Growth is measured from the first sample at or after `warm_up` frame
    sets (start-up allocations, caches and numba are not a leak) to the last."""
    samples = result.samples
    fitted = len(result.skeletons)
    lines = [f'soak: {result.bag}  ({len(result.sent)} frame sets sent, cameras {" ".join(map(str, result.cameras))}, '
             f'{result.width}×{result.height}, window {result.window}, {result.wall_seconds / 60:.1f} min)',
             f'  fitted {fitted}; too few views {result.unfitted}; lost (STATUS_LOST) {result.lost}; passed over '
             f'{result.overtaken}; skipped by the fitter {result.skipped}; dropped (no answer in {STALL_TIMEOUT:.0f} s) '
             f'{result.dropped}']
    if not samples:
        return '\n'.join(lines + ['  (no sample: fewer frame sets than one sample period)'])
    names = list(samples[0].resident_mib)
    lines.append('  frame sets   minutes   latency ms   ' + '  '.join(f'{name:>22}' for name in names) + '   (RSS MiB)')
    for sample in samples:
        lines.append(f'  {sample.answered:>10}  {sample.seconds / 60:>8.1f}  {_number(sample.latency_ms, 11, 0)}   '
                     + '  '.join(f'{_number(sample.resident_mib[name], 22, 1)}' for name in names))
    base = next((s for s in samples if s.answered >= warm_up), samples[-1])
    last = samples[-1]
    growth = {name: last.resident_mib[name] - base.resident_mib[name] for name in names}
    lines.append(f'  RSS growth from {base.answered} to {last.answered} frame sets [MiB]: '
                 + ', '.join(f'{name} {_number(value, 0, 1)}' for name, value in growth.items()))
    after_warm_up = [s.latency_ms for s in samples if s.answered > base.answered and np.isfinite(s.latency_ms)]
    if after_warm_up:
        lines.append(f'  latency drift: median of the first sample after warm-up {after_warm_up[0]:.0f} ms, of the last '
                     f'{after_warm_up[-1]:.0f} ms (range {min(after_warm_up):.0f}–{max(after_warm_up):.0f} ms)')
    return '\n'.join(lines)
