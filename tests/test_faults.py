"""Faults the graph survives (issue 15), over DDS with the nodes as separate processes: a camera's feature
node killed and started again, the fitter killed and started again. The launcher's respawn is tested in
test_launcher.py, the synchroniser's odd stamps in test_sync.py."""
import json
import os
import signal
import time

import pytest
from common import GRAPH_CAMERAS, GRAPH_INPUTS, SKELETON_OUT, SkeletonRecorder, wait_for_graph

from mvpose_nodes.app.graph_run import graph_inputs
from mvpose_nodes.fitting.settings import FitterSettings

pytestmark = pytest.mark.graph

# The bag's speed: slow enough for the graph (a restarted fitter's start passes over some: STARTING_FITS).
RATE = 0.1
CAMERA_TIMEOUT = 0.5  # [s] of bag time the fitter waits for a silent camera (skeleton_fitter's camera_timeout)
# [s] of wall time a killed camera stays down: longer than CAMERA_TIMEOUT of bag time at RATE (5 s), so that
# the fitter leaves it out (the synchroniser's silence is in the input's time, so that a bag gives the same
# frame sets at any rate), and short enough that it is back well before the bag's end.
CAMERA_DOWN = 6.0
FRAME_NS = 40_000_000
BAG_FRAMES = '45-104'  # 60 frames: 2.4 s of bag, 24 s at RATE
# A restarted fitter's first fits, slower (numba's cache loaded, and a start's labellings compared over
# hypothesis_frames fits): the frame sets played meanwhile are passed over.
STARTING_FITS = FitterSettings().hypothesis_frames + 1


def play_into_graph(synth_bag, background, recorder):
    """The processes of launch/mvpose.launch.yaml started one by one (so that each can be killed alone),
    the bag played into them, and the first skeletons in: ({camera: Background}, the fitter's and the
    player's Background)."""
    bag = synth_bag('--cameras', *GRAPH_CAMERAS, '--frames', BAG_FRAMES, '--resolution', '960x540')
    cameras = {k: start_camera(background, k) for k in GRAPH_CAMERAS}
    fitter = start_fitter(background)
    wait_for_graph(graph_inputs(GRAPH_CAMERAS), [SKELETON_OUT])
    player = background('bag', 'play', bag, '--rate', RATE, '--topics', *GRAPH_INPUTS)
    recorder.spin_until_count(5, timeout=60)
    recorder.spin_for(1.0)
    return cameras, fitter, player


def play_to_the_end(player, recorder):
    code, _, err = player.finish(timeout=120)
    assert code == 0, err
    recorder.spin_for(3.0)   # the bag's last frame sets, flushed after camera_timeout


def start_camera(background, k):
    return background('run', 'camera_features', '--ros-args', '-r', f'__ns:=/cam{k}')


def start_fitter(background):
    return background('run', 'skeleton_fitter', '--ros-args', '-p', f'camera_timeout:={CAMERA_TIMEOUT}')


def kill(process):
    """SIGKILL to the process and its children (a crash: no clean-up)."""
    os.killpg(process.process.pid, signal.SIGKILL)
    process.process.wait()


def used_cameras(received):
    """The cameras a DEGRADED skeleton names in its status message ('cameras used: [3, 5]', perhaps followed by
    '; …'), None if it names none (all of them used)."""
    first_part = received[3].split('; ')[0]
    prefix = 'cameras used: '
    return json.loads(first_part[len(prefix):]) if first_part.startswith(prefix) else None


def bag_time(stamp, first):
    return (stamp - first) / 1e9


@pytest.mark.timeout(300)
def test_a_camera_node_killed_leaves_a_degraded_fit_and_is_used_again_when_it_returns(synth_bag, background,
                                                                                      ros_context):
    """Camera 7's node is killed 2 s into the bag and started again CAMERA_DOWN later: skeletons keep coming,
    DEGRADED with cameras 3 and 5, with no gap of more than camera_timeout of bag time, and once the node
    is back the fit uses all three cameras again."""
    recorder = SkeletonRecorder()
    try:
        cameras, _, player = play_into_graph(synth_bag, background, recorder)
        kill(cameras[7])
        killed_after = len(recorder.received)
        recorder.spin_for(CAMERA_DOWN)
        start_camera(background, 7)
        restarted = time.monotonic()
        wait_for_graph(graph_inputs([7]))
        back_after = time.monotonic() - restarted   # [s]: how long the node took to start, for the messages
        play_to_the_end(player, recorder)
    finally:
        recorder.close()
    stamps = recorder.stamps()
    first = stamps[0]
    gaps = [bag_time(b, a) for a, b in zip(stamps, stamps[1:])]
    assert max(gaps) <= CAMERA_TIMEOUT + 2 * FRAME_NS / 1e9, (gaps, recorder.received)
    after_kill = recorder.received[killed_after:]
    # A status message may go on to say that stale frame sets were skipped (while the fitter waits
    # camera_timeout for the silent camera, newer sets come): only its first part names the cameras.
    degraded = [r for r in after_kill if used_cameras(r) == [3, 5]]
    assert degraded, after_kill
    # Once camera 7 is back every fit uses it. Another camera may miss a set while camera 7's node starts
    # beside it on the two cores (its features come after camera_timeout): that set is fitted without it.
    back = [r for r in after_kill if r[1] > degraded[-1][1]]
    timeline = [(round(bag_time(r[1], first), 2), r[2], used_cameras(r)) for r in after_kill]
    started = (f'camera 7 connected {back_after:.1f} s after its restart; after the kill '
               f'(bag time [s], status, cameras used): {timeline}')
    assert back and all(used_cameras(r) is None or 7 in used_cameras(r) for r in back), started
    assert any(r[2] == 0 and used_cameras(r) is None for r in back), started   # STATUS_OK: all three
    assert bag_time(stamps[-1], first) == pytest.approx(59 * FRAME_NS / 1e9)   # up to the bag's last frame


@pytest.mark.timeout(300)
def test_the_fitter_killed_and_started_again_catches_up_with_the_newest_frame_set(synth_bag, background,
                                                                                 ros_context):
    """The fitter is killed 2 s into the bag and started again: it initialises afresh from the frame set
    being played when it is back (not from a backlog) and fits the frame sets from there to the last."""
    recorder = SkeletonRecorder()
    try:
        _, fitter, player = play_into_graph(synth_bag, background, recorder)
        kill(fitter)
        # Take what the old fitter sent before it died: a skeleton still in the recorder's reader cache, taken
        # after the count, once passed for the new fitter's first (status OK, at the stamp of the kill).
        recorder.spin_for(0.5)
        before = len(recorder.received)
        start_fitter(background)
        recorder.spin_until_count(before + 1, timeout=60)
        restarted = recorder.received[before]
        play_to_the_end(player, recorder)
    finally:
        recorder.close()
    stamps = recorder.stamps()
    first = stamps[0]
    # The new fitter's first skeleton (taken as it came: spin_until_count spins) is initialising, and of a
    # frame set played at most 2 s (ten frame sets) before, counting from the old fitter's first: it skipped
    # what was held while it was down (killed ~1.5 s in, back ~3 s later: working through that would put
    # it 2.5 s or more behind). Its first fit is slow: 0.6 s behind here, 1.05 s once on a loaded CI.
    assert restarted[2] == 1, restarted   # STATUS_INITIALISING
    expected_arrival = recorder.received[0][0] + bag_time(restarted[1], first) / RATE
    assert restarted[0] - expected_arrival < 2.0, (restarted, recorder.received[0])
    # Then every frame set to the last. Its first fits are slower (numba's cache loaded, the maps made), and as
    # it keeps to the newest frame set it passes over those played meanwhile (counted): as many as its start
    # took, one after its second fit in one CI run, five after its first in another.
    after = stamps[before:]
    steps = [round(bag_time(b, a) * 1e9 / FRAME_NS) for a, b in zip(after, after[1:])]
    assert steps[STARTING_FITS:] == [1] * (len(steps) - STARTING_FITS), steps
    assert bag_time(stamps[-1], first) == pytest.approx(59 * FRAME_NS / 1e9)
