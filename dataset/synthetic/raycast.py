"""Vectorised ray casting in an axis-aligned room with boxes, wall rectangles and one mirror.

World frame: metres, x right, y **down**, z forward (the camera frame at zero yaw and
pitch), so the floor is the room's max-y face and the ceiling its min-y face. Rays are
component triples ``(x, y, z)`` of arrays (origins may be Python floats); a hit's ``t`` is in
units of the ray direction's length, so a primary ray whose direction has a unit component
along the camera's optical axis reports ``t`` = camera depth, and a mirror-bounced ray (the
reflection keeps the direction's length) reports the depth of its virtual, unfolded point.

Surface ids: room faces ``0..5`` (``2·axis + side``, side 1 = the max bound), box ``k``'s
faces ``6 + 3k + axis``, then one id per entry of ``Scene.rects`` in order.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from dataset.synthetic.textures import Atlas

# Tangent (texture) axes of a face whose normal is along axis 0, 1, 2.
TANGENT_AXES = ((2, 1), (0, 2), (0, 1))
FLOOR_FACE = 3
N_FACES = 6
_EPS = 1e-6
# Lighting: ambient + Lambert from one point light with a soft distance fall-off (m).
_AMBIENT = 0.3
_DIFFUSE = 0.95
_FALLOFF_M = 6.0
# Boxes darken the floor around their footprint (a view-independent contact shadow).
_CONTACT_DARKENING = 0.5
_CONTACT_RANGE_M = 0.12


Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class Rect:
    """Rectangle on room face ``face``: ``lo``/``hi`` bound its two tangent coordinates (m)."""

    face: int
    lo: tuple[float, float]
    hi: tuple[float, float]

    def grown(self, margin: float) -> Rect:
        """The rectangle enlarged by ``margin`` metres on every side."""
        return Rect(self.face, (self.lo[0] - margin, self.lo[1] - margin),
                    (self.hi[0] + margin, self.hi[1] + margin))

    def contains(self, t0: np.ndarray, t1: np.ndarray) -> np.ndarray:
        """Bool array: tangent coordinates (t0, t1) lie inside (boundary included)."""
        return (t0 >= self.lo[0]) & (t0 <= self.hi[0]) & (t1 >= self.lo[1]) & (t1 <= self.hi[1])

    @property
    def size(self) -> tuple[float, float]:
        """Extent (m) along the two tangent axes."""
        return self.hi[0] - self.lo[0], self.hi[1] - self.lo[1]


@dataclass(frozen=True)
class Material:
    """Texture ``tile`` of the atlas, addressed by s = t0·s_map[0] + s_map[1] and
    t = t1·t_map[0] + t_map[1] (t0, t1: tangent coordinates in m); repeating if ``wrap`` else
    clamped to [0, 1]; ``tint`` multiplies the texture (linear RGB)."""

    tile: int
    wrap: bool
    s_map: tuple[float, float]
    t_map: tuple[float, float]
    tint: Vec3 = (1.0, 1.0, 1.0)


@dataclass(frozen=True)
class Scene:
    """An axis-aligned room ``[room_lo, room_hi]`` (m) holding axis-aligned ``boxes``
    ((lo, hi) pairs) and ``rects`` painted on its faces (a later rect overrides an earlier
    one where they overlap); ``materials`` is indexed by surface id; ``mirror`` is the
    surface id of the one reflecting rect, or -1."""

    room_lo: Vec3
    room_hi: Vec3
    boxes: tuple[tuple[Vec3, Vec3], ...]
    rects: tuple[Rect, ...]
    materials: tuple[Material, ...]
    light: Vec3
    mirror: int = -1

    def rect_sid(self, index: int) -> int:
        """Surface id of ``rects[index]``."""
        return N_FACES + 3 * len(self.boxes) + index


@dataclass
class Hits:
    """Per-ray hit record (all arrays of the rays' shape): ``t`` ray parameter, ``sid``
    surface id, ``face`` room face id (-1 on boxes), ``axis`` normal axis, ``normal_sign``
    ±1 (the normal points along ``normal_sign · e_axis``), ``p`` hit point (m), ``t0``/``t1``
    tangent coordinates (m)."""

    t: np.ndarray
    sid: np.ndarray
    face: np.ndarray
    axis: np.ndarray
    normal_sign: np.ndarray
    p: tuple[np.ndarray, np.ndarray, np.ndarray]
    t0: np.ndarray
    t1: np.ndarray

    def assign(self, where: np.ndarray, other: Hits, t_offset: np.ndarray) -> None:
        """Overwrite the rays selected by bool ``where`` with the flat ``other`` hits, adding
        ``t_offset`` (the path already travelled) to their ``t``."""
        self.t[where] = other.t + t_offset
        for name in ("sid", "face", "axis", "normal_sign", "t0", "t1"):
            getattr(self, name)[where] = getattr(other, name)
        for mine, theirs in zip(self.p, other.p):
            mine[where] = theirs

    def copy(self) -> Hits:
        """A deep copy."""
        return Hits(self.t.copy(), self.sid.copy(), self.face.copy(), self.axis.copy(),
                    self.normal_sign.copy(), tuple(c.copy() for c in self.p), self.t0.copy(),
                    self.t1.copy())


def _pick(axis: np.ndarray, c: tuple[np.ndarray, ...]) -> np.ndarray:
    return np.where(axis == 0, c[0], np.where(axis == 1, c[1], c[2]))


def cast(
    scene: Scene,
    o: tuple[float | np.ndarray, ...],
    d: tuple[np.ndarray, np.ndarray, np.ndarray],
    windows: list[tuple[slice, slice] | None] | None = None,
) -> Hits:
    """Nearest hit of rays ``o + t·d`` (t > 0) with the scene; every ray hits (closed room).

    ``o``: three floats or arrays broadcastable to ``d``'s shape; ``d``: three same-shape
    float arrays (dtype sets the precision). ``windows`` (one per box, only with float
    origins): the 2-D index window of rays that may hit that box, or None for all rays —
    the caller's screen-space culling.
    """
    shape = d[0].shape
    t = np.full(shape, np.inf, d[0].dtype)
    axis = np.zeros(shape, np.int8)
    face = np.zeros(shape, np.int8)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = [1.0 / c for c in d]
        for a in range(3):
            forward = d[a] > 0
            ta = np.where(forward, scene.room_hi[a] - o[a], scene.room_lo[a] - o[a]) * inv[a]
            # ta >= 0 also rejects the NaN / -inf of rays parallel to this face pair.
            better = (ta >= 0) & (ta < t)
            t = np.where(better, ta, t)
            axis[better] = a
            face[better] = 2 * a + forward[better]
        sid = face.astype(np.int16)
        for k, (lo, hi) in enumerate(scene.boxes):
            window = windows[k] if windows is not None else None
            sl = window if window is not None else ...
            ii = [c[sl] for c in inv]
            oo = [c if np.ndim(c) == 0 else c[sl] for c in o]
            for a in range(3):
                t_lo, t_hi = (lo[a] - oo[a]) * ii[a], (hi[a] - oo[a]) * ii[a]
                near, far = np.minimum(t_lo, t_hi), np.maximum(t_lo, t_hi)
                if a == 0:
                    t_near, t_far, ax = near, far, np.zeros(near.shape, np.int8)
                else:
                    ax = np.where(near > t_near, np.int8(a), ax)
                    t_near, t_far = np.maximum(t_near, near), np.minimum(t_far, far)
            t_win = t[sl]
            hit = (t_near <= t_far) & (t_near > _EPS) & (t_near < t_win)
            t_win[hit] = t_near[hit]
            axis[sl][hit] = ax[hit]
            face[sl][hit] = -1
            sid[sl][hit] = N_FACES + 3 * k + ax[hit]
    p = tuple(o[a] + t * d[a] for a in range(3))
    normal_sign = np.where(_pick(axis, d) > 0, np.int8(-1), np.int8(1))
    t0 = np.where(axis == 0, p[2], p[0])
    t1 = np.where(axis == 1, p[2], p[1])
    for j, rect in enumerate(scene.rects):
        sid[(face == rect.face) & rect.contains(t0, t1)] = scene.rect_sid(j)
    return Hits(t, sid, face, axis, normal_sign, p, t0, t1)


def shade(scene: Scene, atlas: Atlas, hits: Hits) -> np.ndarray:
    """Linear RGB float32 (..., 3) of 2-D hit arrays: bilinear texture × tint × lighting.

    Lighting depends on the surface point only (Lambert), so two views of a point agree.
    """
    n = len(scene.materials)
    table = np.zeros((n, 8), np.float32)
    tint = np.zeros((n, 3), np.float32)
    wrap = np.zeros(n, bool)
    for i, m in enumerate(scene.materials):
        x0, y0, w, h = atlas.tiles[m.tile]
        # +1 skips the tile's padding texel, -0.5 maps texel centres to integer coordinates.
        table[i] = (x0 + 0.5, y0 + 0.5, w, h, *m.s_map, *m.t_map)
        tint[i] = m.tint
        wrap[i] = m.wrap
    row = table[hits.sid]
    s = hits.t0 * row[..., 4] + row[..., 5]
    tt = hits.t1 * row[..., 6] + row[..., 7]
    rep = wrap[hits.sid]
    s = np.where(rep, s - np.floor(s), np.clip(s, 0, 1))
    tt = np.where(rep, tt - np.floor(tt), np.clip(tt, 0, 1))
    map_x = (row[..., 0] + s * row[..., 2]).astype(np.float32)
    map_y = (row[..., 1] + tt * row[..., 3]).astype(np.float32)
    texture = cv2.remap(atlas.image, map_x, map_y, cv2.INTER_LINEAR,
                        borderMode=cv2.BORDER_REPLICATE)

    to_light = [scene.light[a] - hits.p[a] for a in range(3)]
    dist2 = to_light[0] ** 2 + to_light[1] ** 2 + to_light[2] ** 2
    cos = np.maximum(hits.normal_sign * _pick(hits.axis, tuple(to_light)), 0) / np.sqrt(dist2)
    light = (_AMBIENT + _DIFFUSE * cos / (1 + dist2 / _FALLOFF_M**2)).astype(np.float32)
    floor = hits.sid == FLOOR_FACE
    if scene.boxes and floor.any():
        x, z = hits.p[0][floor], hits.p[2][floor]
        occlusion = np.ones(x.shape, np.float32)
        for lo, hi in scene.boxes:
            ex = np.maximum(np.maximum(lo[0] - x, x - hi[0]), 0)
            ez = np.maximum(np.maximum(lo[2] - z, z - hi[2]), 0)
            occlusion *= 1 - _CONTACT_DARKENING * np.exp(-np.hypot(ex, ez) / _CONTACT_RANGE_M)
        light[floor] *= occlusion
    return texture * tint[hits.sid] * light[..., None]


@dataclass(frozen=True)
class View:
    """A pinhole camera: ``center`` (m, world), ``rotation`` camera-to-world (3, 3) whose
    columns are the camera's x (right), y (down), z (forward) axes; focal ``f`` and principal
    point ``cx``, ``cy`` in pixels (pixel centres at integer coordinates)."""

    center: np.ndarray
    rotation: np.ndarray
    f: float
    cx: float
    cy: float


def _box_windows(scene: Scene, view: View, u: np.ndarray, v: np.ndarray) -> list:
    """Per box, the (rows, cols) window of the (v, u) ray grid its projection can cover."""
    windows: list[tuple[slice, slice] | None] = []
    for lo, hi in scene.boxes:
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                            for z in (lo[2], hi[2])])
        cam = (corners - view.center) @ view.rotation
        if cam[:, 2].min() <= 1e-3:
            windows.append(None)
            continue
        pu = view.f * cam[:, 0] / cam[:, 2] + view.cx
        pv = view.f * cam[:, 1] / cam[:, 2] + view.cy
        cols = slice(np.searchsorted(u, pu.min() - 1), np.searchsorted(u, pu.max() + 1, "right"))
        rows = slice(np.searchsorted(v, pv.min() - 1), np.searchsorted(v, pv.max() + 1, "right"))
        windows.append((rows, cols))
    return windows


def trace(scene: Scene, view: View, u: np.ndarray, v: np.ndarray) -> tuple[Hits, Hits]:
    """Primary and final hits of the rays through pixel coordinates ``u`` (W,) × ``v`` (H,)
    (sorted 1-D float arrays; their dtype sets the precision), as (H, W) arrays.

    Primary ``t`` is camera depth. The final hits equal the primary ones except where the
    primary ray meets the mirror: there the ray reflects once and the final ``t`` is the
    camera depth of the virtual point (the true hit mirrored back through the glass plane).
    """
    x = ((u - view.cx) / view.f)[None, :]
    y = ((v - view.cy) / view.f)[:, None]
    r = [[float(c) for c in row] for row in view.rotation]
    d = tuple(r[a][0] * x + r[a][1] * y + np.asarray(r[a][2], u.dtype) for a in range(3))
    o = tuple(float(c) for c in view.center)
    primary = cast(scene, o, d, _box_windows(scene, view, u, v))
    final = primary
    if scene.mirror >= 0:
        on_mirror = primary.sid == scene.mirror
        if on_mirror.any():
            final = primary.copy()
            mirror_axis = scene.rects[scene.mirror - scene.rect_sid(0)].face // 2
            bounce_d = tuple(-c[on_mirror] if a == mirror_axis else c[on_mirror]
                             for a, c in enumerate(d))
            bounce = cast(scene, tuple(c[on_mirror] for c in primary.p), bounce_d)
            final.assign(on_mirror, bounce, primary.t[on_mirror])
    return primary, final
