"""Scene groups: a re-encoded, resized copy of a video is recognised at ingest by its frames' dHashes
and joins the original's group; training runs' splits and exports keep a group on one side; the
migration adds the column to a populated database."""

from __future__ import annotations

import json
import random
import shutil
from pathlib import Path

import cv2
import pytest
from alembic import command
from sqlalchemy import func, select, text, update

from benchmarks.scale import seed
from dataset.db import alembic_config, make_engine, transaction
from dataset.export import parse_split_spec, split_of
from dataset.ingest.copies import find_copies
from dataset.readers.version import pin_dataset_version, split_by_video
from dataset.services.errors import InvalidInput
from dataset.services.scene_groups import join_scene_group
from dataset.synthetic import write_synthetic_dataset
from dataset.tables import Frame, JobState, Video
from tests.fixtures.workspaces import export, open_runtime
from tests.test_ingest import run_ingest, write_avi
from webapp.runtime import Runtime


def reencode(video: Path, out: Path, scale: float = 0.75, quality: int = 40) -> Path:
    """Another codec (Motion-JPEG), a low quality, a smaller size and another frame rate."""
    cap = cv2.VideoCapture(str(video))
    frames = []
    while (got := cap.read())[0]:
        frames.append(got[1])
    cap.release()
    size = (round(frames[0].shape[1] * scale), round(frames[0].shape[0] * scale))
    writer = cv2.VideoWriter(str(out), cv2.VideoWriter_fourcc(*"MJPG"), 5, size)
    writer.set(cv2.VIDEOWRITER_PROP_QUALITY, quality)
    for frame in frames:
        writer.write(cv2.resize(frame, size, interpolation=cv2.INTER_AREA))
    writer.release()
    return out


def groups(rt: Runtime) -> dict[str, int | None]:
    with rt.sessions() as s:
        return dict(s.execute(select(Video.name, Video.scene_group)).all())


def test_a_reencoded_copy_joins_the_originals_scene_group(runtime: Runtime, tmp_path: Path) -> None:
    scenes = write_synthetic_dataset(tmp_path / "s", videos=3, seed=0, n_frames=6, width=320, height=180)
    for scene in scenes:
        job = run_ingest(runtime, scene, fps=None, dedup_hamming=None)
        assert job.state == JobState.succeeded and "copy_of" not in job.result  # look-alike rooms are no copies
    noise = run_ingest(runtime, write_avi(tmp_path / "noise.avi", 6), fps=None)
    assert "copy_of" not in noise.result
    with runtime.sessions() as s:
        original = s.scalar(select(Video).where(Video.name == scenes[1].name))

    copy = run_ingest(runtime, reencode(scenes[1] / "video.mp4", tmp_path / "holiday final.avi"), fps=None)
    assert copy.state == JobState.succeeded, copy.error
    found = copy.result["copy_of"]
    assert (found["video_id"], found["video_name"], found["scene_group"]) == (original.id, original.name, original.id)
    assert found["matched"] == found["frames"] == copy.result["frames"] >= 2  # every kept frame matches
    assert f"looks like a copy of video {original.id}" in copy.log and "kept in the same scene group" in copy.log
    assert groups(runtime) == {scenes[0].name: None, scenes[1].name: original.id, scenes[2].name: None,
                               "noise.avi": None, "holiday final.avi": original.id}

    # a copy of the copy, cut short and smaller again, lands in the same group
    short = reencode(tmp_path / "holiday final.avi", tmp_path / "short.avi", scale=0.5, quality=30)
    cap, writer = cv2.VideoCapture(str(short)), None
    cut = tmp_path / "cut.avi"
    for _ in range(3):
        ok, frame = cap.read()
        writer = writer or cv2.VideoWriter(str(cut), cv2.VideoWriter_fourcc(*"MJPG"), 5, frame.shape[1::-1])
        writer.write(frame)
    writer.release()
    assert run_ingest(runtime, cut, fps=None).result["copy_of"]["scene_group"] == original.id
    assert groups(runtime)["cut.avi"] == original.id


def test_matching_counts_frames_both_ways_and_needs_two() -> None:
    a, b, c, d = 0x0123456789ABCDEF, 0x3C3CA5A55A5AC3C3, 0x0F0F0F0F0F0F0F0F, 0xFFFF0000FFFF0000
    others = [(1, a), (1, a ^ 0b11), (2, b), (2, b ^ 0b101), (2, d), (3, c), (3, c ^ 1 << 40)]
    found = find_copies([a ^ 1, a ^ 0b10, b, b ^ 1 << 63], others)
    assert [(m.video_id, m.matched, m.matched_there, m.share) for m in found] == [(1, 2, 2, 1.0), (2, 2, 2, 2 / 3)]
    assert find_copies([a ^ 1, c], others) == []  # one frame in common is not a copy
    assert find_copies([a ^ 0xFF, a ^ 0xFF00], others) == []  # 8 bits off: other pictures
    assert find_copies([], others) == [] and find_copies([a], []) == []


def test_a_video_copying_two_groups_merges_them(sessions) -> None:  # type: ignore[no-untyped-def]
    rng = random.Random(3)  # random 64-bit hashes lie ~32 bits apart: seven different pictures
    hashes = {name: [rng.getrandbits(64), rng.getrandbits(64)] for name in "abc"}
    with transaction(sessions) as s:
        ids = {}
        for name, frames in hashes.items():
            video = Video(name=name, source_kind="web", content_sha256=name * 64, meta={"ingest": "complete"})
            s.add(video)
            s.flush()
            ids[name] = video.id
            s.add_all(Frame(video_id=video.id, index=i, time_s=i, width=8, height=8, content_sha256=f"{i}" * 64,
                            media_key="k", assets={"dhash": f"{h:016x}"}) for i, h in enumerate(frames))
        s.add(Video(name="running", source_kind="web", content_sha256="r" * 64, meta={"ingest": "running"}))
    with transaction(sessions) as s:
        assert join_scene_group(s, ids["a"] + 100, [rng.getrandbits(64)]) is None
        copy_of_b = join_scene_group(s, ids["c"], hashes["b"])  # c's own frames don't count
        assert copy_of_b == {"video_id": ids["b"], "video_name": "b", "matched": 2, "frames": 2,
                             "scene_group": ids["b"]}
        both = join_scene_group(s, ids["c"] + 1000, [*hashes["a"], *hashes["b"]])
        assert both is not None and both["scene_group"] == ids["a"]  # the oldest group takes the others in
    with sessions() as s:
        assert dict(s.execute(select(Video.name, Video.scene_group)).all()) == {
            "a": ids["a"], "b": ids["a"], "c": ids["a"], "running": None}


def test_run_and_export_splits_keep_a_scene_group_together(source_template: Path, tmp_path: Path) -> None:
    shutil.copytree(source_template, tmp_path, dirs_exist_ok=True)
    rt = open_runtime(tmp_path / "ws")  # 3 synthetic videos and a capture, with accepted samples
    try:
        with rt.sessions() as s:
            version = pin_dataset_version(s, rt.media)
            videos = s.execute(select(Video.id, Video.name).where(Video.name.like("synthetic-%"))
                               .order_by(Video.id)).all()[:2]
        assert all(item["scene_group"] == item["video_id"] for item in version["items"])  # each its own
        fractions = {"train": 0.5, "test": 0.5}
        apart = [k for k in range(40) if len(set(_sides(split_by_video(version, fractions, k), version, videos))) == 2]
        assert apart, "no seed splits the two videos apart; the test would prove nothing"
        quarters = {name: 0.25 for name in ("a", "b", "c", "d")}
        assert all(split_by_video(version, quarters, seed=0).values())  # 4 videos: one each

        with transaction(rt.sessions) as s:  # what ingest records when the second copies the first
            s.execute(update(Video).where(Video.id.in_([v.id for v in videos])).values(scene_group=videos[0].id))
        with rt.sessions() as s:
            grouped = pin_dataset_version(s, rt.media)
        for k in apart:
            first, second = _sides(split_by_video(grouped, fractions, k), grouped, videos)
            assert first == second
        with pytest.raises(InvalidInput, match=r"4 video\(s\) in 3 scene group\(s\)"):
            split_by_video(grouped, quarters, seed=0)

        # exports: a seed under which the two folders fall apart on their own, then together
        spec = parse_split_spec("train=0.5,test=0.5")
        dirs = [v.name for v in videos]
        k = next(k for k in range(100) if split_of(dirs[0], spec, k) != split_of(dirs[1], spec, k))
        export(rt, tmp_path / "out", split="train=0.5,test=0.5", seed=k)
        manifest = json.loads((tmp_path / "out" / "manifest.json").read_text())
        sides = {sample["video"]: sample["split"] for sample in manifest["samples"]}
        assert sides[dirs[0]] == sides[dirs[1]] == split_of(dirs[0], spec, k)  # the first video's side
        others = [v for v in sides if v not in dirs]
        assert others and all(sides[v] == split_of(v, spec, k) for v in others)  # the rest split as before
    finally:
        rt.close()


def _sides(splits: dict[str, list[int]], version: dict, videos: list) -> tuple[str, str]:  # type: ignore[type-arg]
    """The split of each of two videos' samples."""
    where = {i: name for name, ids in splits.items() for i in ids}
    first, second = ({where[i["sample_id"]] for i in version["items"] if i["video_id"] == v.id} for v in videos)
    assert len(first) == len(second) == 1
    return first.pop(), second.pop()


def test_migration_adds_scene_groups_to_a_populated_database(db_url: str) -> None:
    cfg = alembic_config(db_url)
    command.upgrade(cfg, "0001")
    engine = make_engine(db_url)
    with engine.begin() as conn:
        seed(conn, 120)
    command.upgrade(cfg, "0005")
    with engine.connect() as conn:
        before = conn.execute(text("SELECT count(*) FROM videos")).scalar(), conn.execute(
            text("SELECT count(*) FROM frames")).scalar()
    command.upgrade(cfg, "head")
    with engine.connect() as conn:
        assert conn.execute(text("SELECT count(*), count(scene_group) FROM videos")).one() == (before[0], 0)
        assert conn.execute(text("SELECT count(*) FROM frames")).scalar() == before[1]
    command.downgrade(cfg, "0005")  # the column goes; the frames stay (no table rebuilt under them)
    with engine.connect() as conn:
        assert conn.execute(text("SELECT count(*) FROM frames")).scalar() == before[1]
    command.upgrade(cfg, "head")
    with make_engine(db_url).connect() as conn:
        assert conn.execute(select(func.count()).select_from(Frame)).scalar() == before[1]
    engine.dispose()
