"""What a generated sample is on disk: named outputs in the media store, keyed in ``Sample.files``.

One place defines the names, so generation, capture import, preview, export and import agree:

====================  =========================================================================
``left``              PNG, RGB uint8 HxWx3: the frame
``right``             PNG, RGB uint8 HxWx3: synthesized (inpainted) or captured right view
``disparity``         PFM, float32 HxW, pixels: the training target (scaled, rectified); NaN = no value
``disparity_rect``    PFM, float32 HxW, backend units: rectified monocular disparity, before scaling
``disparity_mono``    PFM, float32 HxW, backend units: monocular disparity as estimated
``holes``             PNG 0/255 HxW: right-view pixels no source landed on (inpainted)
``valid``             PNG 0/255 HxW: pixels with a trustworthy disparity (real captures)
``masks``             {"illusion_00": PNG 0/255, "support_00": PNG 0/255, …}: the regions used
====================  =========================================================================

Not every sample has every output (a real capture has no ``holes``; a synthesized one no ``valid``).
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from core.formats import decode_pfm, encode_pfm
from dataset.media import MediaStore

IMAGES = ("left", "right")
MAPS = ("disparity", "disparity_rect", "disparity_mono")
MASKS = ("holes", "valid")


def mask_name(kind: str, pair: int) -> str:
    """``illusion_00`` / ``support_00``: the key of a region mask in ``files["masks"]``."""
    return f"{kind}_{pair:02d}"


def _png(image: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", image)
    if not ok:
        raise ValueError("PNG encoding failed")
    return buf.tobytes()


def store_outputs(media: MediaStore, outputs: dict[str, Any]) -> dict[str, Any]:
    """Put arrays into the media store; returns the ``Sample.files`` dict of keys.

    ``outputs``: names from the table above → arrays (RGB images, float maps, bool masks), and
    ``masks`` → {name: bool HxW}.
    """
    files: dict[str, Any] = {}
    for name, value in outputs.items():
        if name in IMAGES:
            files[name] = media.put_bytes(_png(cv2.cvtColor(value, cv2.COLOR_RGB2BGR)), "png")
        elif name in MAPS:
            files[name] = media.put_bytes(encode_pfm(np.asarray(value, np.float32)), "pfm")
        elif name in MASKS:
            files[name] = media.put_bytes(_png(np.asarray(value, bool).astype(np.uint8) * 255), "png")
        elif name == "masks":
            files["masks"] = {k: media.put_bytes(_png(np.asarray(m, bool).astype(np.uint8) * 255), "png")
                              for k, m in value.items()}
        else:
            raise ValueError(f"unknown sample output {name!r}")
    return files


def load_output(media: MediaStore, key: str, name: str) -> np.ndarray:
    """One stored output back as an array (RGB uint8, float32 map, or bool mask)."""
    data = media.read_bytes(key)
    if name in MAPS:
        return decode_pfm(data, key)
    flags = cv2.IMREAD_COLOR if name in IMAGES else cv2.IMREAD_GRAYSCALE
    image = cv2.imdecode(np.frombuffer(data, np.uint8), flags)
    if image is None:
        raise ValueError(f"media file {key} is not a readable image")
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB) if name in IMAGES else image >= 128


def load_outputs(media: MediaStore, files: dict[str, Any]) -> dict[str, Any]:
    """All outputs of a sample as arrays (``masks`` as {name: bool HxW})."""
    out: dict[str, Any] = {name: load_output(media, key, name) for name, key in files.items() if name != "masks"}
    out["masks"] = {name: load_output(media, key, "mask") for name, key in files.get("masks", {}).items()}
    return out
