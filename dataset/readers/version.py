"""Dataset versions: the accepted samples of the database pinned with their files' hashes, so a
training run stays reproducible while curation goes on; splits by scene group (copies of one video
stay together); a reader over a version.

A version is plain JSON (stored in a run's ``run.json``)::

    {"id": sha256 of the items, "created_at", "filters", "skipped": [{"sample_id", "reason"}],
     "items": [{"sample_id", "frame_id", "frame_index", "video_id", "video_name", "scene_group",
                "kind": "synthesized" | "capture", "illusion_types", "pair_types": {mask: type},
                "qa_flags", "scale", "camera": {"fx", "baseline"} | null,
                "files": {name: media key, "masks": {name: key}}, "hashes": {media key: sha256}}]}

One sample per frame: among a frame's accepted samples, the one made from the newest annotation
version (as exports choose). Media keys are content hashes, so ``hashes`` is read off the keys:
nothing is re-hashed, and a version's files stay what they were as long as the store keeps them
(``version_media_keys`` lists them for garbage collection).
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Iterator, Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from dataset.media import MediaKeyError, MediaStore
from dataset.readers.base import Camera, ListedReader, StereoSample, invalidate, make_regions
from dataset.readers.native import illusion_regions, pair_types, video_camera
from dataset.samples import load_output
from dataset.services.errors import InvalidInput
from dataset.states import IllusionType, SampleState, SourceKind

if TYPE_CHECKING:
    from sqlalchemy.orm import Session

KINDS = ("synthesized", "capture")
_BATCH = 256  # rows fetched at a time: sample rows carry JSON blobs (files, qa, provenance)


def pin_dataset_version(session: Session, media: MediaStore, *, video_ids: Sequence[int] | None = None,
                        illusion_types: Sequence[str] | None = None, kinds: Sequence[str] | None = None,
                        qa_flags: Sequence[str] | None = None) -> dict[str, Any]:
    """Pin the accepted samples passing every given filter (None: no filter):

    - ``video_ids``: samples of these videos;
    - ``illusion_types``: samples holding at least one of these types;
    - ``kinds``: ``synthesized`` (right view made by the pipeline) and/or ``capture`` (a real rig);
    - ``qa_flags``: the QA flags tolerated, as prefixes of the flag sentences (``["holes", "SGBM"]``);
      a sample with any other flag is left out, so ``[]`` keeps unflagged samples only.

    A sample whose files are missing from the media store is left out and listed in ``skipped``.
    An empty selection gives a version without items (the caller refuses to train on it).
    """
    # The database layer is imported here, not above: the trainer reads versions (VersionReader)
    # and loads none of it.
    from sqlalchemy import select

    from dataset.tables import Video

    filters = _filters(video_ids, illusion_types, kinds, qa_flags)
    videos = {row.id: row for row in session.execute(select(Video.id, Video.name, Video.source_kind, Video.illusion_types,
                                                            Video.meta, Video.scene_group))}
    items, skipped = [], []
    for row in _newest_accepted(session, filters["video_ids"]):
        item = _item(row, videos[row.video_id])
        if not _passes(item, filters):
            continue
        missing = [key for key in item["hashes"] if not _stored(media, key)]
        if missing:
            skipped.append({"sample_id": item["sample_id"], "reason": f"media file {missing[0]} is missing from the store"})
            continue
        items.append(item)
    items.sort(key=lambda item: item["sample_id"])
    digest = hashlib.sha256(json.dumps(items, sort_keys=True, separators=(",", ":")).encode()).hexdigest()
    return {"id": digest, "created_at": datetime.now(UTC).isoformat(timespec="seconds").replace("+00:00", "Z"),
            "filters": filters, "skipped": skipped, "items": items}


def version_counts(version: Mapping[str, Any]) -> dict[str, int]:
    """How many samples of each kind and illusion type a version holds, and of how many videos."""
    counts: dict[str, int] = {"samples": len(version["items"]),
                              "videos": len({item["video_id"] for item in version["items"]})}
    for item in version["items"]:
        for key in (item["kind"], *item["illusion_types"]):
            counts[key] = counts.get(key, 0) + 1
    return counts


def split_by_video(version: Mapping[str, Any], fractions: Mapping[str, float], seed: int) -> dict[str, list[int]]:
    """{split: sorted sample ids}, whole scene groups (a video and its copies; see
    ``dataset.services.scene_groups``) to one split, in the shares of ``fractions`` (≥ 0, summing
    to 1). Every split with a share > 0 gets at least one group; fewer groups than such splits is
    an :class:`InvalidInput` saying so. Deterministic: groups are ordered by SHA-256 of
    ``<seed>:<group>`` (the group of a video without copies is its id) and dealt out in that order
    by largest remainders."""
    if not fractions or any(not (math.isfinite(f) and f >= 0) for f in fractions.values()) \
            or abs(sum(fractions.values()) - 1) > 1e-6:
        raise InvalidInput(f"split fractions must be ≥ 0 and sum to 1, got {dict(fractions)}")
    groups = sorted({_group(item) for item in version["items"]},
                    key=lambda g: hashlib.sha256(f"{seed}:{g}".encode()).hexdigest())
    needed = [name for name, f in fractions.items() if f > 0]
    if len(groups) < len(needed):
        videos = len({item["video_id"] for item in version["items"]})
        copies = f" in {len(groups)} scene group(s) (copies of one scene split together)" if len(groups) < videos else ""
        raise InvalidInput(f"the selection has {videos} video(s){copies} but {len(needed)} splits ({', '.join(needed)}) "
                           "each need one of their own: select more videos or fewer splits")
    counts = _apportion(fractions, len(groups))
    of_group, start = {}, 0
    for name, count in counts.items():
        of_group.update({group: name for group in groups[start:start + count]})
        start += count
    splits: dict[str, list[int]] = {name: [] for name in fractions}
    for item in version["items"]:
        splits[of_group[_group(item)]].append(item["sample_id"])
    return {name: sorted(ids) for name, ids in splits.items()}


def _group(item: Mapping[str, Any]) -> int:
    """An item's scene group; versions pinned before scene groups existed split by video."""
    return item.get("scene_group", item["video_id"])


def version_media_keys(version: Mapping[str, Any]) -> set[str]:
    """Every media key a version pins (to keep them through garbage collection)."""
    return {key for item in version["items"] for key in _keys(item["files"])}


class VersionReader(ListedReader):
    """The samples of a pinned version (all, or ``sample_ids`` in that order) read from the media
    store at ``media_root``; names ``video_<id>/frame_<index:06d>``. Regions ``all``, ``illusion``,
    ``non_illusion`` and one per illusion type; ``mono`` = ``disparity_mono``."""

    def __init__(self, version: Mapping[str, Any], media_root: Path, sample_ids: Sequence[int] | None = None) -> None:
        by_id = {item["sample_id"]: item for item in version["items"]}
        unknown = [i for i in sample_ids or [] if i not in by_id]
        if unknown:
            raise InvalidInput(f"sample {unknown[0]} is not in dataset version {version['id'][:12]}")
        self.items = [by_id[i] for i in sample_ids] if sample_ids is not None else list(version["items"])
        self.media = MediaStore(Path(media_root))
        by_name = {sample_name(item): item for item in self.items}
        super().__init__(self.media.root, list(by_name), lambda name: self._read(by_name[name]))

    def _read(self, item: Mapping[str, Any]) -> StereoSample:
        files = item["files"]
        outputs = {name: self._output(key, name) for name, key in files.items() if name != "masks"}
        disparity = invalidate(outputs["disparity"], outputs.get("valid", np.ones(outputs["disparity"].shape, bool)))
        illusion = {name: self._output(key, "mask") for name, key in files.get("masks", {}).items()
                    if name.startswith("illusion_")}
        regions = illusion_regions(disparity.shape, illusion, item["pair_types"])
        camera = Camera(**item["camera"]) if item["camera"] else None
        return StereoSample(
            name=sample_name(item), left=outputs["left"], right=outputs["right"], disparity=disparity,
            regions=make_regions(disparity, regions), mono=outputs.get("disparity_mono"), camera=camera,
            meta={key: item[key] for key in ("sample_id", "frame_id", "frame_index", "video_id", "video_name", "kind",
                                             "illusion_types", "scale")} | {"left": files["left"]},
        )

    def _output(self, key: str, name: str) -> np.ndarray:
        if not self.media.exists(key):
            raise FileNotFoundError(f"media file {key} is missing from {self.media.root}")
        return load_output(self.media, key, name)


def sample_name(item: Mapping[str, Any]) -> str:
    return f"video_{item['video_id']}/frame_{item['frame_index']:06d}"


# --- helpers -------------------------------------------------------------------------------------

def _filters(video_ids: Sequence[int] | None, illusion_types: Sequence[str] | None, kinds: Sequence[str] | None,
             qa_flags: Sequence[str] | None) -> dict[str, Any]:
    bad_types = [t for t in illusion_types or [] if t not in IllusionType.__members__]
    if bad_types:
        raise InvalidInput(f"unknown illusion type {bad_types[0]!r}; use {', '.join(IllusionType)}")
    bad_kinds = [k for k in kinds or [] if k not in KINDS]
    if bad_kinds:
        raise InvalidInput(f"unknown sample kind {bad_kinds[0]!r}; use {' or '.join(KINDS)}")
    return {"video_ids": None if video_ids is None else sorted({int(v) for v in video_ids}),
            "illusion_types": None if illusion_types is None else sorted(set(illusion_types)),
            "kinds": None if kinds is None else sorted(set(kinds)),
            "qa_flags": None if qa_flags is None else sorted(set(qa_flags))}


def _newest_accepted(session: Session, video_ids: list[int] | None) -> Iterator[Any]:
    """Accepted sample rows, the newest annotation version of each frame only, streamed in batches."""
    from sqlalchemy import select

    from dataset.tables import Annotation, Frame, Sample

    query = (select(Sample.id, Sample.frame_id, Sample.annotation_version, Sample.files, Sample.params, Sample.provenance,
                    Sample.qa, Frame.index, Frame.video_id, Annotation.illusion_type)
             .join(Frame, Frame.id == Sample.frame_id).outerjoin(Annotation, Annotation.frame_id == Frame.id)
             .where(Sample.state == SampleState.accepted)
             .order_by(Sample.frame_id, Sample.annotation_version.desc().nulls_last(), Sample.id.desc()))
    if video_ids is not None:
        query = query.where(Frame.video_id.in_(video_ids))
    last_frame = None
    for row in session.execute(query.execution_options(yield_per=_BATCH)):
        if row.frame_id != last_frame:
            last_frame = row.frame_id
            yield row


def _item(row: Any, video: Any) -> dict[str, Any]:
    from dataset.services.scene_groups import group_of

    capture = row.provenance.get("source") == "capture" or video.source_kind == SourceKind.real_capture
    frame_type = row.illusion_type.value if row.illusion_type is not None else row.provenance.get("illusion_type")
    types = pair_types([name for name in row.files.get("masks", {}) if name.startswith("illusion_")], frame_type,
                       row.provenance.get("pair_types"))
    camera = video_camera(video.meta) if capture else None
    return {
        "sample_id": row.id, "frame_id": row.frame_id, "frame_index": row.index, "video_id": row.video_id,
        "video_name": video.name, "scene_group": group_of(video), "kind": "capture" if capture else "synthesized",
        "illusion_types": sorted(set(types.values()) or set(video.illusion_types)), "pair_types": types,
        "qa_flags": list(row.qa.get("flags", [])), "scale": float(row.params.get("scale", 1.0)),
        "camera": None if camera is None else {"fx": camera.fx, "baseline": camera.baseline},
        "files": row.files, "hashes": {key: _sha256_of_key(key) for key in _keys(row.files)},
    }


def _passes(item: Mapping[str, Any], filters: Mapping[str, Any]) -> bool:
    if filters["kinds"] is not None and item["kind"] not in filters["kinds"]:
        return False
    if filters["illusion_types"] is not None and not set(item["illusion_types"]) & set(filters["illusion_types"]):
        return False
    tolerated = filters["qa_flags"]
    return tolerated is None or all(flag.startswith(tuple(tolerated)) for flag in item["qa_flags"])


def _apportion(fractions: Mapping[str, float], n: int) -> dict[str, int]:
    """Video counts per split: largest remainders of fraction·n, then at least one per split with a
    share > 0 (taken from the split that has most)."""
    exact = {name: f * n for name, f in fractions.items()}
    counts = {name: math.floor(x) for name, x in exact.items()}
    for name in sorted(exact, key=lambda k: counts[k] - exact[k])[:n - sum(counts.values())]:
        counts[name] += 1
    for name in (k for k, f in fractions.items() if f > 0 and counts[k] == 0):
        counts[max(counts, key=counts.get)] -= 1
        counts[name] = 1
    return counts


def _keys(files: Mapping[str, Any]) -> list[str]:
    return [key for name, value in files.items()
            for key in (value.values() if name == "masks" else [value])]


def _sha256_of_key(key: str) -> str:
    """The SHA-256 a content-addressed key carries (``ab/cd/<64 hex>.ext``)."""
    digest = Path(key).stem
    if len(digest) != 64 or any(c not in "0123456789abcdef" for c in digest):
        raise MediaKeyError(f"not a content-addressed media key: {key!r}")
    return digest


def _stored(media: MediaStore, key: str) -> bool:
    try:
        return media.exists(key)
    except MediaKeyError:
        return False
