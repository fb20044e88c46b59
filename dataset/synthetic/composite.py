"""Real scenes with composited pictures: framed photographs on planar boards pasted into a real
stereo frame with true disparity, and the monocular disparity the synthetic scenes' estimator
model (:mod:`dataset.synthetic.mono`) reports for it. The proposers' real-scene benchmark.

A real scene is a left view and its true disparity (holes filled from the background side). A
composition places BOARDS boards on it, each a plane at the local near disparity (the
NEAR_PERCENTILE of the scene's disparity under it) with a slight tilt (TILT; its side that is nearer
looks that much larger) and roll (ROLL_DEG), carrying a photograph (scikit-image's bundled ones,
which load offline) in a frame FRAME_PX wide. The photograph's depicted disparity — what a
monocular network reads in it — is a smooth layout (far at the top, nearer at the bottom, a gentle
wave) at DEPICTED_RATIO of the board's. The monocular input is ``realistic_mono`` of a mono model
drawn from the composition's seed: the picture as painted, the rest distorted, blurred and opened,
under an unknown scale and shift. Untouched frames (no boards) come from the scene, its mirror
image and crops of it, through the same model.

Sizes are pixels at the Middlebury Motorcycle's 741×500; smaller scenes scale them down
(:func:`size_factor`). Everything is a function of the scene and the seed.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np
import skimage.data

from dataset.readers.base import StereoSample, resize_sample
from dataset.synthetic.mono import realistic_mono, sample_mono_model
from dataset.synthetic.records import RegionPair

REFERENCE_SIZE = (741, 500)  # (width, height) the pixel sizes below are given at
PICTURE_W = (80, 130)
PICTURE_H = (110, 170)
FRAME_PX = (24, 48)
BOARDS = 2
NEAR_PERCENTILE = 90
TILT = 0.08  # largest change of the board's disparity across its width or height, relative
ROLL_DEG = 4.0  # largest rotation of a board in the image
DEPICTED_RATIO = (0.35, 0.7)  # the depicted disparity over the board's
CROP_FRACTION = 0.7  # untouched crops: this share of the width and height, at the four corners
# Colour photographs shipped inside the scikit-image wheel (no download).
PHOTOS = ("astronaut", "coffee", "chelsea", "rocket", "hubble_deep_field", "immunohistochemistry", "retina")
FRAME_TINTS = ((0.45, 0.30, 0.16), (0.12, 0.12, 0.12), (0.92, 0.90, 0.86), (0.70, 0.55, 0.30), (0.55, 0.57, 0.60))
_STREAM = 0x636F6D70  # "comp": the composition's random numbers, apart from the mono model's
_PLACEMENT_TRIES = 200


@dataclass(frozen=True, eq=False)
class RealScene:
    """A real left view (uint8 (H, W, 3) RGB) and its true disparity (float32 (H, W), finite, > 0)."""

    name: str
    left: np.ndarray
    disparity: np.ndarray


@dataclass(frozen=True, eq=False)
class CompositeFrame:
    """A frame for the proposers: ``left`` (uint8 RGB), the true ``disparity`` (boards included),
    ``mono_ideal`` (the depicted disparity inside pictures, else the truth), ``mono_disparity``
    (what the estimator model reports), ``regions`` (one picture pair per board: the photograph
    and its frame; none for an untouched frame) and ``frame_px`` (each board's frame width)."""

    name: str
    left: np.ndarray
    disparity: np.ndarray
    mono_ideal: np.ndarray
    mono_disparity: np.ndarray
    regions: list[RegionPair]
    frame_px: list[int]


def motorcycle() -> RealScene:
    """scikit-image's Middlebury 2014 Motorcycle (741×500, shipped in the wheel; ``inf`` holes filled)."""
    left, _, disparity = skimage.data.stereo_motorcycle()
    return real_scene("motorcycle", left, disparity)


def scene_from_sample(sample: StereoSample) -> RealScene:
    """A reader's pair as a scene, shrunk to about the reference area (so that pictures keep their
    pixel sizes' meaning and a proposer its time); ValueError when it has no ground truth."""
    height, width = sample.disparity.shape
    factor = min(1.0, float(np.sqrt(REFERENCE_SIZE[0] * REFERENCE_SIZE[1] / (width * height))))
    sample = resize_sample(sample, factor)
    return real_scene(sample.name, sample.left, sample.disparity)


def real_scene(name: str, left: np.ndarray, disparity: np.ndarray) -> RealScene:
    """A scene from a real view and its disparity (NaN, ``inf`` or ≤ 0 = unknown, filled from the
    farther of the nearest known pixels to the left and right on its row: holes in a left view's
    disparity are mostly occlusions, which belong to the background); ValueError when none is known."""
    disparity = np.asarray(disparity, np.float32)
    known = np.isfinite(disparity) & (disparity > 0)
    if not known.any():
        raise ValueError(f"{name}: the disparity has no finite positive value")
    filled = _fill_rows(np.where(known, disparity, np.nan))
    filled = _fill_rows(filled.T).T  # rows with no known pixel take their column's neighbours
    return RealScene(name, np.ascontiguousarray(left[..., :3], np.uint8), filled.astype(np.float32))


def untouched_scenes(scene: RealScene) -> list[RealScene]:
    """The scene, its mirror image and four corner crops (CROP_FRACTION of each side)."""
    height, width = scene.disparity.shape
    h, w = round(CROP_FRACTION * height), round(CROP_FRACTION * width)
    mirror = RealScene(f"{scene.name}-mirror", scene.left[:, ::-1].copy(), scene.disparity[:, ::-1].copy())
    crops = [RealScene(f"{scene.name}-crop-{corner}", scene.left[y:y + h, x:x + w].copy(),
                       scene.disparity[y:y + h, x:x + w].copy())
             for corner, (y, x) in {"tl": (0, 0), "tr": (0, width - w), "bl": (height - h, 0),
                                    "br": (height - h, width - w)}.items()]
    return [scene, mirror, *crops]


def size_factor(scene: RealScene) -> float:
    """How much the reference pixel sizes shrink for this scene (1 at 741×500 and above)."""
    height, width = scene.disparity.shape
    return min(1.0, width / REFERENCE_SIZE[0], height / REFERENCE_SIZE[1])


def untouched_frame(scene: RealScene, seed: int) -> CompositeFrame:
    """The scene without boards, seen by the estimator model of ``seed``."""
    nothing = np.zeros(scene.disparity.shape, bool)
    mono, _ = realistic_mono(sample_mono_model(seed), seed, 0, scene.disparity, scene.disparity, nothing, nothing)
    return CompositeFrame(f"{scene.name}@{seed}", scene.left.copy(), scene.disparity.copy(), scene.disparity.copy(),
                          mono, [], [])


def compose(scene: RealScene, seed: int, boards: int = BOARDS) -> CompositeFrame:
    """``boards`` framed photographs on planar boards in ``scene`` (apart, fully inside) and the
    estimator model's view of it; deterministic in ``seed``. ValueError when they do not fit."""
    rng = np.random.default_rng([_STREAM, seed])
    height, width = scene.disparity.shape
    factor = size_factor(scene)
    left = scene.left.astype(np.float32) / 255
    truth = scene.disparity.astype(np.float64)
    ideal = truth.copy()
    taken = np.zeros((height, width), bool)
    v, u = np.mgrid[0:height, 0:width].astype(np.float64)
    regions, frames = [], []
    for pair in range(boards):
        frame_px = max(2, round(rng.integers(FRAME_PX[0], FRAME_PX[1] + 1) * factor))
        pw = max(8, round(rng.integers(PICTURE_W[0], PICTURE_W[1] + 1) * factor))
        ph = max(8, round(rng.integers(PICTURE_H[0], PICTURE_H[1] + 1) * factor))
        bw, bh = pw + 2 * frame_px, ph + 2 * frame_px
        roll, tilt = np.radians(rng.uniform(-ROLL_DEG, ROLL_DEG)), rng.uniform(-TILT, TILT, size=2)
        corners = _placed(rng, taken, bw, bh, roll, tilt, frame_px)
        if corners is None:
            raise ValueError(f"{scene.name}: no room for a {bw}×{bh} board ({pair + 1} of {boards}, seed {seed})")
        warp = cv2.getPerspectiveTransform(np.float32([[0, 0], [bw, 0], [bw, bh], [0, bh]]), corners)
        inner = np.zeros((bh, bw), np.float32)
        inner[frame_px:frame_px + ph, frame_px:frame_px + pw] = 1
        board_cover, picture_cover = (_warp(a, warp, width, height) for a in (np.ones((bh, bw), np.float32), inner))
        board, picture = board_cover > 0.5, picture_cover > 0.5
        taken |= board
        centre = corners.mean(axis=0)
        level = float(np.percentile(truth[board], NEAR_PERCENTILE))
        plane = level * (1 + tilt[0] * (u - centre[0]) / bw + tilt[1] * (v - centre[1]) / bh)
        truth[board] = ideal[board] = plane[board]
        # The depicted layout is the photograph's own: it moves with the picture, edges replicated.
        to_picture = warp @ np.array([[1, 0, frame_px], [0, 1, frame_px], [0, 0, 1]], np.float64)
        ratio = _warp(_depicted_ratio(rng, pw, ph).astype(np.float32), to_picture, width, height, cv2.BORDER_REPLICATE)
        ideal[picture] = plane[picture] * ratio[picture]
        texture = _frame_texture(rng, bh, bw)
        texture[frame_px:frame_px + ph, frame_px:frame_px + pw] = _photo(rng, pw, ph)
        left = left * (1 - board_cover[..., None]) + _warp(texture, warp, width, height)  # edges antialiased
        regions.append(RegionPair(pair, "picture", "picture", picture, board & ~picture))
        frames.append(frame_px)
    pictures = np.any([r.illusion for r in regions], axis=0) if regions else np.zeros((height, width), bool)
    truth, ideal = truth.astype(np.float32), ideal.astype(np.float32)
    mono, _ = realistic_mono(sample_mono_model(seed), seed, 0, truth, ideal, pictures, np.zeros_like(pictures))
    image = (np.clip(left, 0, 1) * 255 + 0.5).astype(np.uint8)
    return CompositeFrame(f"{scene.name}#{seed}", image, truth, ideal, mono, regions, frames)


def _placed(rng: np.random.Generator, taken: np.ndarray, bw: int, bh: int, roll: float, tilt: np.ndarray,
            frame_px: int) -> np.ndarray | None:
    """float32 (4, 2) image corners (x, y) of a ``bw``×``bh`` board rolled by ``roll`` and seen in the
    perspective of its ``tilt`` (a side ``tilt`` nearer is that much larger), inside the image and a
    frame's width away from every ``taken`` pixel (so no support band touches another board); None
    when no place was found."""
    height, width = taken.shape
    rect = np.array([[-bw, -bh], [bw, -bh], [bw, bh], [-bw, bh]], np.float64) / 2
    rotation = np.array([[np.cos(roll), -np.sin(roll)], [np.sin(roll), np.cos(roll)]])
    offsets = rect @ rotation.T
    offsets *= (1 + tilt[0] * offsets[:, :1] / bw + tilt[1] * offsets[:, 1:] / bh)
    low, high = offsets.min(axis=0), offsets.max(axis=0)
    if np.any(high - low + 2 > (width, height)):
        return None
    for _ in range(_PLACEMENT_TRIES):
        centre = rng.uniform(-low + 1, np.array([width, height]) - high - 1)
        x0, y0 = np.floor(centre + low).astype(int) - frame_px
        x1, y1 = np.ceil(centre + high).astype(int) + frame_px
        if not taken[max(0, y0):y1 + 1, max(0, x0):x1 + 1].any():
            return (centre + offsets).astype(np.float32)
    return None


def _warp(array: np.ndarray, warp: np.ndarray, width: int, height: int, border: int = cv2.BORDER_CONSTANT) -> np.ndarray:
    """``array`` (board or picture coordinates) seen through the homography ``warp``, bilinear."""
    return cv2.warpPerspective(array, warp, (width, height), flags=cv2.INTER_LINEAR, borderMode=border)


def _depicted_ratio(rng: np.random.Generator, pw: int, ph: int) -> np.ndarray:
    """float64 (ph, pw) in DEPICTED_RATIO: a photograph's depth layout over its board's disparity —
    far at the top, nearer towards the bottom (a ground), with a gentle wave (smooth: no edges)."""
    low = rng.uniform(DEPICTED_RATIO[0], DEPICTED_RATIO[1] - 0.1)
    high = rng.uniform(low + 0.05, DEPICTED_RATIO[1])
    y = np.linspace(0, 1, ph)[:, None]
    x = np.linspace(0, 1, pw)[None, :]
    kx, ky, phase = rng.uniform(0.3, 1.0), rng.uniform(0.3, 1.0), rng.uniform(0, 2 * np.pi)
    layout = 0.75 * y ** rng.uniform(0.7, 2.0) + 0.25 * (0.5 + 0.5 * np.cos(2 * np.pi * (kx * x + ky * y) + phase))
    return low + (high - low) * layout


def _frame_texture(rng: np.random.Generator, bh: int, bw: int) -> np.ndarray:
    """float32 (bh, bw, 3) in [0, 1]: a tinted frame with a faint grain."""
    tint = np.array(FRAME_TINTS[int(rng.integers(len(FRAME_TINTS)))], np.float32)
    grain = cv2.GaussianBlur(rng.normal(0, 1, (bh, bw)).astype(np.float32), (0, 0), 1.5)
    return np.clip(tint[None, None, :] * (1 + 0.06 * grain[..., None] / max(float(grain.std()), 1e-6)), 0, 1,
                   dtype=np.float32)


def _photo(rng: np.random.Generator, pw: int, ph: int) -> np.ndarray:
    """float32 (ph, pw, 3) in [0, 1]: a random window of a bundled photograph at the picture's aspect."""
    image = _photograph(PHOTOS[int(rng.integers(len(PHOTOS)))])
    height, width = image.shape[:2]
    scale = rng.uniform(0.5, 1.0) * min(width / pw, height / ph)
    cw, ch = max(1, int(pw * scale)), max(1, int(ph * scale))
    x, y = int(rng.integers(0, width - cw + 1)), int(rng.integers(0, height - ch + 1))
    return cv2.resize(image[y:y + ch, x:x + cw], (pw, ph), interpolation=cv2.INTER_AREA)


@functools.cache
def _photograph(name: str) -> np.ndarray:
    """float32 (H, W, 3) in [0, 1] (cached, read-only)."""
    image = np.asarray(getattr(skimage.data, name)())[..., :3].astype(np.float32) / 255
    image.flags.writeable = False
    return image


def _fill_rows(values: np.ndarray) -> np.ndarray:
    """NaNs replaced, per row, by the smaller of the nearest finite values to the left and right
    (the one side where there is one; a row without any stays NaN)."""
    known = np.isfinite(values)
    columns = np.arange(values.shape[1])[None, :]
    rows = np.arange(values.shape[0])[:, None]
    from_left = np.maximum.accumulate(np.where(known, columns, -1), axis=1)
    from_right = np.minimum.accumulate(np.where(known, columns, values.shape[1])[:, ::-1], axis=1)[:, ::-1]
    left = np.where(from_left >= 0, values[rows, np.clip(from_left, 0, None)], np.nan)
    right = np.where(from_right < values.shape[1], values[rows, np.clip(from_right, None, values.shape[1] - 1)], np.nan)
    filled = np.fmin(left, right)  # fmin: the known side when the other is NaN
    return np.where(known, values, filled)
