"""COCO-style annotations of a native export's split: one image per sample (its left view), one
annotation per region mask with a compressed RLE ``segmentation`` (pycocotools).

Categories are illusion/support per illusion type of the pair (``picture/illusion``,
``picture/support``, …, and ``unspecified/…`` for pairs without a type); each annotation also carries
``attributes: {pair, kind}`` so the pairs survive. The file is derived from the sample's mask
PNGs, which stay the source of truth for import.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from core.formats import mask_to_rle
from dataset.export.records import SampleRecord
from dataset.samples import mask_name
from dataset.tables import IllusionType, RegionKind

UNSPECIFIED = "unspecified"
TYPES = [t.value for t in IllusionType] + [UNSPECIFIED]
KINDS = [k.value for k in RegionKind]


def categories() -> list[dict[str, Any]]:
    """Every category, ids from 1 in a fixed order (types as in :class:`IllusionType`)."""
    return [{"id": 1 + t * len(KINDS) + k, "name": f"{type_}/{kind}", "supercategory": type_}
            for t, type_ in enumerate(TYPES) for k, kind in enumerate(KINDS)]


def category_id(illusion_type: str | None, kind: str) -> int:
    return 1 + TYPES.index(illusion_type or UNSPECIFIED) * len(KINDS) + KINDS.index(kind)


def pair_type(record: SampleRecord, pair: int) -> str | None:
    """The illusion type of one pair: what the sample recorded for it, else the frame's."""
    return (record.provenance.get("pair_types") or {}).get(mask_name("illusion", pair)) or record.illusion_type


def parse_mask_name(name: str) -> tuple[str, int]:
    """``illusion_00`` → ("illusion", 0): a region mask's kind and pair (see ``dataset.samples.mask_name``)."""
    kind, _, pair = name.rpartition("_")
    if kind not in KINDS or not pair.isdigit():
        raise ValueError(f"not a region mask name: {name!r}")
    return kind, int(pair)


def coco_document(split: str, images: list[tuple[SampleRecord, str]],
                  load_mask: Callable[[str], np.ndarray]) -> dict[str, Any]:
    """The COCO dict of one split: ``images`` are (record, left image path relative to the export root);
    ``load_mask`` turns a mask's media key into bool HxW."""
    doc: dict[str, Any] = {
        "info": {"description": f"Illusion Studio native export, split {split}", "version": "1"},
        "categories": categories(), "images": [], "annotations": [],
    }
    for image_id, (record, left_path) in enumerate(images, start=1):
        doc["images"].append({"id": image_id, "file_name": left_path, "width": record.width,
                              "height": record.height, "sample": record.name})
        for name, key in sorted(record.files.get("masks", {}).items()):
            kind, pair = parse_mask_name(name)
            mask = load_mask(key)
            doc["annotations"].append({
                "id": len(doc["annotations"]) + 1, "image_id": image_id,
                "category_id": category_id(pair_type(record, pair), kind),
                "segmentation": mask_to_rle(mask), "area": int(mask.sum()), "bbox": _bbox(mask), "iscrowd": 0,
                "attributes": {"pair": pair, "kind": kind},
            })
    return doc


def _bbox(mask: np.ndarray) -> list[float]:
    """COCO [x, y, width, height] of the mask's pixels ([0, 0, 0, 0] when empty)."""
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if rows.size == 0:
        return [0.0, 0.0, 0.0, 0.0]
    return [float(cols[0]), float(rows[0]), float(cols[-1] - cols[0] + 1), float(rows[-1] - rows[0] + 1)]
