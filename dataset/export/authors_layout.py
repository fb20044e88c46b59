"""Names and paths of the authors' released layout (see DESIGN.md), shared by export and import.

Training data (web-sourced and generated videos)::

    video_frame_sequence/<video>/<title>/<frame>.png         left
    video_frame_sequence_right/<video>/<title>/<frame>.png   right
    depth_rect/<video>/<title>/<frame>.png                   uint16 round(d · 16), d before scaling
    sam_mask/<video>/<title>/<frame>-<obj:02d>-<obj2:02d>-<illusion|nonillusion>.png|jpg
    meta_data/scale_factors.csv                              <right path>,<scale> (training d = uint16 · scale)

Real test data (captures)::

    testing/{left,right}/<scene>_<obj>/frame_<id>.png
    testing/disp/<scene>_<obj>/frame_<id>.pfm               float32 px
    testing/mask/<scene>_<obj>/frame_<id>.png|jpg           255 = illusion ∧ valid depth
    meta_data/testing_enter.pkl                             {(scene, obj, id): {left, right, disp, mask}}
"""

from __future__ import annotations

import re

from dataset.export.records import SampleRecord

LEFT = "video_frame_sequence"
RIGHT = "video_frame_sequence_right"
DEPTH = "depth_rect"
MASKS = "sam_mask"
SCALES = "meta_data/scale_factors.csv"
TESTING = "testing"
TESTING_INDEX = "meta_data/testing_enter.pkl"
TESTING_PARTS = ("left", "right", "disp", "mask")
MASK_FORMATS = ("png", "jpg")

# obj = the pair; obj2 = a part of that object's mask: we write one part (00), import unites parts.
MASK_FILE = re.compile(r"(?P<frame>.+)-(?P<obj>\d+)-(?P<obj2>\d+)-(?P<word>illusion|nonillusion)\.(?:png|jpe?g)",
                       re.IGNORECASE)
KIND_WORDS = {"illusion": "illusion", "support": "nonillusion"}
FRAME_STEM = re.compile(r"frame_(\d+)")


def mask_file(frame: str, pair: int, kind: str, ext: str) -> str:
    """``frame_0001-00-00-illusion.png`` for pair 0's illusion mask (``nonillusion`` = support)."""
    return f"{frame}-{pair:02d}-00-{KIND_WORDS[kind]}.{ext}"


def is_capture(record: SampleRecord) -> bool:
    """Real captures go to the test layout, everything else to the training layout."""
    return record.provenance.get("source") == "capture"


def training_names(record: SampleRecord) -> tuple[str, str, str]:
    """(video, title, frame stem): the names an import recorded, else (video folder, the frame's
    illusion types joined by ``+`` — ``mirror+picture`` for a frame holding both —, ``frame_<index:04d>``)."""
    names = record.provenance.get("authors", {})
    if {"video", "title", "frame"} <= names.keys():
        return names["video"], names["title"], names["frame"]
    types = sorted(set((record.provenance.get("pair_types") or {}).values()) or {record.illusion_type or "unspecified"})
    return record.video_dir, "+".join(types), f"frame_{record.index:04d}"


def testing_names(record: SampleRecord) -> tuple[str, str, str]:
    """(scene, obj, id): the names an import recorded, else (video folder, ``00``, ``<index:06d>``)."""
    names = record.provenance.get("authors", {})
    if {"scene", "obj", "id"} <= names.keys():
        return names["scene"], names["obj"], names["id"]
    return record.video_dir, "00", f"{record.index:06d}"


def testing_paths(scene: str, obj: str, frame_id: str, mask_ext: str) -> dict[str, str]:
    """The index entry of one test frame: paths relative to ``testing/``."""
    folder = f"{scene}_{obj}"
    return {"left": f"left/{folder}/frame_{frame_id}.png", "right": f"right/{folder}/frame_{frame_id}.png",
            "disp": f"disp/{folder}/frame_{frame_id}.pfm", "mask": f"mask/{folder}/frame_{frame_id}.{mask_ext}"}
