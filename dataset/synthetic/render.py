"""Render synthetic illusion videos: exact stereo pairs and true / mono-fooled (ideal and
realistic) / stereo-fooled disparities with picture and mirror masks.

Images are supersampled (SUPERSAMPLE² rays per pixel, averaged) so that forward-warping the
left view with the true disparity reproduces the right view closely; the maps come from
one float64 ray through each pixel centre, so a plane's disparity is exactly a plane in
(u, v, d).

Ideal mono-fooled disparity (``mono_ideal``): inside the picture it is the depicted scene's
depth (the room behind the canvas, seen from the viewpoint the picture was painted for) measured
along the current camera's optical axis; inside the mirror it is the reflected room's virtual
depth, because a monocular network reads a mirror as an opening just as it reads a picture. A
picture seen *in* the mirror counts as part of the reflected room (its flat virtual surface).
Elsewhere it is the truth. The realistic one (``mono_disparity``) is made from it by :mod:`dataset.synthetic.mono`.
"""

from __future__ import annotations

import numpy as np

from dataset.synthetic.layout import (
    BASELINE_M,
    CANONICAL_F,
    CANONICAL_SIZE,
    FPS,
    SUPPORT_BAND_M,
    Layout,
    face_point,
    sample_layout,
)
from dataset.synthetic.mono import realistic_mono, sample_mono_model
from dataset.synthetic.raycast import TANGENT_AXES, View, cast, shade, trace
from dataset.synthetic.records import RegionPair, SyntheticFrame, SyntheticVideo
from dataset.synthetic.textures import Atlas, build_atlas

SUPERSAMPLE = 2
# A real mirror is slightly dark and cool.
_MIRROR_REFLECTANCE = np.array([0.86, 0.9, 0.93], np.float32)


def _to_uint8(rgb: np.ndarray, ss: int) -> np.ndarray:
    """Average ss×ss blocks of float RGB in [0, 1] and quantise to uint8."""
    h, w = rgb.shape[0] // ss, rgb.shape[1] // ss
    mean = rgb.reshape(h, ss, w, ss, 3).mean(axis=(1, 3))
    return np.clip(mean * 255 + 0.5, 0, 255).astype(np.uint8)


def _sample_coords(n: int, ss: int) -> np.ndarray:
    """Sub-pixel sample positions (float32, (n·ss,)) with pixel centres at integers."""
    return (np.arange(n * ss, dtype=np.float32) + 0.5) / ss - 0.5


def render_picture(layout: Layout) -> np.ndarray:
    """The picture's texture, float32 (h, w, 3) linear RGB: the depicted scene rendered
    through the canvas from ``layout.viewpoint``."""
    w, h = layout.picture_texels
    rect = layout.picture
    s = (np.arange(w * SUPERSAMPLE) + 0.5) / (w * SUPERSAMPLE)
    t = (np.arange(h * SUPERSAMPLE) + 0.5) / (h * SUPERSAMPLE)
    t0 = (rect.lo[0] + s * rect.size[0])[None, :]
    t1 = (rect.lo[1] + t * rect.size[1])[:, None]
    origin = _canvas_points(layout, t0, t1)
    direction = tuple((c - e).astype(np.float32) for c, e in zip(origin, layout.viewpoint))
    hits = cast(layout.depicted, tuple(c.astype(np.float32) for c in origin), direction)
    rgb = shade(layout.depicted, build_atlas(), hits)
    return rgb.reshape(h, SUPERSAMPLE, w, SUPERSAMPLE, 3).mean(axis=(1, 3)).astype(np.float32)


def _canvas_points(layout: Layout, t0: np.ndarray, t1: np.ndarray) -> tuple[np.ndarray, ...]:
    """World coordinates (three arrays of the broadcast shape) of canvas tangent coords."""
    rect, scene = layout.picture, layout.scene
    base = face_point(scene.room_lo, scene.room_hi, rect.face, 0.0, 0.0)
    horizontal, vertical = TANGENT_AXES[rect.face // 2]
    shape = np.broadcast_shapes(np.shape(t0), np.shape(t1))
    out = [np.full(shape, base[a]) for a in range(3)]
    out[horizontal] = np.broadcast_to(t0, shape).copy()
    out[vertical] = np.broadcast_to(t1, shape).copy()
    return tuple(out)


def _render_image(layout: Layout, atlas: Atlas, view: View, width: int, height: int) -> np.ndarray:
    """uint8 (H, W, 3) RGB image of the room seen by ``view``."""
    u, v = _sample_coords(width, SUPERSAMPLE), _sample_coords(height, SUPERSAMPLE)
    primary, final = trace(layout.scene, view, u, v)
    rgb = shade(layout.scene, atlas, final)
    rgb[primary.sid == layout.mirror_sid] *= _MIRROR_REFLECTANCE
    return _to_uint8(rgb, SUPERSAMPLE)


def _render_maps(layout: Layout, view: View, width: int, height: int,
                 baseline_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[RegionPair]]:
    """(true, ideal mono-fooled, stereo-fooled) float32 (H, W) disparities and the region pairs."""
    u, v = np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64)
    primary, final = trace(layout.scene, view, u, v)
    fb = view.f * baseline_m
    disparity = (fb / primary.t).astype(np.float32)
    stereo = (fb / final.t).astype(np.float32)
    mono = stereo.copy()
    on_picture = primary.sid == layout.picture_sid
    if on_picture.any():
        canvas = tuple(c[on_picture] for c in primary.p)
        depicted = cast(layout.depicted, canvas,
                        tuple(c - e for c, e in zip(canvas, layout.viewpoint)))
        depth = sum((p - c) * r for p, c, r in zip(depicted.p, view.center, view.rotation[:, 2]))
        mono[on_picture] = (fb / depth).astype(np.float32)
    regions = []
    for pair, (kind, rect, sid) in enumerate((
        ("picture", layout.picture, layout.picture_sid),
        ("mirror", layout.mirror, layout.mirror_sid),
    )):
        illusion = primary.sid == sid
        on_wall = primary.face == rect.face
        band = rect.grown(SUPPORT_BAND_M)
        support = on_wall & band.contains(primary.t0, primary.t1) & ~rect.contains(
            primary.t0, primary.t1)
        regions.append(RegionPair(pair, kind, kind, illusion, support))
    return disparity, mono, stereo, regions


def intrinsics(width: int, height: int) -> tuple[float, float, float]:
    """(f, cx, cy) in pixels: the canonical 640×360 field of view, widened along whichever
    axis the aspect ratio gives extra room, so the validated view is always inside."""
    f = CANONICAL_F * min(width / CANONICAL_SIZE[0], height / CANONICAL_SIZE[1])
    return f, (width - 1) / 2, (height - 1) / 2


def render_video(seed: int, n_frames: int = 12, width: int = 640,
                 height: int = 360, baseline_m: float = BASELINE_M, *, families: bool = False) -> SyntheticVideo:
    """Render ``n_frames`` frames (at FPS) of the synthetic room for ``seed``; deterministic.

    Pair 0 is the picture, pair 1 the mirror. The scene depends on ``seed`` (and ``families``: the scene
    families' frames, mirror sizes, walls and mirror-reading estimators, named ``synthetic-families-…``)
    only; the size only scales the view (see :func:`intrinsics`); ``baseline_m`` (metres) scales every
    disparity, e.g. to bring a test set into a model's training range.
    """
    if not baseline_m > 0:
        raise ValueError(f"baseline must be positive, got {baseline_m} m")
    if n_frames < 1 or width < 16 or height < 16:
        raise ValueError(f"need n_frames >= 1 and a size of at least 16x16, got "
                         f"{n_frames} frames of {width}x{height}")
    layout = sample_layout(seed, families)
    mono_model = sample_mono_model(seed, families)
    atlas = build_atlas((render_picture(layout),))
    f, cx, cy = intrinsics(width, height)
    frames = []
    for index in range(n_frames):
        time_s = index / FPS
        center, rotation = layout.trajectory.pose(time_s)
        left = View(center, rotation, f, cx, cy)
        right = View(center + baseline_m * rotation[:, 0], rotation, f, cx, cy)
        disparity, ideal, stereo, regions = _render_maps(layout, left, width, height, baseline_m)
        illusions = {r.kind: r.illusion for r in regions}
        mono, affine = realistic_mono(mono_model, seed, index, disparity, ideal, illusions["picture"],
                                      illusions["mirror"])
        frames.append(SyntheticFrame(
            index=index,
            time_s=time_s,
            left=_render_image(layout, atlas, left, width, height),
            right=_render_image(layout, atlas, right, width, height),
            disparity=disparity,
            mono_disparity=mono,
            mono_ideal=ideal,
            mono_affine=affine,
            stereo_disparity=stereo,
            regions=regions,
        ))
    name = f"synthetic-families-{seed:04d}" if families else f"synthetic-{seed:04d}"
    return SyntheticVideo(name=name, seed=seed, fps=FPS, fx=f, fy=f, cx=cx, cy=cy, baseline_m=baseline_m,
                          frames=frames, mono=mono_model, families=families)
