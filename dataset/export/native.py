"""The native layout (documented in ``NATIVE_FORMAT.md``): export and validated reading.

Every sample file is the media store's file copied byte for byte, and the manifest and COCO files
are canonical JSON, so export → import → export reproduces every byte.
"""

from __future__ import annotations

import hashlib
from dataclasses import asdict
from datetime import datetime
from functools import partial
from pathlib import Path, PurePosixPath
from typing import Any

from dataset.export.coco import coco_document
from dataset.export.errors import LayoutError
from dataset.export.manifest import (
    FORMAT,
    FORMAT_VERSION,
    MANIFEST,
    created_by,
    dump_json,
    manifest_file,
    read_json,
    read_manifest,
)
from dataset.export.probe import check_shape, raster_shape
from dataset.export.records import PendingSample, Progress, SampleRecord, VideoInfo
from dataset.export.splits import split_of
from dataset.export.staging import copy_file, write_bytes
from dataset.media import MediaStore
from dataset.samples import IMAGES, load_output

ANNOTATIONS = "annotations"


def export_native(records: list[SampleRecord], media: MediaStore, root: Path, *, spec: dict[str, float], seed: int,
                  progress: Progress) -> dict[str, Any]:
    """Write ``records`` under the (empty, staged) folder ``root``; returns counts per split."""
    splits = {r.video_dir: split_of(r.scene or r.video_dir, spec, seed) for r in records}
    entries: list[dict[str, Any]] = []
    images: dict[str, list[tuple[SampleRecord, str]]] = {name: [] for name in spec}
    for done, record in enumerate(records, start=1):
        split = splits[record.video_dir]
        base = f"{split}/{record.name}"
        files: dict[str, Any] = {}
        for name, key in sorted(record.files.items()):
            if name == "masks":
                files["masks"] = {m: _copy(media, k, root, f"{base}/masks/{m}") for m, k in sorted(key.items())}
            else:
                files[name] = _copy(media, key, root, f"{base}/{name}")
        entries.append(_entry(record, split, files))
        images[split].append((record, files["left"]["path"]))
        progress(done, len(records), record.name)
    for split, split_images in images.items():
        doc = coco_document(split, split_images, lambda key: load_output(media, key, "mask"))
        write_bytes(root / _annotations(split), dump_json(doc))
    summary = [{"name": name, "fraction": fraction, "annotations": _annotations(name),
                "videos": sorted({r.video_dir for r, _ in images[name]}), "samples": len(images[name])}
               for name, fraction in spec.items()]
    videos = {r.video_dir: asdict(r.video) for r in records}
    write_bytes(root / MANIFEST, dump_json({"format": FORMAT, "format_version": FORMAT_VERSION,
                                            "created_by": created_by(), "seed": seed, "splits": summary,
                                            "videos": videos, "samples": entries}))
    return {"samples": len(records), "splits": {s["name"]: {"videos": len(s["videos"]), "samples": s["samples"]}
                                                for s in summary}}


def _annotations(split: str) -> str:
    return f"{ANNOTATIONS}/{split}.json"


def _copy(media: MediaStore, key: str, root: Path, stem: str) -> dict[str, str]:
    """Copy media file ``key`` to ``root/stem.<ext>``; its SHA-256 is the key's (content-addressed)."""
    path = f"{stem}.{key.rsplit('.', 1)[1]}"
    copy_file(media.path(key), root / path)
    return {"path": path, "sha256": PurePosixPath(key).stem}


def _entry(record: SampleRecord, split: str, files: dict[str, Any]) -> dict[str, Any]:
    return {
        "id": record.name, "split": split, "video": record.video_dir,
        "frame": {"index": record.index, "time_s": record.time_s, "width": record.width, "height": record.height,
                  "state": record.frame_state},
        "state": record.state, "flagged": record.flagged, "annotation_version": record.annotation_version,
        "illusion_type": record.illusion_type, "files": files, "params": record.params,
        "provenance": record.provenance, "qa": record.qa,
        "created_at": record.created_at.isoformat() if record.created_at else None,
    }


def read_native(root: Path, progress: Progress) -> list[PendingSample]:
    """Validate the native export at ``root`` completely (manifest, every file's presence, checksum and
    size) before anything is imported; raises :class:`LayoutError` naming the first problem."""
    root = Path(root).absolute()
    manifest = read_manifest(root)
    for split in manifest["splits"]:
        read_json(manifest_file(root, split["annotations"], "annotations"), f"COCO annotations of split {split['name']}")
    pending = []
    samples = manifest["samples"]
    for done, entry in enumerate(samples, start=1):
        paths = _sample_paths(root, entry)
        video = manifest["videos"][entry["video"]]
        pending.append(PendingSample(entry["id"], partial(_store, entry, video, paths)))
        progress(done, len(samples), entry["id"])
    return pending


def _sample_paths(root: Path, entry: dict[str, Any]) -> dict[str, Any]:
    """{name: Path} (masks nested) of one manifest sample, each file checked."""
    frame = entry["frame"]
    paths: dict[str, Any] = {}
    for name, spec in entry["files"].items():
        if name == "masks":
            if not isinstance(spec, dict):
                raise LayoutError(f"{root / MANIFEST}: sample {entry['id']}: 'masks' must be an object")
            paths["masks"] = {m: _check_file(root, entry["id"], f"mask {m}", s, frame, 1) for m, s in spec.items()}
        else:
            paths[name] = _check_file(root, entry["id"], name, spec, frame, 3 if name in IMAGES else 1)
    return paths


def _check_file(root: Path, sample: str, name: str, spec: Any, frame: dict[str, Any], channels: int) -> Path:
    if not (isinstance(spec, dict) and isinstance(spec.get("path"), str) and isinstance(spec.get("sha256"), str)):
        raise LayoutError(f"{root / MANIFEST}: sample {sample}: {name} needs 'path' and 'sha256'")
    path = manifest_file(root, spec["path"], f"{name} of sample {sample}")
    data = path.read_bytes()
    if hashlib.sha256(data).hexdigest() != spec["sha256"]:
        raise LayoutError(f"{path}: content does not match its SHA-256 in {MANIFEST} (changed or corrupt)")
    check_shape(path, raster_shape(data, path), frame["height"], frame["width"], channels)
    return path


def _store(entry: dict[str, Any], video: dict[str, Any], paths: dict[str, Any], media: MediaStore) -> SampleRecord:
    files: dict[str, Any] = {}
    for name, path in paths.items():
        if name == "masks":
            files["masks"] = {m: media.put_file(p) for m, p in path.items()}
        else:
            files[name] = media.put_file(path)
    frame = entry["frame"]
    return SampleRecord(
        video=VideoInfo(name=video["name"], source_kind=video["source_kind"], illusion_types=video["illusion_types"],
                        content_sha256=video["content_sha256"], fps=video.get("fps"), width=video.get("width"),
                        height=video.get("height"), meta=video["meta"]),
        index=frame["index"], time_s=frame["time_s"], width=frame["width"], height=frame["height"],
        frame_state=frame["state"], state=entry["state"], flagged=entry["flagged"],
        annotation_version=entry.get("annotation_version"), illusion_type=entry.get("illusion_type"),
        files=files, params=entry["params"], provenance=entry["provenance"], qa=entry["qa"],
        created_at=datetime.fromisoformat(entry["created_at"]) if entry.get("created_at") else None,
        video_dir=entry["video"],
    )
