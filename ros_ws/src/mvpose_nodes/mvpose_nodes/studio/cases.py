"""Randomised studio cases for the evaluation suite (`eval suite`): a motion window, a person, a camera
rig and the imaging, all drawn from one seeded NumPy Generator.

A case is drawn over (every range uniform unless said otherwise):
- the motion: one of the names given, a window of `frames` frames starting at a random index (the
  first frame, index 0, a quarter of the time: the clips that start standing start so), heading
  uniform in [0, 2π), the motion's mean pelvis within CENTRE_RADIUS of the middle (uniform on the disc);
- the person: height PERSON_HEIGHT, girth GIRTH, long or short sleeves (even odds), and uniformly a
  skin tone, hair colour, hair length, shirt and trousers colour of scene's tables (all pass the
  chroma key as person, tests/test_cases.py checks it);
- the rig (body.camera.ring_rig): ring diameter RING_DIAMETER, camera height CAMERA_HEIGHT (one for the
  rig), each camera aimed at its own point AIM_HEIGHT above the floor within AIM_RADIUS of the middle,
  focal length FOCAL_SCALE × the room's lens (RIG_FOCAL × diameter / 8 m: what the studio's lens is to
  its 8 m ring) for the rig, principal point within ±PRINCIPAL_OFFSET px of the image centre per camera
  and axis; any 3 distinct cameras of the 8, or all 8 with probability `all_cameras_share`;
- the imaging: rig exposure EXPOSURE times a per-camera spread EXPOSURE_VARIATION, a rig colour cast
  white balance (1 + c, 1, 1 − c) with c in ±COLOUR_CAST times a per-camera, per-channel spread
  WHITE_BALANCE_VARIATION, sensor noise NOISE, optical blur BLUR, JPEG quality JPEG_QUALITY, floor
  shadows with probability SHADOWS_SHARE, and per camera a stamp offset within ±JITTER.

Why the aim height and the focal length are not the studio's (0.7 m, 1400 px at every diameter): every
camera must see the whole of a 1.95 m person standing anywhere within 0.5 m of the middle (all 15
joints inside the image). With the studio's fixed 1400 px lens, a 6 m ring would need the focal length
below 0.70 × 1400 px (its cameras stand 2.5 m from such a person), so the lens scales with the ring
instead, as a studio fits its lenses to its room. And aimed at 0.7 m, the head leaves the top of the
image already at 0.93–1.05 × the room's lens (with the aim 0.5 m off the middle and the principal
point 20 px off); aimed at 1.0 m, the middle of the tallest person, the worst case allows 1.21 ×, so
the ±15 % asked for holds with no tightening. The studio's rig itself (studio_rig) is unchanged.
A motion that travels further leaves the views (a run crosses a 6–10 m ring in two seconds, past the
cameras); the suite shortens such a window until every frame shows the whole person to at least
MIN_FULL_VIEWS of the case's cameras (full_views; app/suite/__init__.py, in_view).

Draws happen in a fixed order, every value is always drawn (even when `cameras` is given or the motion
is shorter than the window), so a Generator seeded alike gives the same case: the suite seeds one per
case with [seed, index] (case_rng). Pure NumPy; the motion catalogue is read only for motion names
given without their lengths.
"""
import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from mvpose_nodes.body.camera import RIG_CAMERAS, RIG_FOCAL, RIG_RADIUS, RIG_RESOLUTION, ring_rig
from mvpose_nodes.studio import palette, scene

CENTRE_RADIUS = 0.5          # [m] the motion's mean pelvis from the middle of the studio, at most
FIRST_FRAME_SHARE = 0.25     # the share of cases whose window starts at the motion's first frame
PERSON_HEIGHT = (1.5, 1.95)  # [m]
GIRTH = (0.85, 1.25)         # scene.Appearance.girth: limb and torso thickness scale
LONG_SLEEVES_SHARE = 0.5
RING_DIAMETER = (6.0, 10.0)  # [m] (the studio's wall is 10 m across: a 10 m ring stands at it)
CAMERA_HEIGHT = (1.6, 2.6)   # [m]
AIM_RADIUS = 0.5             # [m] each camera's aim point from the middle, horizontally, at most
AIM_HEIGHT = 1.0             # [m] the aim points' height: the middle of the tallest person
FOCAL_SCALE = (0.85, 1.15)   # × RIG_FOCAL × diameter / (2 RIG_RADIUS): the room's lens, ±15 %
PRINCIPAL_OFFSET = 20.0      # [px at 1920 px wide, scaled with the width] ± per camera and axis
ALL_CAMERAS_SHARE = 0.2      # the default share of cases with all 8 cameras (else 3)
CASE_CAMERAS = 3
EXPOSURE = (0.75, 1.25)      # scene.Realism.exposure: the rig's gain
EXPOSURE_VARIATION = (0.0, 0.12)       # scene.Realism.exposure_variation: per-camera gain spread
COLOUR_CAST = 0.03           # ± c: the rig's white balance (1 + c, 1, 1 − c): warm > 0, cool < 0
WHITE_BALANCE_VARIATION = (0.0, 0.05)  # scene.Realism.white_balance_variation: per camera and channel
NOISE = (0.5, 5.0)           # [DN] scene.Realism.noise
BLUR = (0.3, 1.5)            # [px] scene.Realism.blur, in the case's images
JPEG_QUALITY = (60, 95)      # inclusive
SHADOWS_SHARE = 0.75
JITTER = 0.003               # [s] ± per camera: its stamp's offset from the frame's instant
MIN_FULL_VIEWS = 2           # cameras that see the whole person in every frame of a window: a 3D fit needs two


@dataclass(frozen=True, eq=False)
class Case:
    """One drawn case (see the module's docstring for the ranges). Compare cases with `same_case`.

    index: the case's number in its run; seed: the seed of its rendering's own random choices (per-camera
    gains, sensor noise: pass it to Realism.finish); motion: the motion's name; start: the window's
    first index into the motion (0 = its first frame); frames: the window's length (the motion's, when
    shorter than asked; the suite shortens it to keep the person in view); heading [rad] and centre
    (x, y) [m]: where the window is placed (BodyMotion.placed); height [m]: the person's; appearance:
    scene.Appearance; rig: all 8 cameras (body.camera.Camera, numbers 1..8); cameras: the numbers used
    (3 or 8, ascending); realism: scene.Realism; shadows: floor shadows on; jpeg_quality; jitter: per
    used camera (in `cameras` order) its stamp offset [s]; resolution: (width, height) [px]."""
    index: int
    seed: int
    motion: str
    start: int
    frames: int
    heading: float
    centre: tuple
    height: float
    appearance: scene.Appearance
    rig: tuple
    cameras: tuple
    realism: scene.Realism
    shadows: bool
    jpeg_quality: int
    jitter: tuple
    resolution: tuple


def full_views(case, joints):
    """(F,) int: per frame of `joints` (F, 15, 3) [m], how many of the case's cameras see the whole person:
    all 15 joints in front of the camera and inside its image."""
    width, height = case.resolution
    counts = np.zeros(len(joints), int)
    for camera in case.rig:
        if camera.number not in case.cameras:
            continue
        pixels, depths = camera.project(joints.reshape(-1, 3))
        pixels, depths = pixels.reshape(*joints.shape[:2], 2), depths.reshape(joints.shape[:2])
        inside = (depths > 0) & (pixels[..., 0] >= 0) & (pixels[..., 0] < width) \
            & (pixels[..., 1] >= 0) & (pixels[..., 1] < height)
        counts += inside.all(axis=1)
    return counts


def case_rng(seed, index):
    """The Generator case `index` of a run seeded `seed` is drawn from."""
    return np.random.default_rng([seed, index])


def draw_case(rng, index, motions, frames, resolution, cameras=None, all_cameras_share=ALL_CAMERAS_SHARE):
    """A Case drawn from `rng` (numpy Generator).

    motions: the motion names to choose from (uniformly), or {name: its length in frames} (or {name:
    BodyMotion}); names alone are looked up in studio.catalogue (motion_length).
    frames: the window's length; resolution: (width, height) [px]; cameras: the camera numbers to use
    instead of drawn ones (None: draw)."""
    names = list(motions)
    if not names:
        raise ValueError('draw_case needs at least one motion')
    width, image_height = resolution

    # The motion and the person's height.
    motion = names[int(rng.integers(len(names)))]
    height = float(rng.uniform(*PERSON_HEIGHT))
    length = _motion_length(motions, motion)
    first_frame = rng.random() < FIRST_FRAME_SHARE
    start_fraction = rng.random()
    count = min(int(frames), length)
    start = 0 if first_frame else int(start_fraction * (length - count + 1))
    heading = float(rng.uniform(0.0, 2 * math.pi))
    centre = tuple(float(v) for v in _in_disc(rng, CENTRE_RADIUS))

    # The person's looks.
    skin = _pick(rng, palette.SKIN_TONES)
    hair = _pick(rng, palette.HAIR_COLOURS)
    hair_length = palette.HAIR_LENGTHS[int(rng.integers(len(palette.HAIR_LENGTHS)))]
    shirt = _pick(rng, palette.SHIRTS)
    trousers = _pick(rng, palette.TROUSER_COLOURS)
    long_sleeves = bool(rng.random() < LONG_SLEEVES_SHARE)
    girth = float(rng.uniform(*GIRTH))
    appearance = scene.Appearance(skin=skin, hair=hair, shirt=shirt, trousers=trousers, long_sleeves=long_sleeves,
                                  girth=girth, hair_length=hair_length)

    # The rig.
    diameter = float(rng.uniform(*RING_DIAMETER))
    camera_height = float(rng.uniform(*CAMERA_HEIGHT))
    focal_scale = float(rng.uniform(*FOCAL_SCALE))
    aims = np.column_stack([[_in_disc(rng, AIM_RADIUS) for _ in range(RIG_CAMERAS)], np.full(RIG_CAMERAS, AIM_HEIGHT)])
    offsets = rng.uniform(-1, 1, (RIG_CAMERAS, 2)) * PRINCIPAL_OFFSET * width / RIG_RESOLUTION[0]
    rig = tuple(ring_rig(resolution, diameter, camera_height, aims, focal_scale * diameter / (2 * RIG_RADIUS),
                         offsets))
    all_cameras = rng.random() < all_cameras_share
    three = tuple(sorted(int(k) + 1 for k in rng.choice(RIG_CAMERAS, CASE_CAMERAS, replace=False)))
    if cameras is not None:
        used = tuple(sorted(int(k) for k in cameras))
        if not used or len(set(used)) != len(used) or not all(1 <= k <= RIG_CAMERAS for k in used):
            raise ValueError(f'cameras must be distinct numbers 1..{RIG_CAMERAS}, got {cameras}')
    else:
        used = tuple(range(1, RIG_CAMERAS + 1)) if all_cameras else three

    # The imaging.
    exposure = float(rng.uniform(*EXPOSURE))
    exposure_variation = float(rng.uniform(*EXPOSURE_VARIATION))
    cast = float(rng.uniform(-COLOUR_CAST, COLOUR_CAST))
    white_balance_variation = float(rng.uniform(*WHITE_BALANCE_VARIATION))
    noise = float(rng.uniform(*NOISE))
    blur = float(rng.uniform(*BLUR))
    jpeg_quality = int(rng.integers(JPEG_QUALITY[0], JPEG_QUALITY[1] + 1))
    shadows = bool(rng.random() < SHADOWS_SHARE)
    jitters = rng.uniform(-JITTER, JITTER, RIG_CAMERAS)  # per camera number, whichever are used
    seed = int(rng.integers(2 ** 31))
    realism = scene.Realism(exposure_variation=exposure_variation, white_balance_variation=white_balance_variation,
                            noise=noise, blur=blur, exposure=exposure, white_balance=(1.0 + cast, 1.0, 1.0 - cast))
    return Case(index=index, seed=seed, motion=motion, start=start, frames=count, heading=heading, centre=centre,
                height=height, appearance=appearance, rig=rig, cameras=used, realism=realism, shadows=shadows,
                jpeg_quality=jpeg_quality, jitter=tuple(float(jitters[k - 1]) for k in used),
                resolution=(int(width), int(image_height)))


def _motion_length(motions, name):
    """Frames of motion `name` (see draw_case's `motions`)."""
    if isinstance(motions, Mapping):
        value = motions[name]
        return len(value.joints) if hasattr(value, 'joints') else int(value)
    from mvpose_nodes.studio.catalogue import motion_length
    return motion_length(name)


def _pick(rng, table):
    """A value of the dict `table`, uniformly."""
    values = list(table.values())
    return values[int(rng.integers(len(values)))]


def _in_disc(rng, radius):
    """(x, y) uniform on the disc of `radius` about the origin."""
    r = radius * math.sqrt(rng.random())
    angle = rng.uniform(0.0, 2 * math.pi)
    return r * math.cos(angle), r * math.sin(angle)


def same_case(a, b):
    """Whether two cases are equal in every field (cameras compared by their arrays)."""
    def plain(case):
        return tuple((name, value) for name, value in vars(case).items() if name != 'rig')
    return plain(a) == plain(b) and len(a.rig) == len(b.rig) and all(
        x.number == y.number and x.width == y.width and x.height == y.height and
        all(np.array_equal(getattr(x, f), getattr(y, f)) for f in ('K', 'R', 't', 'D')) for x, y in zip(a.rig, b.rig))


def rig_values(case):
    """What the case's rig was drawn as, read back off its cameras: {'diameter' [m], 'height' [m],
    'focal_scale' (× the room's lens), 'aims' (8, 3) [m] (where each optical axis meets the plane
    z = AIM_HEIGHT), 'principal_offsets' (8, 2) [px]}."""
    width, image_height = case.resolution
    centres = np.array([camera.center for camera in case.rig])
    diameter = 2 * float(np.mean(np.linalg.norm(centres[:, :2], axis=1)))
    room_focal = RIG_FOCAL * width / RIG_RESOLUTION[0] * diameter / (2 * RIG_RADIUS)
    aims = []
    for camera, centre in zip(case.rig, centres):
        axis = camera.R[2]
        aims.append(centre + (AIM_HEIGHT - centre[2]) / axis[2] * axis)
    offsets = np.array([camera.K[:2, 2] - [(width - 1) / 2, (image_height - 1) / 2] for camera in case.rig])
    return {'diameter': diameter, 'height': float(np.mean(centres[:, 2])),
            'focal_scale': float(np.mean([camera.K[0, 0] for camera in case.rig]) / room_focal),
            'aims': np.array(aims), 'principal_offsets': offsets}


def _name(colour, table):
    return next((name for name, value in table.items() if tuple(value) == tuple(colour)), 'custom')


def describe_case(case):
    """Short strings for a table row: {'motion', 'rig', 'body', 'imaging'}."""
    rig = rig_values(case)
    cameras = 'all 8' if len(case.cameras) == RIG_CAMERAS else ' '.join(str(k) for k in case.cameras)
    looks = case.appearance
    realism = case.realism
    cast = realism.white_balance[0] - 1.0
    jitter = max(abs(j) for j in case.jitter) if case.jitter else 0.0
    return {
        'motion': f'{case.motion} {case.start}–{case.start + case.frames - 1} heading {math.degrees(case.heading):.0f}°',
        'rig': f'Ø{rig["diameter"]:.1f} m h{rig["height"]:.1f} f{100 * (rig["focal_scale"] - 1):+.0f}% cams {cameras}',
        'body': f'{case.height:.2f} m girth {looks.girth:.2f} {_name(looks.shirt, palette.SHIRTS)} '
                f'{"long" if looks.long_sleeves else "short"} sleeves, {_name(looks.trousers, palette.TROUSER_COLOURS)} '
                f'trousers, {_name(looks.hair, palette.HAIR_COLOURS)} hair {looks.hair_length}, '
                f'skin {_name(looks.skin, palette.SKIN_TONES)}',
        'imaging': f'exp {realism.exposure:.2f} wb {round(100 * cast):+d}% jpeg {case.jpeg_quality} blur {realism.blur:.1f} '
                   f'noise {realism.noise:.1f} jitter ±{1000 * jitter:.1f} ms{"" if case.shadows else " no shadows"}',
    }
