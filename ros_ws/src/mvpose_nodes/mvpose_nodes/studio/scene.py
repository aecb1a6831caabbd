"""The synthetic i3DPost-like studio: a clothed person of smooth shaded solids in a blue chroma
studio, ray cast per camera, with the ground truth that feature evaluation needs.

A body is capsules (limbs, neck, feet, shoulders) and ellipsoids (torso, pelvis, head, hands)
placed on the 15 joints of a pose; every pixel's nearest surface gives its colour (albedo ×
soft wrap-around Lambert light), its body-part label and whether it is skin. The studio is a
floor (z = 0) inside a cylindrical wall, both chroma blue, with the person's soft shadow on the
floor. Realism (exposure, white balance, sensor noise, lens distortion) is applied per camera by
`Realism`. Pure NumPy/OpenCV; images are H×W×3 float32 linear RGB in [0, 1] until `finish`.
"""
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from mvpose_nodes.body.model import (JOINT_INDEX, JOINT_NAMES, LABEL_HEAD, LABEL_LEFT_ARM, LABEL_LEFT_HAND, LABEL_LEFT_LEG, LABEL_RIGHT_ARM, LABEL_RIGHT_HAND, LABEL_RIGHT_LEG, LABEL_TORSO)
from mvpose_nodes.body.geometry import normalize
from mvpose_nodes.studio.palette import HAIR_COLOURS, HAIR_LENGTHS, SHIRTS, SKIN_TONES, TROUSER_COLOURS

SKIN_BIT = 0x80  # set in a ground-truth label mask where the surface is skin

# Materials (indices into Appearance.palette()).
SKIN, HAIR, SHIRT, TROUSERS, SHOES, HEAD, MARKER = range(1, 8)  # HEAD: hair or face, decided per pixel
MARKER_RED = (0.80, 0.015, 0.02)  # linear RGB of the joint markers: saturated red, nothing else on the person is
MARKER_RADIUS = 0.02      # [m] the markers are 4 cm spheres
MARKER_PROTRUSION = 0.5   # marker centre this many radii outside the body surface (the rest is sunk into it)
MARKER_MIN_VISIBLE = 0.25  # a marker is visible in a camera when at least this fraction of its disc is seen

STUDIO_RADIUS = 5.0       # [m] cylindrical wall around the capture area
STUDIO_HEIGHT = 3.2       # [m] wall height; above it the ceiling
CHROMA_BLUE = np.array([0.06, 0.16, 0.55], np.float32)  # linear RGB of the walls and floor
CEILING = (CHROMA_BLUE * 0.6).astype(np.float32)  # blue, dimmer: studio/cases.py's lower, wider cameras see it
KEY_LIGHT = normalize(np.array([0.35, 0.25, 1.0]))    # mostly from above, as studio lights hang
AMBIENT = 0.35
WRAP = 0.5                # wrap-around diffuse: soft shading without black terminators
SHADOW_GRID = 0.015       # [m] floor shadow resolution
SHADOW_EXTENT = 1.4       # [m] half size of the shadow map around the pelvis
SHADOW_BLUR = 0.05        # [m] penumbra (sigma)
SHADOW_STRENGTH = 0.55


@dataclass(frozen=True)
class Appearance:
    """How the person looks: linear-RGB albedos, clothing and size. Radii scale with `girth`."""
    skin: tuple = SKIN_TONES['medium']
    hair: tuple = HAIR_COLOURS['dark']
    shirt: tuple = SHIRTS['red']
    trousers: tuple = TROUSER_COLOURS['dark']
    shoes: tuple = (0.035, 0.035, 0.04)  # black: brown leather is skin-coloured to any colour detector
    long_sleeves: bool = False
    girth: float = 1.0
    markers: bool = False  # red marker spheres on the 15 joints (paper 001's marker suit), see marker_centres
    hair_length: str = 'short'  # one of HAIR_LENGTHS

    def __post_init__(self):
        HAIR_LENGTHS.index(self.hair_length)  # ValueError unless one of them

    def palette(self):
        """(8, 3) float32: row m = albedo of material m (row 0 unused, HEAD resolved per pixel)."""
        return np.array([(0, 0, 0), self.skin, self.hair, self.shirt, self.trousers, self.shoes, self.skin,
                         MARKER_RED], np.float32)


@dataclass(frozen=True)
class BodyPose:
    """One frame of a person: joints (15, 3) [m] in JOINT_NAMES order, toe tips (2, 3), fingertips (2, 3)
    (left, right), and the unit direction the face looks (3,)."""
    joints: np.ndarray
    toes: np.ndarray
    hand_tips: np.ndarray
    head_forward: np.ndarray


@dataclass
class Capsule:
    a: np.ndarray
    b: np.ndarray
    radius: float
    label: int
    material: int
    name: str = ''         # which part of the body (e.g. 'left_thigh', 'marker_left_knee')


@dataclass
class Ellipsoid:
    center: np.ndarray
    axes: np.ndarray       # 3×3, columns = the ellipsoid's unit axes in the world
    semi_axes: np.ndarray  # (3,) [m]
    label: int
    material: int
    name: str = ''


def _frame(primary, secondary):
    """3×3 columns (u, v, w): u along `primary`, v = `secondary` made orthogonal to u (any
    perpendicular when they are parallel), w = u × v."""
    u = normalize(primary)
    v = secondary - np.dot(secondary, u) * u
    if np.linalg.norm(v) < 1e-6 * max(np.linalg.norm(secondary), 1e-12):
        v = np.cross(u, np.eye(3)[np.argmin(np.abs(u))])
    v = normalize(v)
    return np.column_stack([u, v, np.cross(u, v)])


def body_primitives(pose, appearance):
    """The solids of a person in `pose` (a list of Capsule and Ellipsoid), each named after its body
    part; with `appearance.markers`, also the 15 red marker spheres (named 'marker_<joint>', last)."""
    solids = _body_solids(pose, appearance)
    if appearance.markers:
        solids += marker_solids(marker_centres(pose, appearance, solids))
    return solids


def _body_solids(pose, appearance):
    p, g = pose.joints, appearance.girth
    up = normalize(p[JOINT_INDEX['neck']] - p[JOINT_INDEX['pelvis']])
    left = normalize(p[JOINT_INDEX['left_hip']] - p[JOINT_INDEX['right_hip']])
    forward = normalize(np.cross(left, up))
    arm_material = SHIRT if appearance.long_sleeves else SKIN
    solids = [
        Ellipsoid(p[JOINT_INDEX['pelvis']] + 0.02 * up, _frame(left, up), np.array([0.17, 0.12, 0.10]) * g, LABEL_TORSO, TROUSERS,
                  'pelvis'),
        Ellipsoid(0.5 * (p[JOINT_INDEX['pelvis']] + p[JOINT_INDEX['neck']]) - 0.01 * forward, _frame(up, left),
                  np.array([0.5 * np.linalg.norm(p[JOINT_INDEX['neck']] - p[JOINT_INDEX['pelvis']]) + 0.03, 0.165 * g, 0.11 * g]),
                  LABEL_TORSO, SHIRT, 'torso'),
        Capsule(p[JOINT_INDEX['left_shoulder']], p[JOINT_INDEX['right_shoulder']], 0.055 * g, LABEL_TORSO, SHIRT, 'shoulders'),
        Capsule(p[JOINT_INDEX['neck']] - 0.03 * up, p[JOINT_INDEX['head']] - 0.16 * normalize(p[JOINT_INDEX['head']] - p[JOINT_INDEX['neck']]), 0.05 * g,
                LABEL_HEAD, SKIN, 'neck'),
    ]
    head_up = normalize(p[JOINT_INDEX['head']] - p[JOINT_INDEX['neck']])
    head = Ellipsoid(p[JOINT_INDEX['head']] - 0.115 * head_up, _frame(head_up, pose.head_forward),
                     np.array([0.115, 0.10, 0.08]), LABEL_HEAD, HEAD, 'head')
    solids.append(head)
    if appearance.hair_length == 'long':  # a shell behind the head and neck to 0.36 m below the crown
        solids.append(Ellipsoid(head.center - 0.07 * head_up - 0.035 * head.axes[:, 1], head.axes,
                                np.array([0.175, 0.085, 0.092]), LABEL_HEAD, HAIR, 'hair'))
    for side, arm_label, hand_label, leg_label, toe, tip in (
            ('left', LABEL_LEFT_ARM, LABEL_LEFT_HAND, LABEL_LEFT_LEG, pose.toes[0], pose.hand_tips[0]),
            ('right', LABEL_RIGHT_ARM, LABEL_RIGHT_HAND, LABEL_RIGHT_LEG, pose.toes[1], pose.hand_tips[1])):
        shoulder, elbow, wrist = (p[JOINT_INDEX[f'{side}_{n}']] for n in ('shoulder', 'elbow', 'wrist'))
        hip, knee, ankle = (p[JOINT_INDEX[f'{side}_{n}']] for n in ('hip', 'knee', 'ankle'))
        hand_axis = tip - wrist
        solids += [
            Capsule(shoulder, elbow, 0.05 * g, arm_label, SHIRT, f'{side}_upper_arm'),
            Capsule(elbow, wrist, 0.038 * g, arm_label, arm_material, f'{side}_forearm'),
            Ellipsoid(wrist + 0.45 * hand_axis, _frame(hand_axis, np.cross(hand_axis, up)),
                      np.array([0.55 * np.linalg.norm(hand_axis), 0.045, 0.02]), hand_label, SKIN, f'{side}_hand'),
            Capsule(hip, knee, 0.07 * g, leg_label, TROUSERS, f'{side}_thigh'),
            Capsule(knee, ankle, 0.05 * g, leg_label, TROUSERS, f'{side}_shin'),
            Capsule(ankle + 0.02 * (ankle - toe), toe, 0.045, leg_label, SHOES, f'{side}_foot'),
        ]
    return solids


# Where each joint's marker sits: the body surface seen from the joint along a direction (in the
# body's frame: forward, left, up; 'lateral' = away from the body's midline, made perpendicular to
# the named bone), found on the named solids only. Anatomical landmarks of a marker suit: the vertex,
# the suprasternal notch, the acromia, the lateral epicondyles and styloids, the front of the pelvis,
# the greater trochanters, the patellae and the lateral malleoli.
MARKER_PLACEMENT = {
    'pelvis': (('forward',), None, ('pelvis', 'torso')),
    'neck': (('forward',), None, ('neck', 'torso', 'shoulders')),
    'head': (('head_up',), None, ('head',)),
    **{f'{side}_{joint}': placement for side in ('left', 'right') for joint, placement in (
        ('hip', (('lateral',), None, ('pelvis', f'{side}_thigh'))),
        ('knee', (('forward',), (f'{side}_hip', f'{side}_ankle'), (f'{side}_thigh', f'{side}_shin'))),
        ('ankle', (('lateral',), (f'{side}_knee', f'{side}_ankle'), (f'{side}_shin', f'{side}_foot'))),
        ('shoulder', (('lateral', 'up'), None, ('shoulders', f'{side}_upper_arm', 'torso'))),
        ('elbow', (('lateral',), (f'{side}_shoulder', f'{side}_wrist'), (f'{side}_upper_arm', f'{side}_forearm'))),
        ('wrist', (('lateral',), (f'{side}_elbow', f'{side}_wrist'), (f'{side}_forearm', f'{side}_hand'))))},
}


def marker_centres(pose, appearance=None, solids=None):
    """(15, 3) [m] centres of the joint markers, JOINT_NAMES order: each joint moved out along its
    MARKER_PLACEMENT direction to the body's surface, plus MARKER_PROTRUSION marker radii (the head's
    marker sits on the vertex, which is already on the surface)."""
    appearance = appearance or Appearance()
    solids = solids if solids is not None else _body_solids(pose, appearance)
    by_name = {solid.name: solid for solid in solids}
    p = pose.joints
    up = normalize(p[JOINT_INDEX['neck']] - p[JOINT_INDEX['pelvis']])
    left = normalize(p[JOINT_INDEX['left_hip']] - p[JOINT_INDEX['right_hip']])
    basis = {'forward': normalize(np.cross(left, up)), 'up': up,
             'head_up': normalize(p[JOINT_INDEX['head']] - p[JOINT_INDEX['neck']])}
    centres = np.empty((len(JOINT_NAMES), 3))
    for name, index in JOINT_INDEX.items():
        words, bone, parts = MARKER_PLACEMENT[name]
        outward = -left if name.startswith('right') else left
        direction = sum(outward if word == 'lateral' else basis[word] for word in words)
        if bone is not None:
            axis = normalize(p[JOINT_INDEX[bone[1]]] - p[JOINT_INDEX[bone[0]]])
            direction = direction - np.dot(direction, axis) * axis
        direction = normalize(direction)
        far = p[index] + 1.0 * direction
        hits = [_intersect(by_name[part], far, -direction[None])[0][0] for part in parts]
        depth = 1.0 - min(hits) if np.isfinite(min(hits)) else 0.0
        centres[index] = p[index] + (max(depth, 0.0) + MARKER_PROTRUSION * MARKER_RADIUS) * direction
    return centres


def marker_solids(centres):
    """The red marker spheres at centres (15, 3), labelled with their joint's body part."""
    labels = {'pelvis': LABEL_TORSO, 'neck': LABEL_TORSO, 'head': LABEL_HEAD}
    for side, arm, leg in (('left', LABEL_LEFT_ARM, LABEL_LEFT_LEG), ('right', LABEL_RIGHT_ARM, LABEL_RIGHT_LEG)):
        labels.update({f'{side}_{j}': arm for j in ('shoulder', 'elbow', 'wrist')})
        labels.update({f'{side}_{j}': leg for j in ('hip', 'knee', 'ankle')})
    return [Ellipsoid(np.asarray(centre, float), np.eye(3), np.full(3, MARKER_RADIUS), labels[name], MARKER,
                      f'marker_{name}') for name, centre in zip(JOINT_NAMES, centres)]


def _sphere_disc_rays(origin, centre, radius, count):
    """`count` unit rays from `origin` spread evenly (a sunflower) over the disc the sphere covers."""
    axis = centre - origin
    distance = np.linalg.norm(axis)
    half_angle = np.arcsin(min(radius / distance, 1.0)) * 0.98
    frame = _frame(axis, np.array([0.0, 0.0, 1.0]))
    k = np.arange(count) + 0.5
    rho = np.tan(half_angle) * np.sqrt(k / count)
    phi = k * np.pi * (3 - np.sqrt(5))
    directions = frame[:, [0]] + frame[:, [1]] * rho * np.cos(phi) + frame[:, [2]] * rho * np.sin(phi)
    return normalize(directions.T)


def marker_visibility(camera, pose, appearance, samples=64):
    """Ground truth of the markers in one camera: pixels (15, 2) of the marker centres' true
    projections (with the lens' distortion), the visible fraction (15,) of each marker's disc (rays
    from the camera centre over the disc whose first hit, among the body and all markers, is that
    marker) and visible (15,) bool: fraction >= MARKER_MIN_VISIBLE and the centre inside the image."""
    solids = body_primitives(pose, replace(appearance, markers=True))
    marker_numbers = [number for number, solid in enumerate(solids) if solid.material == MARKER]
    markers = [solids[number] for number in marker_numbers]
    origin = camera.center
    pixels, depth = camera.project(np.array([m.center for m in markers]))
    fractions = np.zeros(len(markers))
    for index, marker in enumerate(markers):
        if depth[index] <= 0:
            continue
        rays = _sphere_disc_rays(origin, marker.center, MARKER_RADIUS, samples)
        nearest = np.full(len(rays), np.inf)
        nearest_solid = np.full(len(rays), -1)
        for number, solid in enumerate(solids):
            t = _intersect(solid, origin, rays)[0]
            nearer = t < nearest
            nearest[nearer], nearest_solid[nearer] = t[nearer], number
        fractions[index] = np.mean(nearest_solid == marker_numbers[index])
    inside = (depth > 0) & (pixels[:, 0] >= -0.5) & (pixels[:, 0] <= camera.width - 0.5) & \
             (pixels[:, 1] >= -0.5) & (pixels[:, 1] <= camera.height - 0.5)
    return pixels, fractions, inside & (fractions >= MARKER_MIN_VISIBLE)


def _bounding_sphere(solid):
    if isinstance(solid, Capsule):
        return 0.5 * (solid.a + solid.b), 0.5 * np.linalg.norm(solid.b - solid.a) + solid.radius
    return solid.center, float(np.max(solid.semi_axes))


def _intersect(solid, origin, directions):
    """Ray parameters t (N,) of the first hit (inf: miss) and unit normals (N, 3), for rays
    origin + t·d with a shared origin (the camera centre) and unit directions (N, 3)."""
    if isinstance(solid, Ellipsoid):
        o = (solid.axes.T @ (origin - solid.center)) / solid.semi_axes
        d = (directions @ solid.axes) / solid.semi_axes
        a = np.einsum('ij,ij->i', d, d)
        b = d @ o
        h = b * b - a * (o @ o - 1.0)
        t = np.where(h > 0, (-b - np.sqrt(np.maximum(h, 0))) / a, np.inf)
        local = o + np.where(np.isfinite(t), t, 0)[:, None] * d
        normals = normalize((local / solid.semi_axes) @ solid.axes.T)
        return np.where(t > 0, t, np.inf), normals
    ba = solid.b - solid.a
    oa = origin - solid.a
    baba, baoa, oaoa = ba @ ba, ba @ oa, oa @ oa
    bard = directions @ ba
    rdoa = directions @ oa
    qa = baba - bard * bard
    qb = baba * rdoa - baoa * bard
    qc = baba * oaoa - baoa * baoa - solid.radius ** 2 * baba
    h = qb * qb - qa * qc
    with np.errstate(divide='ignore', invalid='ignore'):
        t_body = (-qb - np.sqrt(np.maximum(h, 0))) / qa
    y = baoa + t_body * bard
    body_hit = (h > 0) & (y > 0) & (y < baba)
    # The ray misses the cylinder part: try the cap sphere on the side it approaches.
    cap_center = np.where((y <= 0)[:, None], solid.a, solid.b)
    oc = origin - cap_center
    b2 = np.einsum('ij,ij->i', directions, oc)
    h2 = b2 * b2 - (np.einsum('ij,ij->i', oc, oc) - solid.radius ** 2)
    t_cap = np.where(h2 > 0, -b2 - np.sqrt(np.maximum(h2, 0)), np.inf)
    t = np.where(body_hit, t_body, t_cap)
    t = np.where(np.isfinite(t) & (t > 0), t, np.inf)
    points = origin + np.nan_to_num(t, posinf=0)[:, None] * directions
    axis_point = solid.a + np.clip(((points - solid.a) @ ba) / baba, 0, 1)[:, None] * ba
    return t, normalize(points - axis_point)


@dataclass
class CameraRays:
    """Per-camera geometry reused every frame: viewing rays of the ideal (undistorted) image, and
    the floor point (x, y) [m] seen by each background pixel."""
    camera: object
    rays: np.ndarray           # (H, W, 3) float32 unit directions in the world
    background: np.ndarray     # (H, W, 3) float32 linear RGB of the empty studio
    floor_xy: np.ndarray       # (H, W, 2) float32, NaN where the pixel does not see the floor
    ideal_from_distorted: tuple = field(default=None)  # cv2.remap maps, or None without distortion


def prepare_camera(camera, texture_seed=0):
    """Rays, empty studio and floor look-up of one camera (done once per camera)."""
    width, height = camera.width, camera.height
    columns, rows = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    ideal = np.column_stack([(columns.ravel() - camera.K[0, 2]) / camera.K[0, 0],
                             (rows.ravel() - camera.K[1, 2]) / camera.K[1, 1]])
    rays = camera.rays(ideal).reshape(height, width, 3)
    origin = camera.center
    # Floor z = 0 and the cylindrical wall: whichever the ray meets first.
    dz = rays[..., 2]
    with np.errstate(divide='ignore', invalid='ignore'):
        t_floor = np.where(dz < 0, -origin[2] / dz, np.inf)
    dx, dy = rays[..., 0], rays[..., 1]
    a = dx * dx + dy * dy
    b = origin[0] * dx + origin[1] * dy
    c = origin[0] ** 2 + origin[1] ** 2 - STUDIO_RADIUS ** 2
    t_wall = (-b + np.sqrt(np.maximum(b * b - a * c, 0))) / np.maximum(a, 1e-12)
    wall_z = origin[2] + t_wall * dz
    floor = t_floor < t_wall
    floor_points = origin + np.where(floor, t_floor, 0)[..., None] * rays
    rng = np.random.default_rng(texture_seed)
    texture = cv2.GaussianBlur(rng.normal(1.0, 0.08, (height // 8 + 1, width // 8 + 1)).astype(np.float32), (0, 0), 2)
    texture = cv2.resize(texture, (width, height), interpolation=cv2.INTER_LINEAR)
    distance = np.where(floor, t_floor, t_wall)
    falloff = (1.0 / (1.0 + 0.04 * distance ** 2)).astype(np.float32)  # light falls off towards the walls' far side
    background = np.where(floor[..., None], CHROMA_BLUE * 1.1,
                          np.where(((wall_z > 0) & (wall_z < STUDIO_HEIGHT))[..., None],
                                   CHROMA_BLUE * (0.75 + 0.25 * np.clip(wall_z / STUDIO_HEIGHT, 0, 1))[..., None],
                                   CEILING))
    background = (background * (texture * (0.6 + 0.4 * falloff))[..., None]).astype(np.float32)
    floor_xy = np.where(floor[..., None], floor_points[..., :2], np.nan).astype(np.float32)
    maps = None
    if np.any(camera.D):
        distorted = np.column_stack([columns.ravel(), rows.ravel()])
        ideal_pixels = camera.pixels_from_normalized(camera.undistort_pixels(distorted)).astype(np.float32)
        maps = (ideal_pixels[:, 0].reshape(height, width), ideal_pixels[:, 1].reshape(height, width))
    return CameraRays(camera, rays.astype(np.float32), background, floor_xy, maps)


def floor_shadow(pose, appearance):
    """(shadow map, its centre (2,) [m]) of the person's soft shadow on the floor, for `render`."""
    centre = pose.joints[0, :2]
    return shadow_map(body_primitives(pose, appearance), centre), centre


def shadow_map(solids, center_xy):
    """Soft floor shadow (S, S) float32 in [0, SHADOW_STRENGTH] around `center_xy` under an overhead light."""
    size = int(round(2 * SHADOW_EXTENT / SHADOW_GRID))
    coordinates = (np.arange(size) + 0.5) * SHADOW_GRID - SHADOW_EXTENT
    gx, gy = np.meshgrid(coordinates + center_xy[0], coordinates + center_xy[1])
    grid = np.stack([gx, gy], -1)
    occupied = np.zeros((size, size), bool)
    for solid in solids:
        if isinstance(solid, Capsule):
            a, b, r = solid.a[:2], solid.b[:2], solid.radius
        else:
            a = b = solid.center[:2]
            r = float(np.mean(solid.semi_axes))
        ab = b - a
        s = np.clip(((grid - a) @ ab) / max(ab @ ab, 1e-12), 0, 1)
        occupied |= np.linalg.norm(grid - (a + s[..., None] * ab), axis=-1) < r
    sigma = SHADOW_BLUR / SHADOW_GRID
    return SHADOW_STRENGTH * cv2.GaussianBlur(occupied.astype(np.float32), (0, 0), sigma)


@dataclass
class Rendering:
    """One camera's view of one frame: linear RGB (H, W, 3) float32 and the ground-truth label mask
    (H, W) uint8: body-part LABEL_* value, with SKIN_BIT set on skin; 0 = background. With markers,
    marker_ids (H, W) int8: the JOINT_NAMES index of the marker seen at each pixel, −1 elsewhere."""
    rgb: np.ndarray
    labels: np.ndarray
    marker_ids: np.ndarray = None


def render(view, pose, appearance, shadow=None, shadow_center=None, soft_shading=True):
    """Ray cast `pose` into the camera prepared as `view` (CameraRays). `shadow` from shadow_map."""
    camera, height, width = view.camera, view.camera.height, view.camera.width
    depth = np.full((height, width), np.inf, np.float32)
    normals = np.zeros((height, width, 3), np.float32)
    materials = np.zeros((height, width), np.uint8)
    labels = np.zeros((height, width), np.uint8)
    which = np.full((height, width), -1, np.int16)
    origin = camera.center
    solids = body_primitives(pose, appearance)
    for number, solid in enumerate(solids):
        box = _screen_box(camera, *_bounding_sphere(solid))
        if box is None:
            continue
        r0, r1, c0, c1 = box
        directions = view.rays[r0:r1, c0:c1].reshape(-1, 3).astype(np.float64)
        t, n = _intersect(solid, origin, directions)
        t = t.reshape(r1 - r0, c1 - c0)
        nearer = t < depth[r0:r1, c0:c1]
        depth[r0:r1, c0:c1][nearer] = t[nearer]
        normals[r0:r1, c0:c1][nearer] = n.reshape(r1 - r0, c1 - c0, 3)[nearer]
        materials[r0:r1, c0:c1][nearer] = solid.material
        labels[r0:r1, c0:c1][nearer] = solid.label
        which[r0:r1, c0:c1][nearer] = number
    marker_ids = None
    if appearance.markers:  # body_primitives puts the markers last, in JOINT_NAMES order
        first_marker = len(solids) - len(JOINT_NAMES)
        marker_ids = np.where(materials == MARKER, which - first_marker, -1).astype(np.int8)
    person = materials > 0
    _resolve_hair(materials, normals, pose, person, appearance.hair_length)
    albedo = appearance.palette()[materials]
    light = np.clip((normals @ KEY_LIGHT.astype(np.float32) + WRAP) / (1 + WRAP), 0, 1) if soft_shading \
        else np.ones((height, width), np.float32)
    shaded = albedo * (AMBIENT + (1 - AMBIENT) * light)[..., None]
    scene = view.background.copy()
    if shadow is not None:
        floor = ~np.isnan(view.floor_xy[..., 0])
        corner = np.float32(shadow_center) - np.float32(SHADOW_EXTENT)
        map_x = (view.floor_xy[..., 0] - corner[0]) / np.float32(SHADOW_GRID) - np.float32(0.5)
        map_y = (view.floor_xy[..., 1] - corner[1]) / np.float32(SHADOW_GRID) - np.float32(0.5)
        darkening = cv2.remap(shadow, np.nan_to_num(map_x, nan=-10), np.nan_to_num(map_y, nan=-10),
                              cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        scene *= (1 - np.where(floor, darkening, 0))[..., None]
    scene[person] = shaded[person]
    labels[(materials == SKIN)] |= SKIN_BIT
    return Rendering(scene, labels, marker_ids)


def _resolve_hair(materials, normals, pose, person, hair_length='short'):
    """HEAD pixels become hair on the crown and the back of the head, skin on the face (see HAIR_LENGTHS)."""
    head = materials == HEAD
    if not head.any():
        return
    head_up = normalize(pose.joints[JOINT_INDEX['head']] - pose.joints[JOINT_INDEX['neck']])
    forward = normalize(pose.head_forward - np.dot(pose.head_forward, head_up) * head_up)
    n = normals[head]
    crown, back, nape = (0.55, -0.35, -0.2) if hair_length == 'cropped' else (0.45, -0.1, -2.0)
    hair = (n @ head_up > crown) | ((n @ forward < back) & (n @ head_up > nape))
    materials[head] = np.where(hair, HAIR, SKIN)


def _screen_box(camera, center, radius):
    """Pixel rows/columns (r0, r1, c0, c1) covering a sphere in the ideal image, or None if off screen."""
    corners = center + radius * np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
    local = camera.to_camera(corners)
    if np.any(local[:, 2] <= 0.05):
        return None
    pixels = camera.pixels_from_normalized(local[:, :2] / local[:, 2:3])
    c0, r0 = np.floor(pixels.min(axis=0)).astype(int) - 1
    c1, r1 = np.ceil(pixels.max(axis=0)).astype(int) + 2
    r0, r1 = max(r0, 0), min(r1, camera.height)
    c0, c1 = max(c0, 0), min(c1, camera.width)
    return None if r0 >= r1 or c0 >= c1 else (r0, r1, c0, c1)


@dataclass(frozen=True)
class Realism:
    """The camera effects applied to a rendering (each 0, or 1 for exposure and white_balance, for none)."""
    exposure_variation: float = 0.08    # relative spread of per-camera exposure gain
    white_balance_variation: float = 0.04  # relative spread of per-channel gains
    noise: float = 2.0                  # [DN] sensor read noise sigma, plus shot noise
    blur: float = 0.6                   # [px] optics (Gaussian sigma); also softens the ray-cast edges
    exposure: float = 1.0               # gain of the whole rig (under or over exposure), times each camera's
    white_balance: tuple = (1.0, 1.0, 1.0)  # (r, g, b) gains of the whole rig (a colour cast), times each camera's

    def camera_response(self, camera_number, seed):
        """(gain, white balance (3,)) of one camera: fixed per camera and seed, as in a real rig."""
        rng = np.random.default_rng([seed, camera_number, 1])
        gain = self.exposure * (1.0 + self.exposure_variation * rng.uniform(-1, 1))
        balance = np.multiply(self.white_balance, 1.0 + self.white_balance_variation * rng.uniform(-1, 1, 3))
        return gain, balance.astype(np.float32)

    def finish(self, rendering, view, camera_number, seed, frame_number):
        """8-bit RGB (H, W, 3) and the label mask, both distorted like the lens when it has distortion."""
        gain, balance = self.camera_response(camera_number, seed)
        rgb = rendering.rgb * (gain * balance)
        if self.blur:
            rgb = cv2.GaussianBlur(rgb, (0, 0), self.blur)
        labels = rendering.labels
        if view.ideal_from_distorted is not None:
            rgb = cv2.remap(rgb, *view.ideal_from_distorted, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
            labels = cv2.remap(labels, *view.ideal_from_distorted, cv2.INTER_NEAREST)
        encoded = 255.0 * np.power(np.clip(rgb, 0, 1), 1 / 2.2)  # sRGB-like gamma
        if self.noise:
            rng = np.random.default_rng([seed, camera_number, frame_number, 2])
            sigma = np.sqrt(self.noise ** 2 + 0.05 * encoded)  # read noise and shot noise
            encoded = encoded + sigma * rng.standard_normal(encoded.shape, dtype=np.float32)
        return np.clip(encoded + 0.5, 0, 255).astype(np.uint8), labels
