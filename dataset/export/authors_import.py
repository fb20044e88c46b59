"""Validated reading of the authors' released layout (names in ``authors_layout``).

Training frames are listed by ``meta_data/scale_factors.csv`` (their loader's index; absolute
paths such as ``/data2/Fooling3D/video_frame_sequence_right/…`` are cut at the folder name), test
frames by ``testing_enter.pkl`` (in ``meta_data/``, paths relative to ``testing/`` or, as in the
authors' tree, ``real_data/testing/``). Masks are read as PNG or JPEG, thresholded at 128.
Imported samples are accepted; the names they came with are kept in ``provenance.authors``, so
an authors' export of them uses the same names. The layout has no frame times: they are 0.
"""

from __future__ import annotations

import hashlib
import pickle
from collections import defaultdict
from functools import partial
from pathlib import Path, PurePosixPath
from typing import Any

import numpy as np

from core.formats import AUTHORS_FACTOR, FormatError, read_authors_disparity, read_mask, read_pfm, read_scale_factors
from dataset.export.authors_layout import (
    DEPTH,
    FRAME_STEM,
    LEFT,
    MASK_FILE,
    MASKS,
    RIGHT,
    SCALES,
    TESTING,
    TESTING_INDEX,
    TESTING_PARTS,
)
from dataset.export.errors import LayoutError
from dataset.export.probe import check_shape, raster_shape
from dataset.export.records import PendingSample, Progress, SampleRecord, VideoInfo
from dataset.media import MediaStore
from dataset.samples import mask_name, store_outputs

TESTING_ROOTS = (TESTING, f"real_data/{TESTING}")


def read_authors(root: Path, progress: Progress) -> list[PendingSample]:
    """Validate the authors' dataset at ``root`` completely (every listed file present, sizes agree)
    before anything is imported; raises :class:`LayoutError` naming the first problem."""
    root = Path(root).absolute()
    if not root.is_dir():
        raise LayoutError(f"{root}: no such folder")
    scales, index = root / SCALES, root / TESTING_INDEX
    if not scales.is_file() and not index.is_file():
        raise LayoutError(f"{root}: neither {SCALES} nor {TESTING_INDEX}; not the authors' layout "
                          "(a native export imports with --format native)")
    entries: list[tuple[str, Any]] = []
    if scales.is_file():
        try:
            factors = read_scale_factors(scales)
        except FormatError as exc:
            raise LayoutError(str(exc)) from None
        entries += [(right, partial(_training, root, right, scale)) for right, scale in factors.items()]
    if index.is_file():
        entries += [(f"{scene}/{obj}/{frame_id}", partial(_testing, root, paths, (scene, obj, frame_id)))
                    for (scene, obj, frame_id), paths in load_testing_index(index).items()]
    pending = []
    for done, (name, check) in enumerate(entries, start=1):
        pending.append(PendingSample(name, check()))
        progress(done, len(entries), name)
    return pending


# --- training frames -------------------------------------------------------------------------

def _within(root: Path, paths: dict[str, Path], what: str) -> dict[str, Path]:
    """The paths, if every one stays inside the dataset folder (an index could name any file)."""
    top = root.resolve()
    for path in paths.values():
        if not path.resolve().is_relative_to(top):
            raise LayoutError(f"{what}: {path} leaves the dataset folder {root}")
    return paths


def _training(root: Path, right_entry: str, scale: float) -> Any:
    """Check one CSV line's files; returns the function that stores them."""
    parts = PurePosixPath(right_entry.replace("\\", "/")).parts
    if RIGHT not in parts or len(parts) - parts.index(RIGHT) != 4:
        raise LayoutError(f"{root / SCALES}: {right_entry!r} is not a {RIGHT}/<video>/<title>/<frame>.png path")
    video, title, name = parts[parts.index(RIGHT) + 1:]
    stem = PurePosixPath(name).stem
    frame = FRAME_STEM.fullmatch(stem)
    if frame is None:
        raise LayoutError(f"{root / SCALES}: {right_entry!r}: frame files are named frame_<number>.png")
    rel = Path(video, title, name)
    paths = _within(root, {"left": root / LEFT / rel, "right": root / RIGHT / rel, "depth": root / DEPTH / rel},
                    f"{SCALES} line {right_entry!r}")
    masks = _masks(root / MASKS / video / title, stem)
    height, width = _check_files(paths, {"left": 3, "right": 3, "depth": 1}, masks, f"{SCALES} line {right_entry!r}")
    info = VideoInfo(name=f"{video}/{title}", source_kind="web", illusion_types=[],
                     content_sha256=_key("training", video, title), fps=None, width=width, height=height,
                     meta={"authors": {"video": video, "title": title}})
    return partial(_store_training, info, int(frame.group(1)), (height, width), paths, masks, scale,
                   {"video": video, "title": title, "frame": stem})


def _masks(folder: Path, stem: str) -> dict[str, list[Path]]:
    """{mask name: its part files} of one frame: obj → pair, obj2 parts united, nonillusion → support."""
    masks: dict[str, list[Path]] = defaultdict(list)
    for path in sorted(folder.glob("*-*-*-*")) if folder.is_dir() else []:
        match = MASK_FILE.fullmatch(path.name)
        if match and match["frame"] == stem:
            kind = "illusion" if match["word"].lower() == "illusion" else "support"
            masks[mask_name(kind, int(match["obj"]))].append(path)
    return dict(sorted(masks.items()))


def _store_training(info: VideoInfo, index: int, shape: tuple[int, int], paths: dict[str, Path],
                    masks: dict[str, list[Path]], scale: float, names: dict[str, str],
                    media: MediaStore) -> SampleRecord:
    raw = read_authors_disparity(paths["depth"], 1.0)  # the uint16 values, exactly, as float32
    files = store_outputs(media, {
        "disparity": raw * np.float32(scale), "disparity_rect": raw / np.float32(AUTHORS_FACTOR),
        "masks": {name: np.logical_or.reduce([read_mask(p) for p in parts]) for name, parts in masks.items()},
    })
    files.update(left=media.put_file(paths["left"]), right=media.put_file(paths["right"]))
    return _record(info, index, shape, files, annotated=bool(masks), params={"scale": scale * AUTHORS_FACTOR},
                   provenance={"source": "synthesized", "imported_from": "authors", "authors": names})


# --- test frames (real captures) -------------------------------------------------------------

class _PlainData(pickle.Unpickler):
    """Unpickles dicts, tuples, lists and strings only: a pickle can otherwise run any code."""

    def find_class(self, module: str, name: str) -> Any:
        raise pickle.UnpicklingError(f"refusing to load {module}.{name}: the index holds plain data only")


def load_testing_index(path: Path) -> dict[tuple[str, str, str], dict[str, str]]:
    """``testing_enter.pkl`` as {(scene, obj, id): {left, right, disp, mask: path}}, read as plain data only."""
    try:
        with path.open("rb") as fh:
            data = _PlainData(fh).load()
    except (OSError, pickle.UnpicklingError, EOFError, ValueError) as exc:
        raise LayoutError(f"{path}: not a readable index pickle: {exc}") from None
    ok = isinstance(data, dict) and all(
        isinstance(k, tuple) and len(k) == 3 and all(isinstance(p, str) for p in k)
        and isinstance(v, dict) and all(isinstance(v.get(p), str) for p in TESTING_PARTS)
        for k, v in data.items())
    if not ok:
        raise LayoutError(f"{path}: expected {{(scene, obj, id): {{{', '.join(TESTING_PARTS)}: path}}}}")
    return data


def testing_files(root: Path, entry: dict[str, str], key: tuple[str, str, str]) -> dict[str, Path]:
    """The files of one index entry (under ``testing/`` or ``real_data/testing/``), all inside ``root``."""
    base = next((root / t for t in TESTING_ROOTS if (root / t / entry["left"]).is_file()), root / TESTING)
    return _within(root, {part: base / entry[part] for part in TESTING_PARTS}, f"{TESTING_INDEX} entry {key}")


def _testing(root: Path, entry: dict[str, str], key: tuple[str, str, str]) -> Any:
    scene, obj, frame_id = key
    if not frame_id.isdigit():
        raise LayoutError(f"{root / TESTING_INDEX}: frame id {frame_id!r} of {scene}/{obj} is not a number")
    paths = testing_files(root, entry, key)
    mask = paths.pop("mask")
    height, width = _check_files(paths, {"left": 3, "right": 3, "disp": 1}, {"illusion_00": [mask]},
                                 f"{TESTING_INDEX} entry {key}")
    info = VideoInfo(name=f"{scene}_{obj}", source_kind="real_capture", illusion_types=[],
                     content_sha256=_key("testing", scene, obj), fps=None, width=width, height=height,
                     meta={"authors": {"scene": scene, "obj": obj}})
    return partial(_store_testing, info, int(frame_id), (height, width), paths, mask,
                   {"scene": scene, "obj": obj, "id": frame_id})


def _store_testing(info: VideoInfo, index: int, shape: tuple[int, int], paths: dict[str, Path], mask: Path,
                   names: dict[str, str], media: MediaStore) -> SampleRecord:
    disp = read_pfm(paths["disp"])
    valid = np.isfinite(disp) & (disp > 0)  # their depth 0 became inf: no measurement
    files = store_outputs(media, {"disparity": np.where(valid, disp, np.float32(np.nan)), "valid": valid,
                                  "masks": {"illusion_00": read_mask(mask)}})
    files.update(left=media.put_file(paths["left"]), right=media.put_file(paths["right"]))
    # like a capture imported here: its mask is evaluation data, not an annotation
    return _record(info, index, shape, files, annotated=False, params={"scale": 1.0},
                   provenance={"source": "capture", "imported_from": "authors", "authors": names})


# --- shared ----------------------------------------------------------------------------------

def _check_files(paths: dict[str, Path], channels: dict[str, int], masks: dict[str, list[Path]],
                 listed_by: str) -> tuple[int, int]:
    """Every file present and of the left image's size; returns (height, width)."""
    for path in [*paths.values(), *(p for parts in masks.values() for p in parts)]:
        if not path.is_file():
            raise LayoutError(f"{path}: missing (listed by {listed_by})")
    height, width, _ = raster_shape(paths["left"].read_bytes(), paths["left"])
    for name, path in paths.items():
        check_shape(path, raster_shape(path.read_bytes(), path), height, width, channels[name])
    for parts in masks.values():
        for path in parts:
            check_shape(path, raster_shape(path.read_bytes(), path), height, width, None)
    return height, width


def _key(*names: str) -> str:
    """A stable content key for a video that exists only as frames in the authors' layout."""
    return hashlib.sha256("\0".join(("authors", *names)).encode()).hexdigest()


def _record(info: VideoInfo, index: int, shape: tuple[int, int], files: dict[str, Any], *, annotated: bool,
            params: dict[str, Any], provenance: dict[str, Any]) -> SampleRecord:
    return SampleRecord(video=info, index=index, time_s=0.0, width=shape[1], height=shape[0],
                        frame_state="accepted", state="accepted", flagged=False,
                        annotation_version=1 if annotated else None, illusion_type=None, files=files,
                        params=params, provenance=provenance, qa={})
