"""The native export (``dataset/export/NATIVE_FORMAT.md``): its manifest's samples as StereoSamples.

Ground truth is the sample's ``disparity``, NaN outside its ``valid`` mask (captures). Regions:
``all``, ``illusion`` (the union of the illusion masks), ``non_illusion`` (the rest of ``all``) and
one per illusion type the sample holds. ``mono`` is ``disparity_mono`` when the sample has one;
captures whose video records intrinsics and a baseline get a camera.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from core.formats import read_mask, read_pfm, read_rgb
from dataset.export.errors import LayoutError
from dataset.export.manifest import manifest_file, read_manifest
from dataset.readers.base import Camera, ListedReader, StereoSample, invalidate, make_regions


class NativeReader(ListedReader):
    """The samples of a native export at ``root`` (of one ``split``, or all), in manifest order;
    ``mono=False`` skips reading the monocular disparity."""

    def __init__(self, root: Path, split: str | None = None, *, mono: bool = True) -> None:
        root = Path(root).absolute()
        manifest = read_manifest(root)
        names = [s["name"] for s in manifest["splits"]]
        if split is not None and split not in names:
            raise LayoutError(f"{root}: no split {split!r}; this export has {', '.join(names)}")
        self.entries = [s for s in manifest["samples"] if split is None or s["split"] == split]
        self.videos = manifest["videos"]
        self._mono = mono
        by_id = {entry["id"]: entry for entry in self.entries}
        super().__init__(root, list(by_id), lambda name: self._read(by_id[name]))

    def _read(self, entry: dict[str, Any]) -> StereoSample:
        files = entry["files"]
        disparity = read_pfm(self._path(files["disparity"]))
        valid = read_mask(self._path(files["valid"])) if "valid" in files else np.ones(disparity.shape, bool)
        disparity = invalidate(disparity, valid)
        illusion = {name: read_mask(self._path(spec)) for name, spec in files.get("masks", {}).items()
                    if name.startswith("illusion_")}
        kind = "capture" if entry["provenance"].get("source") == "capture" else "synthesized"
        video = self.videos[entry["video"]]
        types = pair_types(illusion, entry.get("illusion_type"), entry["provenance"].get("pair_types"))
        return StereoSample(
            name=entry["id"], left=read_rgb(self._path(files["left"])), right=read_rgb(self._path(files["right"])),
            disparity=disparity, regions=make_regions(disparity, illusion_regions(disparity.shape, illusion, types)),
            mono=read_pfm(self._path(files["disparity_mono"])) if self._mono and "disparity_mono" in files else None,
            camera=video_camera(video["meta"]) if kind == "capture" else None,
            meta={"id": entry["id"], "video": entry["video"], "index": entry["frame"]["index"],
                  "scale": float(entry["params"].get("scale", 1.0)), "kind": kind,
                  "illusion_types": sorted(set(types.values())), "split": entry["split"],
                  "left": files["left"]["path"]},
        )

    def _path(self, spec: dict[str, str]) -> Path:
        return manifest_file(self.root, spec["path"], "a sample's file")


def pair_types(illusion: Iterable[str], illusion_type: str | None,
               recorded: Mapping[str, str] | None = None) -> dict[str, str]:
    """{illusion mask name: its illusion type}: the type the sample recorded for that pair
    (``provenance["pair_types"]``, written by generation and by rendered captures), else the
    frame's; a mask with neither has no typed region."""
    recorded = recorded or {}
    types = {name: recorded.get(name) or illusion_type for name in illusion}
    return {name: t for name, t in types.items() if t}


def illusion_regions(shape: tuple[int, int], illusion: Mapping[str, np.ndarray],
                     types: Mapping[str, str]) -> dict[str, np.ndarray]:
    """``illusion`` (union of the masks), ``non_illusion`` (its complement) and one union per type."""
    union = np.logical_or.reduce([*illusion.values(), np.zeros(shape, bool)])
    regions = {"illusion": union, "non_illusion": ~union}
    for name, kind in types.items():
        regions[kind] = regions.get(kind, np.zeros(shape, bool)) | illusion[name]
    return regions


def video_camera(meta: Mapping[str, Any]) -> Camera | None:
    """The camera a capture's video records (``intrinsics.fx`` px, ``baseline_m``), if it does."""
    fx, baseline = meta.get("intrinsics", {}).get("fx"), meta.get("baseline_m")
    if isinstance(fx, int | float) and isinstance(baseline, int | float) and fx > 0 and baseline > 0:
        return Camera(fx=float(fx), baseline=float(baseline))
    return None
