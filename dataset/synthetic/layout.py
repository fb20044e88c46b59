"""Seeded room layouts: geometry, materials, the picture's depicted scene, camera motion.

A layout depends on the seed only (not on the output resolution): the room, its boxes, a
picture and a mirror on its walls, and a camera that pans back and forth. The picture and
mirror are re-drawn until, for every pose of the camera's motion, each rectangle and the band
of wall around it lie fully inside the canonical 640×360 view and the rectangle covers at
least ``MIN_ILLUSION_PX`` pixels. Nothing can hide them: boxes are lower than the bands'
bottom edge and the camera looks from above that height, so every sight line to a band
passes above every box.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from dataset.synthetic.raycast import N_FACES, TANGENT_AXES, Material, Rect, Scene, Vec3
from dataset.synthetic.textures import (
    BASE_TEXTURES,
    FLAT,
    PHOTO_TEXTURES,
    TILE,
    texture_index,
)

FPS = 2.0
# The camera's motion is periodic, so any number of frames stays within the validated poses.
PERIOD_FRAMES = 24
CANONICAL_SIZE = (640, 360)
CANONICAL_F = 500.0
BASELINE_M = 0.1
SUPPORT_BAND_M = 0.2
FRAME_M = 0.05
MAX_BOX_HEIGHT_M = 0.9
MIN_ILLUSION_PX = 5000
_EDGE_MARGIN_PX = 4
_WALL_MARGIN_M = 0.15
# Texel density of the rendered picture (texels per metre of canvas).
PICTURE_TEXELS_PER_M = 200
# Rect placements tried per room before the whole room is re-drawn, and rooms tried.
_RECT_TRIES = 400
_ROOM_TRIES = 50
# The picture's own texture is the first tile after the base textures in the atlas.
PICTURE_TILE = len(BASE_TEXTURES)
# Faces that can hold an illusion: left, right and front walls (x min, x max, z max).
_ILLUSION_FACES = (0, 1, 5)
_ILLUSION_FACE_WEIGHTS = (0.4, 0.4, 0.2)

_WALL_TEXTURES = ("brick", "gravel", "grass", "moon", "coins")
_FLOOR_TEXTURES = ("gravel", "brick", "grass")
_WALL_TINTS = (
    (0.95, 0.88, 0.75),
    (0.80, 0.88, 0.97),
    (0.85, 0.95, 0.80),
    (0.98, 0.84, 0.84),
    (0.92, 0.92, 0.92),
    (0.97, 0.93, 0.70),
)
_FLOOR_TINTS = ((0.78, 0.56, 0.36), (0.62, 0.62, 0.65), (0.58, 0.46, 0.40))
_CEILING_TINT = (0.98, 0.98, 0.96)
_PICTURE_FRAME_TINT = (0.50, 0.34, 0.16)
_MIRROR_FRAME_TINT = (0.22, 0.22, 0.25)

# Scene families (``families=True``): scenes where each of stereo and the monocular map is the one to trust
# somewhere inside illusions. Their numbers come from a stream of their own, so that a family scene is the
# seed's room with these drawn on top.
_FAMILY_STREAM = 0x66616D  # "fam"
# Every illusion's frame, whatever its kind, from one distribution: so a frame says nothing of the kind.
FRAME_PRESENT = 0.6
FRAME_WIDTH_M = (0.02, 0.12)
FRAME_TINTS = (_PICTURE_FRAME_TINT, _MIRROR_FRAME_TINT, (0.92, 0.92, 0.90), (0.08, 0.08, 0.08),
               (0.75, 0.62, 0.25), (0.55, 0.55, 0.58), (0.35, 0.22, 0.12))
# Mirrors too wide for a matcher to fill from their border: tried for 80 % of scenes, of which about 60 %
# find a wall that holds one whole in view (about half the mirrors are large).
LARGE_MIRROR = 0.8
LARGE_MIRROR_M = ((1.4, 2.4), (1.1, 1.6))  # width, height ranges
# A mirrored front wall, edge to edge (a gym's or a dance studio's): no wall around the glass, and the side
# walls, floor and ceiling go on in the reflection, so the room looks twice as long and nothing in the image
# says where the glass is. Stereo is fooled over the whole wall; a mono that reads mirrors as surfaces is
# not. Drawn first, for this share of family scenes; the picture then goes on a side wall (when neither
# holds it, the scene has no mirrored wall).
MIRROR_WALL = 0.5
_FRONT_FACE = 5
_SIDE_FACES = (0, 1)
# Walls where stereo is weak: textureless (flat paint) or repetitive (a small tile, repeated often).
TEXTURELESS_WALL = 0.3
REPETITIVE_WALL = 0.2
REPETITIVE_REPEAT = (5.0, 8.0)  # tiles per metre: a period of 12-20 cm, some disparity steps at 0.6 m


@dataclass(frozen=True)
class Trajectory:
    """Camera motion: yaw (rad, about the down axis) and a sideways sway (m) oscillating
    with period ``PERIOD_FRAMES / FPS`` seconds; a constant downward ``pitch`` (rad); eye at
    the world origin when the sway is zero."""

    yaw0: float
    yaw_amplitude: float
    pitch: float
    sway_m: float
    yaw_phase: float
    sway_phase: float

    def pose(self, time_s: float) -> tuple[np.ndarray, np.ndarray]:
        """(center (3,) m, rotation (3, 3) camera-to-world, columns right/down/forward)."""
        w = 2 * math.pi * time_s * FPS / PERIOD_FRAMES
        yaw = self.yaw0 + self.yaw_amplitude * math.sin(w + self.yaw_phase)
        center = np.array([self.sway_m * math.sin(w + self.sway_phase), 0.0, 0.0])
        forward = np.array([math.sin(yaw) * math.cos(self.pitch), math.sin(self.pitch),
                            math.cos(yaw) * math.cos(self.pitch)])
        right = np.array([math.cos(yaw), 0.0, -math.sin(yaw)])
        return center, np.stack([right, np.cross(forward, right), forward], axis=1)


@dataclass(frozen=True)
class Layout:
    """One seed's world: the room ``scene`` (rects: picture frame, mirror frame, picture
    canvas, mirror glass), the ``depicted`` scene the picture shows (a room behind the wall,
    world coordinates), the ``viewpoint`` the picture is painted for, the picture texture
    size ``picture_texels`` (w, h) and the camera ``trajectory``."""

    scene: Scene
    depicted: Scene
    picture: Rect
    mirror: Rect
    viewpoint: Vec3
    picture_texels: tuple[int, int]
    trajectory: Trajectory

    @property
    def picture_sid(self) -> int:
        """Surface id of the picture canvas."""
        return self.scene.rect_sid(2)

    @property
    def mirror_sid(self) -> int:
        """Surface id of the mirror glass."""
        return self.scene.rect_sid(3)


def _vec3(values: Iterable[float]) -> Vec3:
    """Three Python floats: numpy scalars in scene constants would promote float32 rays to
    float64 (NEP 50)."""
    x, y, z = (float(c) for c in values)
    return x, y, z


def face_point(room_lo: Vec3, room_hi: Vec3, face: int, t0: float, t1: float) -> np.ndarray:
    """World point (3,) on room face ``face`` at tangent coordinates (t0, t1)."""
    axis = face // 2
    p = np.zeros(3)
    p[axis] = room_hi[axis] if face % 2 else room_lo[axis]
    p[TANGENT_AXES[axis][0]], p[TANGENT_AXES[axis][1]] = t0, t1
    return p


def _corners(room_lo: Vec3, room_hi: Vec3, rect: Rect) -> np.ndarray:
    """(4, 3) corners of ``rect`` in polygon order."""
    (a0, a1), (b0, b1) = rect.lo, rect.hi
    return np.array([face_point(room_lo, room_hi, rect.face, s, t)
                     for s, t in ((a0, a1), (b0, a1), (b0, b1), (a0, b1))])


def _fully_visible(room_lo: Vec3, room_hi: Vec3, rect: Rect, trajectory: Trajectory) -> bool:
    """Whether ``rect`` and its support band stay inside the canonical view at every pose,
    with the rect covering at least MIN_ILLUSION_PX pixels."""
    w, h = CANONICAL_SIZE
    cx, cy = (w - 1) / 2, (h - 1) / 2
    inner = _corners(room_lo, room_hi, rect)
    outer = _corners(room_lo, room_hi, rect.grown(SUPPORT_BAND_M))
    for k in range(PERIOD_FRAMES):
        center, rotation = trajectory.pose(k / FPS)
        cam = (np.vstack([inner, outer]) - center) @ rotation
        if cam[:, 2].min() < 0.3:
            return False
        u = CANONICAL_F * cam[:, 0] / cam[:, 2] + cx
        v = CANONICAL_F * cam[:, 1] / cam[:, 2] + cy
        m = _EDGE_MARGIN_PX
        if u.min() < m or u.max() > w - 1 - m or v.min() < m or v.max() > h - 1 - m:
            return False
        area = 0.5 * abs(np.dot(u[:4], np.roll(v[:4], -1)) - np.dot(v[:4], np.roll(u[:4], -1)))
        if area < MIN_ILLUSION_PX:
            return False
    return True


def _sample_rect(rng: np.random.Generator, room_lo: Vec3, room_hi: Vec3, face: int,
                 width: tuple[float, float], height: tuple[float, float]) -> Rect | None:
    """A random wall rectangle whose support band keeps clear of the wall's edges and whose
    band bottom lies above every box, or None when the drawn height does not fit."""
    horizontal = TANGENT_AXES[face // 2][0]
    w, h = rng.uniform(*width), rng.uniform(*height)
    clearance = SUPPORT_BAND_M + _WALL_MARGIN_M
    lo0 = rng.uniform(room_lo[horizontal] + clearance, room_hi[horizontal] - clearance - w)
    floor_y, room_height = room_hi[1], room_hi[1] - room_lo[1]
    lowest = MAX_BOX_HEIGHT_M + 0.1 + SUPPORT_BAND_M
    if room_height - clearance - h < lowest:
        return None
    bottom = rng.uniform(lowest, room_height - clearance - h)
    return Rect(face, (lo0, floor_y - bottom - h), (lo0 + w, floor_y - bottom))


def _front_wall(room_lo: Vec3, room_hi: Vec3) -> Rect:
    """The whole front wall as one rect (tangent coordinates x, y in m): a frame grown around it lies off
    the wall, so such a mirror has none."""
    assert TANGENT_AXES[_FRONT_FACE // 2] == (0, 1)
    return Rect(_FRONT_FACE, (room_lo[0], room_lo[1]), (room_hi[0], room_hi[1]))


def _disjoint(a: Rect, b: Rect, gap: float) -> bool:
    """Whether rects ``a`` and ``b`` lie on different faces or ``gap`` metres apart."""
    if a.face != b.face:
        return True
    return (a.hi[0] + gap < b.lo[0] or b.hi[0] + gap < a.lo[0]
            or a.hi[1] + gap < b.lo[1] or b.hi[1] + gap < a.lo[1])


def _place_illusion(rng: np.random.Generator, room_lo: Vec3, room_hi: Vec3,
                    trajectory: Trajectory, width: tuple[float, float],
                    height: tuple[float, float], avoid: Rect | None,
                    faces: tuple[int, ...] = _ILLUSION_FACES) -> Rect | None:
    """A wall rect on one of ``faces`` passing every visibility rule, or None if none was found."""
    weights = np.array([_ILLUSION_FACE_WEIGHTS[_ILLUSION_FACES.index(f)] for f in faces])
    for _ in range(_RECT_TRIES):
        face = int(rng.choice(faces, p=weights / weights.sum()))
        rect = _sample_rect(rng, room_lo, room_hi, face, width, height)
        if rect is None:
            continue
        if avoid is not None and not _disjoint(rect.grown(SUPPORT_BAND_M),
                                               avoid.grown(SUPPORT_BAND_M), 0.1):
            continue
        if _fully_visible(room_lo, room_hi, rect, trajectory):
            return rect
    return None


def _sample_boxes(rng: np.random.Generator, count: int, region_lo: tuple[float, float],
                  region_hi: tuple[float, float], floor_y: float,
                  footprint: tuple[float, float], height: tuple[float, float],
                  cone: float | None = None) -> list[tuple[Vec3, Vec3]]:
    """Up to ``count`` boxes standing on ``floor_y``, 0.15 m apart, inside the (x, z)
    rectangle [region_lo, region_hi]; ``footprint``/``height`` are size ranges (m). With
    ``cone``, a box's centre keeps |x| <= cone·z so that the camera sees it."""
    boxes: list[tuple[Vec3, Vec3]] = []
    for _ in range(200 * count):
        if len(boxes) == count:
            break
        sx, sz = rng.uniform(*footprint), rng.uniform(*footprint)
        x0 = rng.uniform(region_lo[0], max(region_lo[0], region_hi[0] - sx))
        z0 = rng.uniform(region_lo[1], max(region_lo[1], region_hi[1] - sz))
        lo = (x0, floor_y - rng.uniform(*height), z0)
        hi = (x0 + sx, floor_y, z0 + sz)
        if hi[0] > region_hi[0] or hi[2] > region_hi[1]:
            continue
        if cone is not None and abs(x0 + sx / 2) > cone * (z0 + sz / 2):
            continue
        if _apart(lo, hi, boxes):
            boxes.append((lo, hi))
    return boxes


def _apart(lo: Vec3, hi: Vec3, boxes: list[tuple[Vec3, Vec3]], gap: float = 0.15) -> bool:
    """Whether the footprint [lo, hi] keeps ``gap`` metres from every box's footprint."""
    return all(hi[0] + gap < b[0][0] or b[1][0] + gap < lo[0]
               or hi[2] + gap < b[0][2] or b[1][2] + gap < lo[2] for b in boxes)


def _room_materials(rng: np.random.Generator, boxes: list[tuple[Vec3, Vec3]],
                    wall_textures: tuple[str, ...], family: np.random.Generator | None = None) -> list[Material]:
    """Materials for the six faces (walls tinted, floor, ceiling) and the boxes' faces; with ``family``
    (scene families) a wall may be textureless or repetitive instead."""
    materials = []
    tints = rng.permutation(len(_WALL_TINTS))
    for face in range(N_FACES):
        if face == 2:
            name, tint, repeat = "moon", _CEILING_TINT, 2.5
        elif face == 3:
            name = str(rng.choice(_FLOOR_TEXTURES))
            tint, repeat = _FLOOR_TINTS[rng.integers(len(_FLOOR_TINTS))], rng.uniform(1.0, 1.6)
        else:
            name, tint = str(rng.choice(wall_textures)), _WALL_TINTS[tints[face]]
            repeat = rng.uniform(1.3, 2.2)
            if family is not None:
                draw = family.random()
                if draw < TEXTURELESS_WALL:
                    name = FLAT
                elif draw < TEXTURELESS_WALL + REPETITIVE_WALL:
                    name, repeat = "brick", family.uniform(*REPETITIVE_REPEAT)
        materials.append(Material(texture_index(name), True, (1 / repeat, 0.0),
                                  (1 / repeat, 0.0), tint))
    photos = rng.permutation(len(PHOTO_TEXTURES))
    for k, (lo, hi) in enumerate(boxes):
        tile = texture_index(PHOTO_TEXTURES[photos[k % len(photos)]])
        for axis in range(3):
            a0, a1 = TANGENT_AXES[axis]
            s0, s1 = hi[a0] - lo[a0], hi[a1] - lo[a1]
            materials.append(Material(tile, False, (1 / s0, -lo[a0] / s0), (1 / s1, -lo[a1] / s1)))
    return materials


def _rect_material(rect: Rect, tile: int) -> Material:
    """Material stretching texture ``tile`` once over ``rect``."""
    (w, h) = rect.size
    return Material(tile, False, (1 / w, -rect.lo[0] / w), (1 / h, -rect.lo[1] / h))


def _depicted_scene(rng: np.random.Generator, room_lo: Vec3, room_hi: Vec3, picture: Rect,
                    viewpoint: np.ndarray) -> Scene:
    """The room the picture depicts, in world coordinates behind the picture's wall: seen
    from ``viewpoint`` through the canvas as through a window (a trompe-l'œil), with its far
    wall ``depth`` metres behind the wall and boxes on its floor in view of the canvas."""
    axis = picture.face // 2
    horizontal = TANGENT_AXES[axis][0]
    wall = room_hi[axis] if picture.face % 2 else room_lo[axis]
    outward = 1.0 if picture.face % 2 else -1.0
    depth = rng.uniform(4.0, 8.0)
    # Where the canvas's horizontal edges, seen from the viewpoint, land on the far wall.
    stretch = (abs(wall - viewpoint[axis]) + depth) / abs(wall - viewpoint[axis])
    far_edges = [viewpoint[horizontal] + (e - viewpoint[horizontal]) * stretch for e in
                 (picture.lo[0], picture.hi[0])]
    lo, hi = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
    lo[axis], hi[axis] = sorted((wall, wall + outward * depth))
    # Side walls somewhere between the canvas edges and the far-wall footprint, so that the
    # far wall is seen whole and the side walls partly or not at all.
    lo[horizontal] = picture.lo[0] - 0.1 - rng.uniform(0.3, 1.0) * max(
        0.0, picture.lo[0] - min(far_edges))
    hi[horizontal] = picture.hi[0] + 0.1 + rng.uniform(0.3, 1.0) * max(
        0.0, max(far_edges) - picture.hi[0])
    lo[1] = picture.lo[1] - rng.uniform(0.05, 0.4)
    hi[1] = picture.hi[1] + rng.uniform(0.05, 0.3)
    boxes: list[tuple[Vec3, Vec3]] = []
    for _ in range(200):
        if len(boxes) == 3:
            break
        # Stand a box on the floor somewhere along the sight line through the canvas's
        # lower edge, where the viewpoint sees it.
        bottom = face_point(room_lo, room_hi, picture.face,
                            picture.lo[0] + rng.uniform(0.15, 0.85) * picture.size[0],
                            picture.hi[1])
        heading = bottom - viewpoint
        heading[1] = 0.0
        heading /= np.linalg.norm(heading)
        centre = bottom + heading * rng.uniform(0.25, 0.8) * depth / abs(heading[axis])
        size = {horizontal: rng.uniform(0.3, 0.8), axis: rng.uniform(0.3, 0.8)}
        box_lo = _vec3((centre[0] - size[0] / 2,
                        hi[1] - rng.uniform(0.25, 0.6 * (hi[1] - lo[1])), centre[2] - size[2] / 2))
        box_hi = _vec3((centre[0] + size[0] / 2, hi[1], centre[2] + size[2] / 2))
        inside = all(lo[a] + 0.2 < box_lo[a] and box_hi[a] < hi[a] - 0.2 for a in (0, 2))
        if inside and _apart(box_lo, box_hi, boxes):
            boxes.append((box_lo, box_hi))
    materials = _room_materials(rng, boxes, ("brick", "gravel", "grass", "moon", "coins"))
    light = [0.0, lo[1] + 0.3, 0.0]
    light[horizontal] = (lo[horizontal] + hi[horizontal]) / 2
    light[axis] = wall + outward * depth * rng.uniform(0.2, 0.5)
    return Scene(_vec3(lo), _vec3(hi), tuple(boxes), (), tuple(materials), _vec3(light))


def sample_layout(seed: int, families: bool = False) -> Layout:
    """The layout for ``seed`` (deterministic); ``families``: with the scene families' frames, mirror
    sizes and walls (module constants FRAME_*, LARGE_MIRROR*, *_WALL)."""
    rng = np.random.default_rng(seed)
    family = np.random.default_rng([_FAMILY_STREAM, seed]) if families else None
    for _ in range(_ROOM_TRIES):
        layout = _try_layout(rng, family)
        if layout is not None:
            return layout
    raise RuntimeError(f"seed {seed}: no room with fully visible illusions; bounds are wrong")


def _frame(family: np.random.Generator | None, tint: tuple[float, float, float]) -> tuple[float, tuple[float, ...]]:
    """(width m, tint) of an illusion's frame: FRAME_M and ``tint`` without families, else from the one
    distribution every kind shares (width 0: no frame)."""
    if family is None:
        return FRAME_M, tint
    width = family.uniform(*FRAME_WIDTH_M) if family.random() < FRAME_PRESENT else 0.0
    return width, FRAME_TINTS[int(family.integers(len(FRAME_TINTS)))]


def _try_layout(rng: np.random.Generator, family: np.random.Generator | None = None) -> Layout | None:
    """A random layout, or None when the drawn room leaves no visible place for an illusion."""
    eye = rng.uniform(1.45, 1.65)
    room_lo = (-rng.uniform(2.0, 3.0), eye - rng.uniform(2.6, 3.0), -rng.uniform(0.8, 1.4))
    room_hi = (rng.uniform(2.0, 3.0), eye, rng.uniform(6.0, 8.5))
    trajectory = Trajectory(
        yaw0=math.radians(rng.uniform(-6, 6)),
        yaw_amplitude=math.radians(rng.uniform(2, 4)),
        pitch=math.radians(rng.uniform(2, 5)),
        sway_m=rng.uniform(0.05, 0.15),
        yaw_phase=rng.uniform(0, 2 * math.pi),
        sway_phase=rng.uniform(0, 2 * math.pi),
    )
    mirror_wall = family is not None and family.random() < MIRROR_WALL
    picture = None
    if mirror_wall:  # the picture on a side wall, if one holds it; else no mirrored wall
        picture = _place_illusion(rng, room_lo, room_hi, trajectory, (1.0, 1.8), (0.7, 1.1), None, _SIDE_FACES)
        mirror_wall = picture is not None
    if picture is None:
        picture = _place_illusion(rng, room_lo, room_hi, trajectory, (1.0, 1.8), (0.7, 1.1), None)
    if picture is None:
        return None
    mirror = _front_wall(room_lo, room_hi) if mirror_wall else None
    if mirror is None and family is not None and family.random() < LARGE_MIRROR:
        mirror = _place_illusion(rng, room_lo, room_hi, trajectory, *LARGE_MIRROR_M, picture)
    if mirror is None:  # (a large one may find no wall it fits whole in view: then a usual one)
        mirror = _place_illusion(rng, room_lo, room_hi, trajectory, (0.8, 1.4), (0.8, 1.1), picture)
    if mirror is None:
        return None
    # Boxes stand where the camera sees their base (the floor enters the view ~3.5 m ahead).
    region_lo = (room_lo[0] + 0.2, 3.5)
    region_hi = (room_hi[0] - 0.2, room_hi[2] - 0.4)
    boxes = _sample_boxes(rng, int(rng.integers(2, 4)), region_lo, region_hi, room_hi[1],
                          (0.4, 0.9), (0.35, MAX_BOX_HEIGHT_M), cone=0.45)
    materials = _room_materials(rng, boxes, _WALL_TEXTURES, family)
    flat = texture_index(FLAT)
    (picture_frame_m, picture_tint), (mirror_frame_m, mirror_tint) = (_frame(family, _PICTURE_FRAME_TINT),
                                                                      _frame(family, _MIRROR_FRAME_TINT))
    materials += [
        Material(flat, False, (0.0, 0.5), (0.0, 0.5), picture_tint),
        Material(flat, False, (0.0, 0.5), (0.0, 0.5), mirror_tint),
        _rect_material(picture, PICTURE_TILE),
        Material(flat, False, (0.0, 0.5), (0.0, 0.5)),
    ]
    light = (rng.uniform(-0.5, 0.5), room_lo[1] + 0.7, rng.uniform(1.5, 3.5))
    # A frame of width 0 is the canvas's own rect, which the canvas (a later rect) paints over: no frame.
    rects = (picture.grown(picture_frame_m), mirror.grown(mirror_frame_m), picture, mirror)
    scene = Scene(room_lo, room_hi, tuple(boxes), rects, tuple(materials), light,
                  mirror=N_FACES + 3 * len(boxes) + 3)
    # The picture is painted for an eye at the camera's mean position, level with the
    # canvas centre, so the camera sees it close to how it was meant to be seen.
    viewpoint = np.array([0.0, (picture.lo[1] + picture.hi[1]) / 2, 0.0])
    depicted = _depicted_scene(rng, room_lo, room_hi, picture, viewpoint)
    texels = tuple(int(np.clip(round(PICTURE_TEXELS_PER_M * s), 32, 2 * TILE))
                   for s in picture.size)
    return Layout(scene, depicted, picture, mirror, _vec3(viewpoint), texels, trajectory)
