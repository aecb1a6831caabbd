"""Reading and writing the i3DPost multi-view database layout: frames and camera calibration.

Source: Gkalelis et al. 2009, "The i3DPost multi-view and 3D human action/interaction database"
(8 synchronised cameras on a ring, 1920×1080, 25 fps, blue studio). The database is licensed and
not available to this project; the published facts about its file format are thin, so the layout
below is ASSUMED. The project writes its synthetic studio in this layout and imports it back, so
the two sides always agree; a real copy that differs needs only this module changed.

ASSUMPTIONS about the layout:
  - Frames: `<root>/<actor>/…/<sequence>/<camera folder>/NNNNN.png`. Camera folders are named
    000..007; folder i holds i3DPost camera number i + 1. Frame files are named by the 5-digit
    frame number (00052.png = frame 52), 25 fps, 1920×1080 RGB PNG.
  - Calibration: one text file. Per camera, in camera-folder order, 21 numbers:
      xmin ymin xmax ymax   image bounds [px], the full image: 0 0 width−1 height−1
      fx fy cx cy           intrinsics [px], no skew
      k1                    radial distortion of normalised coordinates (plumb_bob k1; k2 = p1 = p2 = k3 = 0)
      R                     9 numbers, row by row
      t                     3 numbers, X_cam = R·X_world + t, metres (or millimetres, selectable)
    Only the order of the numeric tokens matters: line breaks are free, '#' starts a comment,
    blank lines are ignored, so a file with or without comment headers parses.

Conventions of the Camera returned (mvpose_nodes.body.camera): X_cam = R·X_world + t with t [m],
D = plumb_bob [k1, k2, p1, p2, k3]. Bad user input raises I3dpostError with a one-line message
naming the file (and line).
"""
import math
import os
import re
from pathlib import Path

import cv2
import numpy as np

from mvpose_nodes.body.camera import Camera


class I3dpostError(ValueError):
    """i3DPost data (calibration, frames, folders, frame ranges) that is missing or malformed; the message names the file."""


CAMERAS = 8
FRAME_RATE = 25.0   # [Hz] of i3DPost's cameras, and of every bag and motion the project makes
NUMBERS_PER_CAMERA = 21  # 4 bounds + 4 intrinsics + k1 + 9 R + 3 t
UNITS_PER_METRE = {'m': 1.0, 'mm': 1000.0}
ROTATION_TOLERANCE = 1e-6  # max |RᵀR − I| element accepted as a rotation
CAMERA_FOLDER = re.compile(r'^00[0-7]$')
FRAME_FILE = re.compile(r'^(\d{5})\.png$')
PNG_FAST = [cv2.IMWRITE_PNG_COMPRESSION, 1]  # frames are many and large: speed over file size

CALIBRATION_HEADER = """\
# i3DPost-layout camera calibration, written by mvpose.
# Per camera, in camera-folder order (folder 000..007 = camera 1..8), 21 numbers:
#   xmin ymin xmax ymax   image bounds [px]
#   fx fy cx cy           intrinsics [px]
#   k1                    radial distortion of normalised coordinates
#   R                     rotation, 9 numbers row by row
#   t                     translation [{units}], X_cam = R * X_world + t
"""


def _units_per_metre(units):
    if units not in UNITS_PER_METRE:
        raise I3dpostError(f'calibration units {units!r}: expected one of {", ".join(UNITS_PER_METRE)}')
    return UNITS_PER_METRE[units]


def write_calibration(path, cameras, units='m'):
    """Write `cameras` (Camera list, numbers exactly 1..N, N ≤ 8) as an i3DPost calibration file.

    Numbers are written with 17 significant digits, so read_calibration returns identical floats
    (t up to the m↔mm scaling rounding)."""
    path = Path(path)
    units_per_metre = _units_per_metre(units)
    cameras = sorted(cameras, key=lambda camera: camera.number)
    numbers = [camera.number for camera in cameras]
    # The file holds no camera numbers: block k is folder k, so only 1..N survive a round trip.
    if numbers != list(range(1, len(cameras) + 1)) or len(cameras) > CAMERAS:
        raise I3dpostError(f'{path}: camera numbers {numbers} must be 1..N (N ≤ {CAMERAS}), '
                        f'one per camera folder 000..{len(cameras) - 1:03d}')
    lines = [CALIBRATION_HEADER.format(units=units)]
    for camera in cameras:
        if np.any(np.asarray(camera.D)[1:]):
            raise I3dpostError(f'{path}: {camera.name} has distortion k2, p1, p2 or k3 ≠ 0; '
                            'the i3DPost calibration format holds k1 only')
        if camera.K[0, 1] != 0:
            raise I3dpostError(f'{path}: {camera.name} has a skewed K; the i3DPost calibration format holds none')
        rows = [[0, 0, camera.width - 1, camera.height - 1],
                [camera.K[0, 0], camera.K[1, 1], camera.K[0, 2], camera.K[1, 2]],
                [camera.D[0]], *camera.R, camera.t * units_per_metre]
        lines.append(f'# camera {camera.number} (folder {camera.number - 1:03d})\n')
        lines += [' '.join('%.17g' % value for value in row) + '\n' for row in rows]
    path.write_text(''.join(lines))


def _numeric_tokens(path):
    """The numbers of a text file in order, '#' comments dropped; I3dpostError naming file:line."""
    try:
        text = path.read_text()
    except OSError as error:
        raise I3dpostError(f'{path}: cannot read calibration file: {error.strerror}') from None
    except UnicodeDecodeError:
        raise I3dpostError(f'{path}: cannot read calibration file: not a text file') from None
    numbers = []
    for line_number, line in enumerate(text.splitlines(), 1):
        for token in line.split('#', 1)[0].split():
            try:
                value = float(token)
            except ValueError:
                value = None
            if value is None or not math.isfinite(value):
                raise I3dpostError(f'{path}:{line_number}: {token!r} is not a finite number')
            numbers.append(value)
    return numbers


def read_calibration(path, units='m', camera_numbers=None, image_size=None):
    """The cameras of an i3DPost calibration file, in file (= camera-folder) order.

    units: of t in the file ('m' or 'mm'); the Cameras' t is in metres.
    camera_numbers: the camera number of each block; default 1..N.
    image_size: (width, height) [px] of the frames, if known: the bounds must agree with it."""
    path = Path(path)
    units_per_metre = _units_per_metre(units)
    numbers = _numeric_tokens(path)
    if not numbers or len(numbers) % NUMBERS_PER_CAMERA:
        raise I3dpostError(f'{path}: {len(numbers)} numbers, expected {NUMBERS_PER_CAMERA} per camera '
                        '(bounds 4, fx fy cx cy, k1, R 9, t 3)')
    blocks = np.reshape(numbers, (-1, NUMBERS_PER_CAMERA))
    camera_numbers = list(range(1, len(blocks) + 1)) if camera_numbers is None else list(camera_numbers)
    if len(camera_numbers) != len(blocks):
        raise I3dpostError(f'{path}: {len(blocks)} cameras, but {len(camera_numbers)} camera numbers given')
    cameras = []
    for number, block in zip(camera_numbers, blocks):
        xmin, ymin, xmax, ymax = block[0:4]
        fx, fy, cx, cy = block[4:8]
        R = block[9:18].reshape(3, 3)
        width, height = int(xmax - xmin) + 1, int(ymax - ymin) + 1
        if xmin != 0 or ymin != 0 or xmax != int(xmax) or ymax != int(ymax) or width < 1 or height < 1:
            raise I3dpostError(f'{path}: camera {number}: image bounds {xmin:g} {ymin:g} {xmax:g} {ymax:g} '
                            'are not 0 0 width−1 height−1')
        if image_size is not None and (width, height) != tuple(image_size):
            raise I3dpostError(f'{path}: camera {number}: image bounds say {width}×{height} px, '
                            f'the frames are {image_size[0]}×{image_size[1]} px')
        if np.abs(R.T @ R - np.eye(3)).max() > ROTATION_TOLERANCE or np.linalg.det(R) < 0:
            raise I3dpostError(f'{path}: camera {number}: R is not a rotation matrix')
        cameras.append(Camera(number, width, height, np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]]),
                              R.copy(), block[18:21] / units_per_metre, np.array([block[8], 0, 0, 0, 0])))
    return cameras


def frame_path(sequence_dir, camera_number, frame_number):
    """`<sequence_dir>/<camera folder>/<frame>.png` of camera 1..8, e.g. camera 1 frame 52 -> 000/00052.png."""
    return Path(sequence_dir) / f'{camera_number - 1:03d}' / f'{frame_number:05d}.png'


def write_frame(sequence_dir, camera_number, frame_number, rgb):
    """Write one frame, uint8 H×W×3 RGB, as a PNG in the layout; its path."""
    path = frame_path(sequence_dir, camera_number, frame_number)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2BGR), PNG_FAST):
        raise I3dpostError(f'cannot write frame {path}')
    return path


def read_frame(path):
    """One frame as uint8 H×W×3 RGB."""
    path = Path(path)
    if not path.is_file():
        raise I3dpostError(f'no frame {path}')
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if bgr is None:
        raise I3dpostError(f'cannot read frame {path}: not an image OpenCV reads')
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def _has_frames(folder):
    return any(FRAME_FILE.match(name) for name in os.listdir(folder))


def find_sequence(root):
    """The one sequence directory at or under `root`: it holds camera folders 000..007 with NNNNN.png."""
    root = Path(root)
    if not root.is_dir():
        raise I3dpostError(f'no directory {root}')
    sequences = []
    for directory, subdirectories, _ in os.walk(root):
        camera_folders = [name for name in subdirectories if CAMERA_FOLDER.match(name)]
        if any(_has_frames(os.path.join(directory, name)) for name in camera_folders):
            sequences.append(Path(directory))
            subdirectories[:] = []  # its camera folders hold thousands of frames, no sequences: skip them
    if not sequences:
        raise I3dpostError(f'{root}: no i3DPost sequence (camera folders 000..007 with NNNNN.png frames) in it')
    if len(sequences) > 1:
        raise I3dpostError(f'{root}: {len(sequences)} sequences in it, point at one of them: '
                        + ', '.join(sorted(str(sequence) for sequence in sequences)))
    return sequences[0]


def available(sequence_dir):
    """Camera number -> sorted frame numbers found in `sequence_dir` (cameras without frames left out)."""
    sequence_dir = Path(sequence_dir)
    if not sequence_dir.is_dir():
        raise I3dpostError(f'no directory {sequence_dir}')
    frames = {}
    for folder in sorted(sequence_dir.iterdir()):
        if folder.is_dir() and CAMERA_FOLDER.match(folder.name):
            numbers = sorted(int(match[1]) for match in map(FRAME_FILE.match, os.listdir(folder)) if match)
            if numbers:
                frames[int(folder.name) + 1] = numbers
    return frames


def parse_frame_range(text):
    """'52-101' -> (52, 101), '60' -> (60, 60): first and last frame numbers, inclusive."""
    match = re.fullmatch(r'\s*(\d+)\s*(?:-\s*(\d+)\s*)?', text)
    if not match:
        raise I3dpostError(f'frame range {text!r}: expected FIRST-LAST or FRAME, e.g. 52-101')
    first, last = int(match[1]), int(match[2] or match[1])
    if first > last:
        raise I3dpostError(f'frame range {text!r}: first frame {first} is after last frame {last}')
    return first, last
