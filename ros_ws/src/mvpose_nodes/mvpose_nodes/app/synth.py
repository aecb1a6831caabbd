"""`synth`: an i3DPost-like multi-camera bag of a person walking (or standing) in a blue studio,
with exact ground truth; optionally also written in the i3DPost dataset layout.

--markers dresses the person in paper 001's marker suit: 4 cm red spheres on the body's surface at
the 15 joints (scene.marker_centres), clothes without red, and per camera the markers' ground truth
(/cam<K>/ground_truth/markers: true projections, visible where >= 25 % of a marker's disc is seen).
--motion occlusions is a scripted sequence of the paper's occlusion cases (scripted_motion).

The motion is real motion capture (CMU clips, retargeted to the 15-joint model at 25 fps); the
person and studio are ray cast by `studio`; every random choice comes from --seed, so a seed
gives the same bag. Topics and stamps follow camera_bag.
"""
import math
import multiprocessing
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from mvpose_nodes.body.camera import studio_rig
from mvpose_nodes.tools.cli import ArgumentParser, UserError, end_with_parent, exit_on_user_error

WALK_HEADING = math.radians(45)  # walk from camera 6's side towards camera 2: cameras 3, 5, 7 see all of it
CLIP_CENTRE_FRAME = 76  # the middle of the paper's frames 52–101: the walk clip is centred there
DEFAULT_FRAMES = '52-101'
SYNTH_ACTOR, SYNTH_SEQUENCE = 'synth', 'walk'


def build_parser(prog):
    parser = ArgumentParser(prog=prog, description=__doc__.split('\n\n')[0].replace('\n', ' '))
    parser.add_argument('-o', '--output', type=Path, default=Path('bags/i3dpost_walk_synth'),
                        help='bag directory to create (default bags/i3dpost_walk_synth)')
    parser.add_argument('--cameras', type=int, nargs='+', default=list(range(1, 9)), metavar='K',
                        help='i3DPost camera numbers 1..8 (default all 8; the paper uses 3 5 7)')
    parser.add_argument('--frames', help=f'frame range, e.g. 52-101 (default {DEFAULT_FRAMES}; with --motion '
                                          'occlusions the whole script, frames 0-247)')
    parser.add_argument('--resolution', default='1920x1080', help='WIDTHxHEIGHT (default 1920x1080)')
    parser.add_argument('--seed', type=int, default=0, help='seed of every random choice (default 0)')
    parser.add_argument('--motion', choices=['walk', 'stand', 'occlusions'], default='walk',
                        help='walk (default), stand still, or occlusions: a scripted sequence of marker occlusions '
                             '(a hand in front of the head, shrug with arms crossed, wrists past the hips, knees '
                             'crossing), standing in the middle facing camera 5')
    parser.add_argument('--clip', default='07_01', help='CMU clip of the motion: 07_01 (default), 07_02, 08_08')
    body = parser.add_argument_group('the person')
    body.add_argument('--height', type=float, default=1.75, help='[m] standing height (default 1.75)')
    body.add_argument('--girth', type=float, default=1.0, help='scale of limb and torso thickness (default 1)')
    body.add_argument('--long-sleeves', action='store_true', help='forearms covered: only hands and face are skin')
    body.add_argument('--skin-tone', choices=['light', 'medium', 'dark'], default='medium', help='(default medium)')
    body.add_argument('--shirt', choices=['red', 'green', 'grey', 'white', 'yellow'],
                      help='shirt colour (default red; green with --markers)')
    body.add_argument('--markers', action='store_true',
                      help="red 4 cm marker spheres on the 15 joints (paper 001), no red clothes, and the markers' "
                           'ground truth per camera on /cam<K>/ground_truth/markers')
    realism = parser.add_argument_group('realism (on by default; each can be turned off)')
    realism.add_argument('--no-soft-shading', action='store_true', help='flat colours instead of shaded solids')
    realism.add_argument('--no-shadow', action='store_true', help='no shadow on the floor')
    realism.add_argument('--exposure-variation', type=float, default=0.08, help='per-camera gain spread (default 0.08)')
    realism.add_argument('--white-balance-variation', type=float, default=0.04,
                         help='per-camera, per-channel gain spread (default 0.04)')
    realism.add_argument('--noise', type=float, default=2.0, help='[DN] sensor noise sigma (default 2; 0 = none)')
    realism.add_argument('--blur', type=float, default=0.6, help='[px] optical blur sigma (default 0.6)')
    realism.add_argument('--image-format', choices=['jpeg', 'png'], default='jpeg', help='compression (default jpeg)')
    realism.add_argument('--jpeg-quality', type=int, default=90, help='JPEG quality (default 90)')
    realism.add_argument('--distortion', type=float, default=0.0, metavar='K1',
                         help='radial lens distortion k1 of every camera (default 0: none)')
    realism.add_argument('--calibration-error', type=float, default=0.0, metavar='SCALE',
                         help='publish a wrong calibration: SCALE × (0.2° rotation, 5 mm position, 0.5 %% focal) '
                              'random errors (default 0: exact)')
    parser.add_argument('--i3dpost-layout', type=Path, metavar='DIR',
                        help='also write the frames and calibration in the i3DPost dataset layout under DIR')
    parser.add_argument('-j', '--jobs', type=int, default=os.cpu_count(), help='worker processes (default: all cores)')
    return parser


@dataclass
class SynthSettings:
    """Everything a worker needs to render one frame (sent once, by fork)."""
    views: list
    appearance: object
    realism: object
    seed: int
    soft_shading: bool
    shadow: bool
    image_format: str
    jpeg_quality: int
    layout_sequence: Path = None


_SETTINGS = None  # set in the parent before the worker pool forks


def render_frame(frame):
    """(frame number, [(camera number, image CDR, label mask CDR, MarkerTracks CDR or None)]) of one
    (frame number, BodyPose)."""
    from rclpy.serialization import serialize_message
    from mvpose_nodes.studio import scene
    from mvpose_nodes.ros.camera_bag import frame_stamp_ns
    from mvpose_nodes.ros.conversions import compressed_image, compressed_labels
    number, pose = frame
    settings = _SETTINGS
    shadow, center = scene.floor_shadow(pose, settings.appearance) if settings.shadow else (None, None)
    outputs = []
    for view in settings.views:
        markers = None
        if settings.appearance.markers:
            from mvpose_msgs.msg import MarkerTracks
            from std_msgs.msg import Header
            from mvpose_nodes.ros.conversions import marker_tracks, optical_frame, set_stamp
            pixels, _, visible = scene.marker_visibility(view.camera, pose, settings.appearance)
            header = Header()
            set_stamp(header, frame_stamp_ns(number), optical_frame(view.camera.number))
            # Ground truth: FLAG_DETECTED where the marker is visible, FLAG_PREDICTED where it is hidden.
            markers = serialize_message(marker_tracks(header, pixels, np.where(
                visible, MarkerTracks.FLAG_DETECTED, MarkerTracks.FLAG_PREDICTED)))
        rendering = scene.render(view, pose, settings.appearance, shadow, center, settings.soft_shading)
        rgb, labels = settings.realism.finish(rendering, view, view.camera.number, settings.seed, number)
        if settings.layout_sequence is not None:
            from mvpose_nodes.studio.i3dpost import write_frame
            write_frame(settings.layout_sequence, view.camera.number, number, rgb)
        stamp = frame_stamp_ns(number)
        image = compressed_image(rgb, view.camera.number, stamp, settings.image_format, settings.jpeg_quality)
        outputs.append((view.camera.number, serialize_message(image),
                        serialize_message(compressed_labels(labels, view.camera.number, stamp)), markers))
    return number, outputs


def make_motion(args):
    from mvpose_nodes.studio.i3dpost import FRAME_RATE
    from mvpose_nodes.studio.i3dpost import parse_frame_range
    from mvpose_nodes.studio.mocap import cmu_clip, load_bvh, retarget, standing_motion
    if args.motion == 'occlusions':
        from mvpose_nodes.studio.scripted_motion import occlusion_motion
        script = occlusion_motion(FRAME_RATE, height=args.height)
        if getattr(args, 'frames', None) is None:
            return script
        return script.select(*parse_frame_range(args.frames))
    first, last = parse_frame_range(args.frames or DEFAULT_FRAMES)
    bvh = load_bvh(cmu_clip(args.clip))
    if args.motion == 'stand':
        return standing_motion(bvh, last - first + 1, height=args.height, frame_rate=FRAME_RATE,
                               first_frame=first, seed=args.seed)
    clip = retarget(bvh, height=args.height, frame_rate=FRAME_RATE)
    clip = replace(clip, first_frame=CLIP_CENTRE_FRAME - len(clip.joints) // 2)
    return clip.select(first, last).placed(center=(0.0, 0.0), heading=WALK_HEADING)


def published_calibration(cameras, scale, seed):
    """The calibration the bag states: the true one, or with SCALE × realistic random errors."""
    from mvpose_nodes.body.geometry import normalize, rotation_about
    if not scale:
        return cameras
    rng = np.random.default_rng([seed, 99])
    wrong = []
    for camera in cameras:
        rotation = rotation_about(normalize(rng.normal(size=3)), math.radians(0.2 * scale) * rng.normal())
        shift = 0.005 * scale * rng.normal(size=3)
        K = camera.K.copy()
        K[0, 0] *= 1 + 0.005 * scale * rng.normal()
        K[1, 1] = K[0, 0]
        R = rotation @ camera.R
        wrong.append(replace(camera, K=K, R=R, t=-R @ (camera.center + shift)))
    return wrong


def parse_resolution(text):
    try:
        width, height = (int(v) for v in text.lower().split('x'))
    except ValueError:
        raise UserError(f"--resolution '{text}' is not WIDTHxHEIGHT, e.g. 1920x1080") from None
    if width < 64 or height < 64:
        raise UserError(f'--resolution {text} is too small (at least 64x64)')
    return width, height


def main(argv=None, prog='synth'):
    args = build_parser(prog).parse_args(sys.argv[1:] if argv is None else argv)
    with exit_on_user_error(prog):
        bad = [k for k in args.cameras if not 1 <= k <= 8]
        if bad or len(set(args.cameras)) != len(args.cameras):
            raise UserError(f'--cameras takes distinct i3DPost camera numbers 1..8 (got {args.cameras})')
        from mvpose_nodes.studio.palette import RED_SHIRTS
        if args.markers and args.shirt in RED_SHIRTS:
            raise UserError(f'--shirt {args.shirt} with --markers: the markers are red, choose another shirt')
        synthesize(args)
    return 0


def synthesize(args):
    global _SETTINGS
    import cv2
    from mvpose_nodes.studio import palette, scene
    from mvpose_nodes.ros.camera_bag import CameraBagWriter
    from mvpose_nodes.app.progress import Progress

    # The workers are forked from this process, so OpenCV must not start its thread pool here: a worker
    # forked while a pool thread held a mutex blocked for ever in cv2.imencode (seen once in CI, the
    # worker's stack read with py-spy). Each worker is one of --jobs processes anyway.
    cv2.setNumThreads(1)
    resolution = parse_resolution(args.resolution)
    motion = make_motion(args)
    rig = [camera.with_distortion([args.distortion, 0, 0, 0, 0]) for camera in studio_rig(resolution)]
    stated = published_calibration(rig, args.calibration_error, args.seed)
    selected = [camera for camera in rig if camera.number in args.cameras]
    layout_sequence = None
    if args.i3dpost_layout:
        from mvpose_nodes.studio.i3dpost import write_calibration
        layout_sequence = args.i3dpost_layout / SYNTH_ACTOR / SYNTH_SEQUENCE
        layout_sequence.mkdir(parents=True, exist_ok=True)
        write_calibration(args.i3dpost_layout / 'calibration.txt', stated)
    print(f'[synth] {len(motion.joints)} frames × {len(selected)} cameras at {resolution[0]}×{resolution[1]} '
          f'-> {args.output}', file=sys.stderr, flush=True)
    _SETTINGS = SynthSettings(
        views=[scene.prepare_camera(camera, texture_seed=camera.number) for camera in selected],
        appearance=scene.Appearance(skin=palette.SKIN_TONES[args.skin_tone],
                                     shirt=palette.SHIRTS[args.shirt or ('green' if args.markers else 'red')],
                                     long_sleeves=args.long_sleeves, girth=args.girth, markers=args.markers),
        realism=scene.Realism(args.exposure_variation, args.white_balance_variation, args.noise, args.blur),
        seed=args.seed, soft_shading=not args.no_soft_shading, shadow=not args.no_shadow,
        image_format=args.image_format, jpeg_quality=args.jpeg_quality, layout_sequence=layout_sequence)
    frames = [(number, scene.BodyPose(motion.joints[i], motion.toes[i], motion.hand_tips[i], motion.head_forward[i]))
              for i, number in enumerate(motion.frame_numbers)]
    appearance = _SETTINGS.appearance
    with CameraBagWriter(args.output, [c for c in stated if c.number in args.cameras], frames[0][0],
                         ground_truth=True, markers=appearance.markers) as bag:
        progress = Progress(len(frames), 'synth')
        with ProcessPoolExecutor(max_workers=max(1, args.jobs), mp_context=multiprocessing.get_context('fork'),
                                 initializer=end_with_parent) as pool:
            for (number, outputs), (_, pose) in zip(pool.map(render_frame, frames), frames):
                for camera_number, image, labels, markers in outputs:
                    bag.write_image(camera_number, number, image)
                    bag.write_image(camera_number, number, labels, kind='labels')
                    if markers is not None:
                        bag.write_markers(camera_number, number, markers)
                bag.write_ground_truth(number, pose.joints)
                if appearance.markers:
                    bag.write_marker_centres(number, scene.marker_centres(pose, appearance))
                progress.update()
        elapsed = progress.close()
    print(f'[synth] wrote {args.output} in {elapsed:.1f} s ({len(frames)} frames × {len(selected)} cameras)',
          file=sys.stderr)
