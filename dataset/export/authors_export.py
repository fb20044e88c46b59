"""Export into the authors' released layout (names in ``authors_layout``).

Quantisation enters once: ``depth_rect`` holds round(d · 16) of the unscaled disparity d = disparity / s,
so d is off by at most 1/32, the training disparity (uint16 · s/16) by at most s/32 px. The scale
itself is written exactly (shortest round-trip decimal). Left and right images, and a capture's
PFM disparity, are copied byte for byte.
"""

from __future__ import annotations

import math
import pickle
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from core.formats import AUTHORS_FACTOR, write_authors_disparity, write_scale_factors
from dataset.export.authors_layout import (
    DEPTH,
    LEFT,
    MASKS,
    RIGHT,
    SCALES,
    TESTING,
    TESTING_INDEX,
    is_capture,
    mask_file,
    testing_names,
    testing_paths,
    training_names,
)
from dataset.export.coco import parse_mask_name
from dataset.export.errors import LayoutError
from dataset.export.records import Progress, SampleRecord
from dataset.export.staging import copy_file, write_bytes
from dataset.media import MediaStore
from dataset.samples import load_output

PICKLE_PROTOCOL = 4  # fixed, so the index file's bytes do not depend on the Python version


def export_authors(records: list[SampleRecord], media: MediaStore, root: Path, *, mask_format: str,
                   progress: Progress) -> dict[str, Any]:
    """Write ``records`` under the (empty, staged) folder ``root``; returns counts.

    ``mask_format``: ``png`` (lossless) or ``jpg`` (what the authors' tools wrote and expect).
    """
    scales: dict[str, float] = {}
    testing: dict[tuple[str, str, str], dict[str, str]] = {}
    zeroed = 0
    for done, record in enumerate(records, start=1):
        if is_capture(record):
            key, paths = _write_testing(record, media, root, mask_format)
            testing[key] = paths
        else:
            right, scale, invalid = _write_training(record, media, root, mask_format)
            scales[right] = scale
            zeroed += invalid
        progress(done, len(records), record.name)
    if scales:
        (root / SCALES).parent.mkdir(parents=True, exist_ok=True)
        write_scale_factors(root / SCALES, dict(sorted(scales.items())))
    if testing:
        write_bytes(root / TESTING_INDEX, pickle.dumps(dict(sorted(testing.items())), protocol=PICKLE_PROTOCOL))
    return {"samples": len(records), "training": len(scales), "testing": len(testing), "zeroed_disparity_px": zeroed}


def _write_training(record: SampleRecord, media: MediaStore, root: Path, mask_format: str) -> tuple[str, float, int]:
    """One training frame; returns (right image path for the CSV, scale s/16, pixels written as 0)."""
    video, title, frame = training_names(record)
    rel = f"{video}/{title}/{frame}.png"
    s = record.params.get("scale")
    if not (isinstance(s, int | float) and math.isfinite(s) and s > 0):
        raise LayoutError(f"sample {record.name}: params.scale is {s!r}; the authors' scale_factors.csv needs "
                          "the right view's disparity scale s > 0")
    copy_file(media.path(record.files["left"]), root / LEFT / rel)
    copy_file(media.path(record.files["right"]), root / RIGHT / rel)
    unscaled = load_output(media, record.files["disparity"], "disparity").astype(np.float64) / s
    # The format has no invalid marker: a pixel without a (positive) disparity becomes 0, "infinitely far".
    valid = np.isfinite(unscaled) & (unscaled >= 0)
    (root / DEPTH / rel).parent.mkdir(parents=True, exist_ok=True)
    write_authors_disparity(root / DEPTH / rel, np.where(valid, unscaled, 0.0))
    for name, key in sorted(record.files.get("masks", {}).items()):
        kind, pair = parse_mask_name(name)
        write_mask_as(root / MASKS / video / title / mask_file(frame, pair, kind, mask_format),
                      load_output(media, key, "mask"))
    return f"{RIGHT}/{rel}", s / AUTHORS_FACTOR, int((~valid).sum())


def _write_testing(record: SampleRecord, media: MediaStore, root: Path,
                   mask_format: str) -> tuple[tuple[str, str, str], dict[str, str]]:
    """One captured test frame; returns its index key and entry."""
    key = testing_names(record)
    paths = testing_paths(*key, mask_format)
    base = root / TESTING
    copy_file(media.path(record.files["left"]), base / paths["left"])
    copy_file(media.path(record.files["right"]), base / paths["right"])
    copy_file(media.path(record.files["disparity"]), base / paths["disp"])
    disparity = load_output(media, record.files["disparity"], "disparity")
    mask = np.isfinite(disparity) & illusion_union(media, record, disparity.shape)
    if "valid" in record.files:
        mask &= load_output(media, record.files["valid"], "valid")
    write_mask_as(base / paths["mask"], mask)
    return key, paths


def illusion_union(media: MediaStore, record: SampleRecord, shape: tuple[int, ...]) -> np.ndarray:
    """The union of a sample's illusion masks, bool HxW (all False without any)."""
    union = np.zeros(shape, bool)
    for name, key in record.files.get("masks", {}).items():
        if parse_mask_name(name)[0] == "illusion":
            union |= load_output(media, key, "mask")
    return union


def write_mask_as(path: Path, mask: np.ndarray) -> None:
    """A 0/255 mask as PNG, or as the authors' JPEG (quality 100; readers threshold at 128)."""
    params = [cv2.IMWRITE_JPEG_QUALITY, 100] if path.suffix == ".jpg" else []
    ok, data = cv2.imencode(path.suffix, mask.astype(np.uint8) * 255, params)
    if not ok:
        raise LayoutError(f"{path}: could not encode the mask")
    write_bytes(path, data.tobytes())
