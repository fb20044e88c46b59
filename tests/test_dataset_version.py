"""Dataset versions: pinning accepted samples with their hashes, filters, splits by video, and the
reader over a version — on the real pipeline's samples and on hand-made rows on both backends."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import select

from dataset.db import transaction
from dataset.media import MediaStore
from dataset.readers.version import (
    VersionReader,
    pin_dataset_version,
    split_by_video,
    version_counts,
    version_media_keys,
)
from dataset.samples import load_outputs, store_outputs
from dataset.services.errors import InvalidInput
from dataset.tables import Annotation, Frame, FrameState, IllusionType, Sample, SampleState, SourceKind, Video
from webapp.runtime import Runtime


def pin(rt: Runtime, **filters):  # type: ignore[no-untyped-def]
    with rt.sessions() as s:
        return pin_dataset_version(s, rt.media, **filters)


def test_pin_holds_accepted_samples_with_their_hashes(source: Runtime) -> None:
    version = pin(source)
    with source.sessions() as s:
        accepted = set(s.scalars(select(Sample.id).where(Sample.state == SampleState.accepted)))
        generated_only = set(s.scalars(select(Sample.id).where(Sample.state == SampleState.generated)))
    assert {item["sample_id"] for item in version["items"]} == accepted and generated_only
    counts = version_counts(version)
    assert (counts["samples"], counts["videos"], counts["synthesized"], counts["capture"]) == (6, 4, 5, 1)
    for item in version["items"]:
        for key, digest in item["hashes"].items():
            assert hashlib.sha256(source.media.read_bytes(key)).hexdigest() == digest
        assert set(item["hashes"]) == {k for name, v in item["files"].items()
                                       for k in (v.values() if name == "masks" else [v])}
    assert version_media_keys(version) == {k for item in version["items"] for k in item["hashes"]}
    again = pin(source)
    assert again["id"] == version["id"] and again["items"] == version["items"] and len(version["id"]) == 64


def test_filters(source: Runtime) -> None:
    everything = pin(source)["items"]
    capture = pin(source, kinds=["capture"])["items"]
    assert [i["kind"] for i in capture] == ["capture"] and capture[0]["illusion_types"] == []
    synthesized = pin(source, kinds=["synthesized"])
    assert len(synthesized["items"]) == 5 and synthesized["filters"]["kinds"] == ["synthesized"]
    video = everything[0]["video_id"]
    assert {i["video_id"] for i in pin(source, video_ids=[video])["items"]} == {video}
    kind = next(t for i in everything for t in i["illusion_types"])
    typed = pin(source, illusion_types=[kind])["items"]
    assert typed and all(kind in i["illusion_types"] for i in typed)
    clean = pin(source, qa_flags=[])["items"]
    assert [i["sample_id"] for i in clean] == [i["sample_id"] for i in everything if not i["qa_flags"]]
    tolerant = pin(source, qa_flags=["holes", "SGBM", "pair", "valid", "%"])["items"]
    assert len(tolerant) >= len(clean)
    with pytest.raises(InvalidInput, match="unknown illusion type 'hologram'"):
        pin(source, illusion_types=["hologram"])
    with pytest.raises(InvalidInput, match="unknown sample kind 'web'"):
        pin(source, kinds=["web"])
    assert pin(source, video_ids=[10_000])["items"] == []


def test_split_by_video(source: Runtime) -> None:
    version = pin(source)
    fractions = {"train": 0.5, "val": 0.25, "test": 0.25}
    splits = split_by_video(version, fractions, seed=3)
    assert split_by_video(version, fractions, seed=3) == splits
    video_of = {i["sample_id"]: i["video_id"] for i in version["items"]}
    videos = {name: {video_of[s] for s in ids} for name, ids in splits.items()}
    assert all(videos.values()) and sum(len(v) for v in videos.values()) == 4  # no video in two splits
    assert sorted(s for ids in splits.values() for s in ids) == sorted(video_of)
    assert split_by_video(version, {"train": 1.0, "test": 0.0}, seed=0)["test"] == []
    with pytest.raises(InvalidInput, match=r"4 video\(s\) but 5 splits .* each need one"):
        split_by_video(version, {n: 0.2 for n in "abcde"}, seed=0)
    with pytest.raises(InvalidInput, match="sum to 1"):
        split_by_video(version, {"train": 0.7, "test": 0.2}, seed=0)
    seeds = {tuple(sorted(split_by_video(version, fractions, seed=k)["test"])) for k in range(8)}
    assert len(seeds) > 1  # the seed matters


def test_version_reader_reads_the_pinned_files(source: Runtime) -> None:
    version = pin(source)
    reader = VersionReader(version, source.settings.media_root)
    assert len(reader) == 6 and reader.names[0].startswith("video_")
    for i, item in enumerate(version["items"]):
        sample = reader[i]
        arrays = load_outputs(source.media, item["files"])
        assert np.array_equal(sample.left, arrays["left"]) and np.array_equal(sample.right, arrays["right"])
        valid = np.isfinite(arrays["disparity"]) & arrays.get("valid", True)
        assert np.array_equal(sample.regions["all"], valid)
        assert np.array_equal(sample.disparity[valid], arrays["disparity"][valid])
        illusion = np.logical_or.reduce([m for n, m in arrays["masks"].items() if n.startswith("illusion")]) & valid
        assert np.array_equal(sample.regions["illusion"], illusion)
        assert np.array_equal(sample.regions["non_illusion"], valid & ~illusion)
        for kind in item["illusion_types"]:  # each type's region: the masks of the pairs of that type
            typed = [m for n, m in arrays["masks"].items() if n.startswith("illusion") and item["pair_types"][n] == kind]
            assert np.array_equal(sample.regions[kind], np.logical_or.reduce(typed) & valid)
        if item["kind"] == "synthesized":
            assert np.array_equal(sample.mono, arrays["disparity_mono"])
        assert sample.meta["sample_id"] == item["sample_id"] and sample.meta["kind"] == item["kind"]
    ids = [version["items"][3]["sample_id"], version["items"][1]["sample_id"]]
    assert [r.meta["sample_id"] for r in VersionReader(version, source.settings.media_root, ids)] == ids
    with pytest.raises(InvalidInput, match="sample 99999 is not in dataset version"):
        VersionReader(version, source.settings.media_root, [99999])


# --- hand-made rows, SQLite and PostgreSQL --------------------------------------------------------

def test_newest_version_per_frame_rejected_and_missing_files(sessions, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    media = MediaStore(tmp_path / "media")
    h, w = 8, 10

    def files(seed: int) -> dict:
        rng = np.random.default_rng(seed)
        return store_outputs(media, {"left": rng.integers(0, 255, (h, w, 3), dtype=np.uint8),
                                     "right": rng.integers(0, 255, (h, w, 3), dtype=np.uint8),
                                     "disparity": np.full((h, w), float(seed), np.float32),
                                     "masks": {"illusion_00": np.eye(h, w, dtype=bool)}})

    with transaction(sessions) as s:
        videos = [Video(name=f"v{k}", source_kind=SourceKind.web, illusion_types=[], content_sha256=f"{k}" * 64)
                  for k in range(3)]
        s.add_all(videos)
        s.flush()
        frames = [Frame(video_id=v.id, index=n, time_s=0.0, width=w, height=h, content_sha256="f" * 64,
                        media_key="k", state=FrameState.accepted) for v in videos for n in range(2)]
        s.add_all(frames)
        s.flush()
        s.add(Annotation(frame_id=frames[0].id, version=2, illusion_type=IllusionType.mirror, submitted=True))
        s.add_all([
            Sample(frame_id=frames[0].id, annotation_version=1, state=SampleState.accepted, files=files(1)),
            Sample(frame_id=frames[0].id, annotation_version=2, state=SampleState.accepted, files=files(2),
                   qa={"flags": ["holes 30% > 20%"]}),
            Sample(frame_id=frames[1].id, annotation_version=1, state=SampleState.rejected, files=files(3)),
            *[Sample(frame_id=f.id, annotation_version=1, state=SampleState.accepted, files=files(10 + n))
              for n, f in enumerate(frames[2:])],
        ])
    gone = files(13)["left"]
    media.path(gone).unlink()
    with sessions() as s:
        version = pin_dataset_version(s, media)
    by_frame = {item["frame_id"]: item for item in version["items"]}
    assert frames[1].id not in by_frame  # only rejected
    newest = by_frame[frames[0].id]
    assert newest["files"] == files(2) and newest["illusion_types"] == ["mirror"]
    assert newest["pair_types"] == {"illusion_00": "mirror"} and newest["qa_flags"] == ["holes 30% > 20%"]
    assert [entry["reason"] for entry in version["skipped"]] == [f"media file {gone} is missing from the store"]
    assert len(version["items"]) == 4
    with sessions() as s:
        assert len(pin_dataset_version(s, media, qa_flags=[])["items"]) == 3
        assert len(pin_dataset_version(s, media, qa_flags=["holes"])["items"]) == 4
    sample = VersionReader(version, tmp_path / "media")[0]
    assert sample.regions["mirror"].sum() == min(h, w) and (sample.disparity == 2).all()
