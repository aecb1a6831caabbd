"""Every motion the randomised evaluation suite (issue 13) can draw, by name, as a BodyMotion of the
15-joint body model at the studio's frame rate: the CMU walks (studio/cmu), CMU 131_01 in the
3dsMax-friendly release and four AMP humanoid motions (studio/motions, README-motions.md), and the
scripted actions (studio/actions).

Each motion lasts at least MINIMUM_DURATION, so that a suite can start it at a random point: clips
shorter than that play their most repeatable cycle again (bvh_cycle, amp.best_cycle: a stride
of the CMU walks, a stride of the run; the seams' points agree within about 3 cm), and the backflip
is done twice, standing between. The motions are where their sources put them (BodyMotion.placed
moves one into the studio). NumPy and SciPy only.
"""
import dataclasses
import functools
import math

import numpy as np

from mvpose_nodes.studio import actions, amp, mocap
from mvpose_nodes.studio.i3dpost import FRAME_RATE
from mvpose_nodes.studio.mocap import MotionFileError

MINIMUM_DURATION = 4.0  # [s]
CMU_CLIPS = ('07_01', '07_02', '08_08')
AMP_MOTIONS = ('amp_run', 'amp_hop', 'amp_cartwheel', 'amp_backflip')
ACTIONS = ('turn_on_the_spot', 'walk_backwards', 'bend_down_and_up', 'arms_overhead_and_wave', 'sit_down_and_stand_up')
MOTIONS = CMU_CLIPS + ('cmu_131_01',) + AMP_MOTIONS + ACTIONS
TUNING_MOTIONS = ('07_01', '07_02', 'amp_run', 'turn_on_the_spot', 'arms_overhead_and_wave', 'sit_down_and_stand_up')
HELD_OUT_MOTIONS = ('08_08', 'cmu_131_01', 'amp_hop', 'walk_backwards', 'bend_down_and_up')
STRESS_MOTIONS = ('amp_cartwheel', 'amp_backflip')
BACKFLIP_PAUSE = 0.6  # [s] standing before, between and after the two backflips

DESCRIPTIONS = {
    '07_01': 'walking, 1.7 m/s, one stride played three times (4.8 s) - CMU 07_01 (subject 7), MotionBuilder BVH',
    '07_02': 'walking, 1.6 m/s, one stride played three times (4.9 s) - CMU 07_02 (subject 7), MotionBuilder BVH',
    '08_08': 'fast walking, 2.2 m/s, one stride played three times (4.2 s) - CMU 08_08 (subject 8), MotionBuilder BVH',
    'cmu_131_01': 'a stylised performance (8.2 s): standing, a high knee kick, pointing, down on one knee in a bow, '
                  'up, 3 m of high-kicking steps, stopping with the right arm raised - CMU 131_01, 3dsMax BVH (bvh11)',
    'amp_run': 'running, 3.8 m/s at 1.75 m, one stride played five times (4.4 s) - '
               'IsaacGymEnvs amp_humanoid_run (CMU), BSD-3',
    'amp_hop': 'hopping forward on both feet, 0.55 m/s (4.9 s) - IsaacGymEnvs amp_humanoid_hop (CMU), BSD-3',
    'amp_cartwheel': 'cartwheels, 1.05 m/s, the head down to 0.6 m (4.8 s; stress case) - '
                     'IsaacGymEnvs amp_humanoid_cartwheel (CMU), BSD-3',
    'amp_backflip': 'two standing backflips, 0.6 s standing before, between and after (5.4 s; stress case) - '
                    'IsaacGymEnvs amp_humanoid_backflip (CMU), BSD-3',
    'turn_on_the_spot': 'a full turn to the left on the spot in nine small steps (6.1 s) - scripted (studio.actions)',
    'walk_backwards': 'walking backwards, seven steps of 0.36 m at 0.6 m/s (6.0 s) - scripted (studio.actions)',
    'bend_down_and_up': 'bending down and up: a stoop, then a squatting reach to the floor (7.1 s) - '
                        'scripted (studio.actions)',
    'arms_overhead_and_wave': 'both arms overhead swaying side to side, then waving hello with the right hand '
                              '(7.8 s) - scripted (studio.actions)',
    'sit_down_and_stand_up': 'sitting down onto an invisible seat at knee height and standing up (5.2 s) - '
                             'scripted (studio.actions)',
}


def _known(name):
    if name not in MOTIONS:
        raise MotionFileError(f'no motion {name!r} (motions: {", ".join(MOTIONS)})')


def describe(name):
    """One line: what motion `name` is and where it comes from; MotionFileError for an unknown name."""
    _known(name)
    return DESCRIPTIONS[name]


def bvh_cycle(bvh, shortest=0.8):
    """(start, stop): the rows of motion (after a T-pose) at least `shortest` [s] apart whose poses
    relative to the root are most alike (the largest distance of any point), for looping a periodic
    motion such as walking: rows start..stop − 1 are one cycle. A CMU walk's best cycle is a stride
    (07_01: 1.09 s, its points within 2.3 cm at the seam)."""
    first = 1 if mocap.has_tpose(bvh) else 0
    positions = bvh.global_positions(np.arange(first, bvh.frame_count))
    pose = positions - positions[:, :1]
    gap = int(np.ceil(shortest / bvh.frame_time))
    best, pair = np.inf, None
    for start in range(len(pose) - gap):
        mismatch = np.linalg.norm(pose[start + gap:] - pose[start], axis=-1).max(axis=1)
        if mismatch.min() < best:
            best, pair = mismatch.min(), (first + start, first + start + gap + int(np.argmin(mismatch)))
    if pair is None:
        raise MotionFileError(f'{bvh.path}: shorter than one cycle of {shortest} s')
    return pair


def looped_bvh(bvh, start, stop, count):
    """The BVH with rows start..stop − 1 (a cycle, see bvh_cycle) played `count` times: the rows before
    it, the cycles each carried on by the root's displacement over the cycle (its position channels, so a
    sloping capture floor keeps sloping), then the rows from `stop` on."""
    root_columns = [column for column, channel in enumerate(bvh.channels[0]) if channel.endswith('position')]
    travel = np.zeros(bvh.motion.shape[1])
    travel[root_columns] = bvh.motion[stop, root_columns] - bvh.motion[start, root_columns]
    rows = [bvh.motion[:start]] + [bvh.motion[start:stop] + repeat * travel for repeat in range(count)]
    rows.append(bvh.motion[stop:] + (count - 1) * travel)
    return dataclasses.replace(bvh, motion=np.concatenate(rows))


def _long_enough_bvh(bvh):
    """The BVH with its best cycle (bvh_cycle) played as often as it takes to last MINIMUM_DURATION."""
    motion_rows = bvh.frame_count - (1 if mocap.has_tpose(bvh) else 0)
    missing = MINIMUM_DURATION - (motion_rows - 1) * bvh.frame_time
    if missing <= 0:
        return bvh
    start, stop = bvh_cycle(bvh)
    return looped_bvh(bvh, start, stop, _plays(missing, (stop - start) * bvh.frame_time))


def _plays(missing, cycle):
    """How often a cycle of `cycle` [s] is played for a motion `missing` [s] short of MINIMUM_DURATION."""
    return 1 + math.ceil(missing / cycle)


def motion_length(name):
    """Frames of motion `name` at the studio's frame rate: the same for every height (the motions are
    resampled by time), so it is read off the default height's motion, which is cached."""
    return len(load_motion(name).joints)


@functools.lru_cache(maxsize=None)
def load_motion(name, height=1.75, frame_rate=FRAME_RATE):
    """The whole motion `name` (one of MOTIONS) of a person `height` [m] tall at frame_rate [Hz], first
    frame 0, its arrays read-only (it is cached); the CMU clips without their T-pose frame. MotionFileError
    for an unknown name, naming the known ones."""
    _known(name)
    if name in CMU_CLIPS or name == 'cmu_131_01':
        path = mocap.cmu_clip(name) if name in CMU_CLIPS else amp.motions_directory() / f'{name}.bvh'
        motion = mocap.retarget(_long_enough_bvh(mocap.load_bvh(path)), height=height, frame_rate=frame_rate)
    elif name == 'amp_backflip':
        motion = amp.body_motion(amp.repeated(amp.amp_clip(name), 2, BACKFLIP_PAUSE), height, frame_rate)
    elif name in AMP_MOTIONS:
        clip = amp.amp_clip(name)
        missing = MINIMUM_DURATION - clip.duration
        if missing > 0:
            start, stop = amp.best_cycle(clip)
            clip = amp.looped(clip, start, stop, _plays(missing, (stop - start) * clip.frame_time))
        motion = amp.body_motion(clip, height, frame_rate)
    else:
        motion = getattr(actions, name)(height=height, frame_rate=frame_rate)
    return motion.read_only()   # cached: shared by every caller
