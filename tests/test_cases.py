"""The randomised studio cases of `eval suite` (studio/cases.py), the rig they are drawn on
(body/camera.ring_rig) and the person's variety (studio/scene.py): reproducible, inside their ranges,
every camera sees the person, every colour is the person's to the chroma key."""
import itertools
import math
from dataclasses import replace

import numpy as np
import pytest

from mvpose_nodes.body.camera import RIG_CAMERAS, RIG_FOCAL, RIG_HEIGHT, RIG_RADIUS, RIG_TARGET, ring_rig, studio_rig
from mvpose_nodes.body.model import JOINT_INDEX
from mvpose_nodes.studio import cases, palette, scene
from mvpose_nodes.studio.scripted_motion import occlusion_motion
from mvpose_nodes.vision.silhouette import BLUENESS_THRESHOLD

pytestmark = pytest.mark.pure

MOTIONS = {'walk': 300, 'spin': 120, 'short': 30}
FRAMES = 50
DRAWS = 200


def draw_cases(seed, count, motions, frames, resolution):
    """Cases 0..count−1 of a run seeded `seed`, each from its own case_rng(seed, k), as the suite draws them."""
    return [cases.draw_case(cases.case_rng(seed, index), index, motions, frames, resolution) for index in range(count)]


@pytest.fixture(scope='module')
def drawn():
    return draw_cases(11, DRAWS, MOTIONS, FRAMES, (1920, 1080))


def test_same_seed_gives_the_same_cases_and_other_seeds_do_not():
    first = draw_cases(5, 6, MOTIONS, FRAMES, (960, 540))
    again = draw_cases(5, 6, MOTIONS, FRAMES, (960, 540))
    assert all(cases.same_case(a, b) for a, b in zip(first, again))
    # A case depends on (seed, index) only, not on how many are drawn.
    assert cases.same_case(first[4], cases.draw_case(cases.case_rng(5, 4), 4, MOTIONS, FRAMES, (960, 540)))
    other = draw_cases(6, 6, MOTIONS, FRAMES, (960, 540))
    assert not any(cases.same_case(a, b) for a, b in zip(first, other))
    assert all(cases.describe_case(a) != cases.describe_case(b) for a, b in zip(first, other))
    # Cameras given: everything else is drawn as before.
    given = cases.draw_case(cases.case_rng(5, 2), 2, MOTIONS, FRAMES, (960, 540), cameras=(7, 3, 5))
    assert given.cameras == (3, 5, 7)
    assert cases.same_case(replace(given, cameras=first[2].cameras, jitter=first[2].jitter), first[2])


def test_drawn_values_are_inside_their_ranges(drawn):
    starts_at_zero = longer = all_eight = 0
    for index, case in enumerate(drawn):
        assert case.index == index and case.resolution == (1920, 1080)
        length = MOTIONS[case.motion]
        assert case.frames == min(FRAMES, length)
        assert 0 <= case.start <= length - case.frames
        if length > FRAMES:  # shorter motions are taken whole, from their first frame
            longer += 1
            starts_at_zero += case.start == 0
        assert 0 <= case.heading < 2 * math.pi
        assert math.hypot(*case.centre) <= cases.CENTRE_RADIUS
        assert cases.PERSON_HEIGHT[0] <= case.height <= cases.PERSON_HEIGHT[1]
        looks = case.appearance
        assert cases.GIRTH[0] <= looks.girth <= cases.GIRTH[1]
        assert looks.skin in palette.SKIN_TONES.values() and looks.hair in palette.HAIR_COLOURS.values()
        assert looks.shirt in palette.SHIRTS.values() and looks.trousers in palette.TROUSER_COLOURS.values()
        assert looks.hair_length in palette.HAIR_LENGTHS and not looks.markers
        rig = cases.rig_values(case)
        assert [camera.number for camera in case.rig] == list(range(1, RIG_CAMERAS + 1))
        assert cases.RING_DIAMETER[0] <= rig['diameter'] <= cases.RING_DIAMETER[1]
        assert cases.CAMERA_HEIGHT[0] <= rig['height'] <= cases.CAMERA_HEIGHT[1]
        assert cases.FOCAL_SCALE[0] - 1e-9 <= rig['focal_scale'] <= cases.FOCAL_SCALE[1] + 1e-9
        assert np.all(np.linalg.norm(rig['aims'][:, :2], axis=1) <= cases.AIM_RADIUS + 1e-9)
        np.testing.assert_allclose(rig['aims'][:, 2], cases.AIM_HEIGHT)
        assert np.all(np.abs(rig['principal_offsets']) <= cases.PRINCIPAL_OFFSET + 1e-9)
        assert len(set(case.cameras)) == len(case.cameras) in (3, 8) and list(case.cameras) == sorted(case.cameras)
        assert all(1 <= k <= RIG_CAMERAS for k in case.cameras)
        all_eight += len(case.cameras) == 8
        assert len(case.jitter) == len(case.cameras) and all(abs(j) <= cases.JITTER for j in case.jitter)
        realism = case.realism
        assert cases.EXPOSURE[0] <= realism.exposure <= cases.EXPOSURE[1]
        assert cases.EXPOSURE_VARIATION[0] <= realism.exposure_variation <= cases.EXPOSURE_VARIATION[1]
        cast = realism.white_balance[0] - 1
        assert abs(cast) <= cases.COLOUR_CAST and realism.white_balance == pytest.approx((1 + cast, 1.0, 1 - cast))
        assert cases.WHITE_BALANCE_VARIATION[0] <= realism.white_balance_variation <= cases.WHITE_BALANCE_VARIATION[1]
        assert cases.NOISE[0] <= realism.noise <= cases.NOISE[1] and cases.BLUR[0] <= realism.blur <= cases.BLUR[1]
        assert cases.JPEG_QUALITY[0] <= case.jpeg_quality <= cases.JPEG_QUALITY[1]
        assert isinstance(case.jpeg_quality, int) and isinstance(case.shadows, bool)
        assert set(cases.describe_case(case)) == {'motion', 'rig', 'body', 'imaging'}
    # The shares: a quarter (plus chance) start at the first frame, a fifth use all 8 cameras.
    assert 0.15 <= starts_at_zero / longer <= 0.4
    assert 0.1 <= all_eight / DRAWS <= 0.3
    # Every camera is drawn, and varied looks.
    assert set(itertools.chain(*(case.cameras for case in drawn))) == set(range(1, 9))
    assert len({case.appearance.shirt for case in drawn}) == len(palette.SHIRTS)
    assert len({case.appearance.hair_length for case in drawn}) == len(palette.HAIR_LENGTHS)


def test_describe_case_reads_like_a_table_row():
    case = cases.draw_case(cases.case_rng(1, 0), 0, MOTIONS, FRAMES, (960, 540), cameras=(2, 4, 7))
    described = cases.describe_case(case)
    assert described['rig'].startswith('Ø') and described['rig'].endswith('cams 2 4 7')
    assert described['body'].startswith(f'{case.height:.2f} m girth ')
    assert 'custom' not in described['body']
    assert described['imaging'].startswith('exp ') and f'jpeg {case.jpeg_quality}' in described['imaging']
    assert described['motion'].startswith(f'{case.motion} {case.start}–')


@pytest.mark.parametrize('resolution', [(1920, 1080), (480, 270), (641, 361)])
def test_ring_rig_with_the_studio_values_is_the_studio_rig(resolution):
    for rig, studio in ((ring_rig(resolution, 2 * RIG_RADIUS, RIG_HEIGHT, RIG_TARGET, 1.0, (0.0, 0.0)),
                         studio_rig(resolution)),
                        (ring_rig(resolution, 8.0, [2.0] * 8, [RIG_TARGET] * 8, [1.0] * 8, np.zeros((8, 2)),
                                  cameras=[3, 5, 7]), studio_rig(resolution, cameras=[3, 5, 7]))):
        assert [c.number for c in rig] == [c.number for c in studio]
        for a, b in zip(rig, studio):
            assert (a.width, a.height) == (b.width, b.height)
            for name in ('K', 'R', 't', 'D'):
                assert np.array_equal(getattr(a, name), getattr(b, name)), name


def test_ring_rig_places_and_aims_each_camera():
    aims = np.array([[0.1 * k, -0.05 * k, 1.0] for k in range(8)])
    offsets = np.array([[k, -k] for k in range(8)], float)
    rig = ring_rig((960, 540), 7.0, 2.4, aims, 0.9, offsets)
    for camera in rig:
        k = camera.number - 1
        angle = 2 * math.pi * k / 8
        np.testing.assert_allclose(camera.center, [3.5 * math.cos(angle), 3.5 * math.sin(angle), 2.4], atol=1e-12)
        pixel, _ = camera.project(aims[k][None])
        np.testing.assert_allclose(pixel[0], camera.K[:2, 2], atol=1e-9)  # the aim is on the optical axis
        np.testing.assert_allclose(camera.K[:2, 2], [479.5 + k, 269.5 - k])
        assert camera.K[0, 0] == camera.K[1, 1] == pytest.approx(0.9 * RIG_FOCAL / 2)
    with pytest.raises(ValueError):
        ring_rig((960, 540), focal_scale=[1.0, 1.1])


def standing_people(height, radius):
    """(N, 15, 3) joints of a person of `height` standing (arms down) facing 4 ways, at the middle and
    at 16 points `radius` from it."""
    joints = occlusion_motion(height=height).joints[0]
    joints = joints - [*joints[JOINT_INDEX['pelvis'], :2], 0.0]
    people = []
    for heading in np.radians([0, 45, 90, 135]):
        turn = np.array([[math.cos(heading), -math.sin(heading), 0], [math.sin(heading), math.cos(heading), 0],
                         [0, 0, 1]])
        for angle in [None, *np.radians(np.arange(0, 360, 22.5))]:
            shift = [0, 0, 0] if angle is None else [radius * math.cos(angle), radius * math.sin(angle), 0]
            people.append(joints @ turn.T + shift)
    return np.array(people)


@pytest.mark.parametrize('resolution', [(1920, 1080), (960, 540)])
def test_every_camera_of_a_drawn_rig_sees_a_tall_person_standing_near_the_middle(drawn, resolution):
    people = standing_people(cases.PERSON_HEIGHT[1], cases.CENTRE_RADIUS).reshape(-1, 3)
    width, height = resolution
    rigs = drawn if resolution == (1920, 1080) else draw_cases(12, DRAWS, MOTIONS, FRAMES, resolution)
    for case in rigs:
        for camera in case.rig:
            pixels, depth = camera.project(people)
            assert np.all(depth > 0)
            assert pixels[:, 0].min() >= -0.5 and pixels[:, 0].max() <= width - 0.5, (case.index, camera.number)
            assert pixels[:, 1].min() >= -0.5 and pixels[:, 1].max() <= height - 0.5, (case.index, camera.number)


def test_full_views_counts_the_cameras_that_see_every_joint(drawn):
    """A tall person standing in the middle of a 6 m ring is seen whole by its cameras 1, 3 and 5 (ring_rig:
    camera k at angle (k − 1)·45°, camera 1 on +x); 2 m towards camera 1, too near it to be seen whole by it;
    2.5 m, out of camera 3's side of the image too; 1.2 m past camera 1, behind it: camera 5 alone."""
    ring = cases.draw_case(cases.case_rng(3, 0), 0, MOTIONS, FRAMES, (1920, 1080), cameras=(1, 3, 5))
    ring = replace(ring, rig=tuple(ring_rig((1920, 1080), diameter=6.0, height=2.0, aim=(0.0, 0.0, 1.0),
                                             focal_scale=6.0 / (2 * RIG_RADIUS))))
    standing = standing_people(cases.PERSON_HEIGHT[1], 0.0)[0]
    walked = np.array([standing + [x, 0.0, 0.0] for x in (0.0, 2.0, 2.5, 4.2)])
    assert cases.full_views(ring, walked).tolist() == [3, 2, 1, 1]
    assert cases.full_views(drawn[0], standing[None]).tolist() == [len(drawn[0].cameras)]


def blueness(rgb):
    """b − max(r, g) of 8-bit RGB pixels (…, 3), as int."""
    rgb = rgb.astype(int)
    return rgb[..., 2] - np.maximum(rgb[..., 0], rgb[..., 1])


def shaded_strip(colours):
    """A Rendering of each colour (rows) under every light the studio gives a surface (columns: from
    the ambient light alone to the full light), and a view without distortion to finish it with."""
    shading = np.linspace(scene.AMBIENT, 1.0, 14, dtype=np.float32)
    rgb = (np.asarray(colours, np.float32)[:, None, :] * shading[None, :, None]).astype(np.float32)
    labels = np.zeros(rgb.shape[:2], np.uint8)
    return scene.Rendering(rgb, labels), scene.CameraRays(None, None, None, None)


PERSON_COLOURS = {**{f'skin {k}': v for k, v in palette.SKIN_TONES.items()},
                  **{f'hair {k}': v for k, v in palette.HAIR_COLOURS.items()},
                  **{f'shirt {k}': v for k, v in palette.SHIRTS.items()},
                  **{f'trousers {k}': v for k, v in palette.TROUSER_COLOURS.items()},
                  'shoes': scene.Appearance().shoes}


def test_every_colour_is_the_person_at_the_extremes_of_exposure_and_white_balance():
    rendering, view = shaded_strip(list(PERSON_COLOURS.values()))
    variation, cast = cases.WHITE_BALANCE_VARIATION[1], cases.COLOUR_CAST
    worst = np.full(len(PERSON_COLOURS), -255)
    for exposure in np.linspace(cases.EXPOSURE[0] * (1 - cases.EXPOSURE_VARIATION[1]),
                                cases.EXPOSURE[1] * (1 + cases.EXPOSURE_VARIATION[1]), 9):
        for c, signs in itertools.product((-cast, cast), itertools.product((-1, 1), repeat=3)):
            balance = np.array([1 + c, 1.0, 1 - c]) * (1 + variation * np.array(signs))
            realism = scene.Realism(0, 0, 0, 0, exposure=float(exposure), white_balance=tuple(balance))
            rgb, _ = realism.finish(rendering, view, 1, 0, 0)
            worst = np.maximum(worst, blueness(rgb).max(axis=1))
    bad = {name: int(b) for name, b in zip(PERSON_COLOURS, worst) if b >= BLUENESS_THRESHOLD - 5}
    assert not bad, f'keyed out (b − max(r, g) in 8-bit, the key takes > {BLUENESS_THRESHOLD}): {bad}'


def test_every_drawn_colour_is_the_person_in_every_camera_of_its_case(drawn):
    for case in drawn:
        looks = case.appearance
        rendering, view = shaded_strip([looks.skin, looks.hair, looks.shirt, looks.trousers, looks.shoes])
        for number in case.cameras:
            realism = replace(case.realism, noise=0, blur=0)
            rgb, _ = realism.finish(rendering, view, number, case.seed, 0)
            assert blueness(rgb).max() < BLUENESS_THRESHOLD - 5, (case.index, number, cases.describe_case(case))


def test_the_empty_studio_stays_blue_screen_in_the_darkest_warmest_case():
    for case in draw_cases(2, 4, MOTIONS, FRAMES, (192, 108)):
        for camera in case.rig:
            view = scene.prepare_camera(camera, texture_seed=camera.number)
            shadowed = scene.Rendering(view.background * (1 - scene.SHADOW_STRENGTH), None)
            c = cases.COLOUR_CAST + cases.WHITE_BALANCE_VARIATION[1]
            realism = scene.Realism(0, 0, 0, 0, exposure=cases.EXPOSURE[0] * (1 - cases.EXPOSURE_VARIATION[1]),
                                    white_balance=(1 + c, 1 + cases.WHITE_BALANCE_VARIATION[1], 1 - c))
            rgb, _ = realism.finish(shadowed, view, camera.number, 0, 0)
            assert blueness(rgb).min() > BLUENESS_THRESHOLD, (case.index, camera.number)


def test_defaults_are_todays_look_and_long_hair_covers_the_back_of_the_head():
    assert scene.Appearance().hair_length == 'short'
    assert scene.Appearance().hair == palette.HAIR_COLOURS['dark'] == (0.06, 0.04, 0.03)
    assert scene.Appearance().trousers == palette.TROUSER_COLOURS['dark'] == (0.08, 0.08, 0.09)
    gain, balance = scene.Realism().camera_response(3, 7)
    rng = np.random.default_rng([7, 3, 1])
    assert gain == 1.0 + 0.08 * rng.uniform(-1, 1)
    assert np.array_equal(balance, (1.0 + 0.04 * rng.uniform(-1, 1, 3)).astype(np.float32))
    with pytest.raises(ValueError):
        scene.Appearance(hair_length='waist')

    motion = occlusion_motion()  # standing, facing camera 5 (world −x): camera 1 sees the back
    pose = scene.BodyPose(motion.joints[0], motion.toes[0], motion.hand_tips[0], motion.head_forward[0])
    names = [solid.name for solid in scene.body_primitives(pose, scene.Appearance(hair_length='long'))]
    assert 'hair' in names and 'hair' not in [s.name for s in scene.body_primitives(pose, scene.Appearance())]

    def head_pixels(camera_number, hair_length):
        camera = ring_rig((320, 180), cameras=[camera_number])[0]
        labels = scene.render(scene.prepare_camera(camera), pose, scene.Appearance(hair_length=hair_length)).labels
        head = (labels & ~np.uint8(scene.SKIN_BIT)) == scene.LABEL_HEAD
        return int(head.sum()), int((head & (labels & scene.SKIN_BIT > 0)).sum())

    back = {length: head_pixels(1, length) for length in palette.HAIR_LENGTHS}
    front = {length: head_pixels(5, length) for length in palette.HAIR_LENGTHS}
    assert back['long'][1] < 0.5 * back['short'][1]   # the neck's skin hides behind the hair
    assert back['long'][0] > back['short'][0]          # and the head looks bigger from behind
    assert back['cropped'][1] > back['short'][1]       # cropped: more skin at the back of the head
    assert front['long'][1] > 0.6 * front['short'][1]  # the face still shows
