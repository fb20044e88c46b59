"""Texture tiles from scikit-image's bundled photographs, packed into one float atlas.

Only images shipped inside the scikit-image wheel are used (they load offline); the ones
that need the optional ``pooch`` download (``eagle``, ``skin``, …) are avoided. All tiles
live in a single float32 RGB atlas so that one ``cv2.remap`` call textures a whole frame.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np
import skimage.data

TILE = 256
# One texel of padding around every tile so that bilinear taps at a tile's edge read the
# wrapped (repeating textures) or clamped (pictures) neighbour instead of the next tile.
_PAD = 1
_COLUMNS = 4

# Greyscale photographs used as wall, floor and ceiling materials (tinted per surface).
SURFACE_TEXTURES = ("brick", "gravel", "grass", "moon", "coins")
# Colour photographs printed on boxes.
PHOTO_TEXTURES = (
    "astronaut",
    "coffee",
    "chelsea",
    "rocket",
    "hubble_deep_field",
    "immunohistochemistry",
    "colorwheel",
    "cat",
)
# A near-uniform tile for picture and mirror frames.
FLAT = "flat"
BASE_TEXTURES = (*SURFACE_TEXTURES, *PHOTO_TEXTURES, FLAT)

# Wall-like materials are shown at reduced contrast around a light mean so that the tint,
# not the photograph's exposure, sets a surface's brightness.
_SURFACE_MEAN = 0.72
_SURFACE_CONTRAST = 0.55


@dataclass(frozen=True)
class Atlas:
    """``image``: float32 (Ha, Wa, 3) in [0, 1]; ``tiles``: per tile (x0, y0, w, h) in texels,
    the tile's interior starting at (x0 + 1, y0 + 1) inside its one-texel border."""

    image: np.ndarray
    tiles: tuple[tuple[int, int, int, int], ...]


def _load(name: str) -> np.ndarray:
    """A square float32 RGB tile (TILE, TILE, 3) in [0, 1] for texture ``name``."""
    if name == FLAT:
        rng = np.random.default_rng(0)
        noise = cv2.GaussianBlur(rng.normal(0.0, 1.0, (TILE, TILE)).astype(np.float32), (0, 0), 3)
        grey = 0.85 + 0.05 * noise / noise.std()
        return np.repeat(grey[..., None], 3, axis=2).clip(0, 1).astype(np.float32)
    img = np.asarray(getattr(skimage.data, name)())
    h, w = img.shape[:2]
    side = min(h, w)
    img = img[(h - side) // 2 : (h - side) // 2 + side, (w - side) // 2 : (w - side) // 2 + side]
    img = cv2.resize(img, (TILE, TILE), interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0
    if img.ndim == 2:
        # Surface textures repeat; mirrored copies make the tile periodic without seams.
        img = np.block([[img, img[:, ::-1]], [img[::-1], img[::-1, ::-1]]])
        img = cv2.resize(img, (TILE, TILE), interpolation=cv2.INTER_AREA)
        img = _SURFACE_MEAN + _SURFACE_CONTRAST * (img - img.mean())
        img = np.repeat(img[..., None], 3, axis=2)
    return img[..., :3].clip(0, 1).astype(np.float32)


@functools.cache
def base_tiles() -> tuple[np.ndarray, ...]:
    """The BASE_TEXTURES tiles, in that order (cached, read-only)."""
    tiles = tuple(_load(name) for name in BASE_TEXTURES)
    for tile in tiles:
        tile.flags.writeable = False
    return tiles


def texture_index(name: str) -> int:
    """Index of a base texture in every atlas built by :func:`build_atlas`."""
    return BASE_TEXTURES.index(name)


def build_atlas(extra: tuple[np.ndarray, ...] = ()) -> Atlas:
    """Pack the base tiles (wrap-padded, indices as BASE_TEXTURES) and then ``extra`` images
    (edge-padded, float32 (h, w, 3), indices continuing after the base tiles)."""
    padded = [np.pad(t, ((_PAD, _PAD), (_PAD, _PAD), (0, 0)), mode="wrap") for t in base_tiles()]
    padded += [np.pad(e, ((_PAD, _PAD), (_PAD, _PAD), (0, 0)), mode="edge") for e in extra]
    cell = TILE + 2 * _PAD
    rows = -(-len(base_tiles()) // _COLUMNS)
    width = max([_COLUMNS * cell] + [p.shape[1] for p in padded])
    height = rows * cell + sum(p.shape[0] for p in padded[len(base_tiles()) :])
    image = np.zeros((height, width, 3), np.float32)
    tiles = []
    for i, tile in enumerate(padded[: len(base_tiles())]):
        y0, x0 = (i // _COLUMNS) * cell, (i % _COLUMNS) * cell
        image[y0 : y0 + cell, x0 : x0 + cell] = tile
        tiles.append((x0, y0, TILE, TILE))
    y0 = rows * cell
    for tile in padded[len(base_tiles()) :]:
        image[y0 : y0 + tile.shape[0], : tile.shape[1]] = tile
        tiles.append((0, y0, tile.shape[1] - 2 * _PAD, tile.shape[0] - 2 * _PAD))
        y0 += tile.shape[0]
    return Atlas(image=image, tiles=tuple(tiles))
