"""`bench load`: annotators and curators against a served app with a worker answer no 5xx
and lose no acknowledged write, on SQLite always and on PostgreSQL + Redis when both are given;
and its read-back finds writes that are missing."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from benchmarks.load_check import lost_writes
from benchmarks.load_clients import Decision, Save, Tally
from dataset.db import transaction
from dataset.tables import Annotation, Frame, FrameState, Region, RegionKind, SourceKind, Video
from tests.conftest import TEST_DATABASE_URL, TEST_REDIS_URL
from webapp.cli import main

ROUTES = {"POST /api/v1/queue/annotate/next", "GET /api/v1/frames/{id}", "POST /api/v1/frames/{id}/segment",
          "POST /api/v1/frames/{id}/annotation", "GET /api/v1/review/frames", "POST /api/v1/frames/{id}/review"}


@pytest.mark.slow
@pytest.mark.parametrize("backend", ["sqlite", "postgresql+redis"])
def test_bench_load_answers_no_5xx_and_loses_no_write(backend: str, monkeypatch: pytest.MonkeyPatch) -> None:
    # A deployment's settings in the environment must not reach the benchmark's scratch workspace.
    monkeypatch.setenv("ILLUSION_STUDIO_DATABASE_URL", "postgresql://nobody@127.0.0.1:1/production")
    args = ["bench", "load", "--json", "--seconds", "4", "--annotators", "1", "--curators", "1", "--frames", "8"]
    if backend != "sqlite":
        if not (TEST_DATABASE_URL and TEST_REDIS_URL):
            pytest.skip("needs TEST_DATABASE_URL and TEST_REDIS_URL")
        args += ["--database-url", TEST_DATABASE_URL, "--queue-url", TEST_REDIS_URL]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    assert "ignoring ILLUSION_STUDIO_DATABASE_URL" in result.stderr
    report = json.loads(result.stdout)
    assert report["database"] == ("sqlite" if backend == "sqlite" else "postgresql")
    assert report["requests"] > 0 and report["5xx"] == 0 and report["transport_errors"] == 0
    assert report["lost_writes"] == 0, report["lost_by_check"]
    assert report["stale_saves_accepted"] == 0
    assert report["writes"]["reviews"] > 0 and report["writes"]["annotation_saves"] > 0
    assert report["conflicts"] == report["statuses"].get("409", 0)
    assert sum(report["statuses"].values()) == report["requests"]
    assert set(report["routes"]) >= ROUTES
    assert all(0 < t["p50_ms"] <= t["p95_ms"] and t["count"] > 0 for t in report["routes"].values())


def test_the_read_back_counts_writes_the_database_lacks(sessions) -> None:  # type: ignore[no-untyped-def]
    with transaction(sessions) as s:
        video = Video(name="v", source_kind=SourceKind.web, content_sha256="0" * 64)
        s.add(video)
        s.flush()
        frames = [Frame(video_id=video.id, index=i, time_s=i, width=4, height=4, content_sha256=f"f{i}", media_key="k",
                        state=FrameState.approved) for i in range(2)]
        s.add_all(frames)
        s.flush()
        stored = Annotation(frame_id=frames[0].id, version=2)
        stored.regions.append(Region(pair=0, kind=RegionKind.illusion, mask_rle={"size": [4, 4], "counts": "stored"}))
        s.add(stored)
        ids = [f.id for f in frames]
    clean = Tally(user_id=1, saves=[Save(ids[0], 0, 1, ("old",), False), Save(ids[0], 1, 2, ("stored",), False)])
    with sessions() as s:
        assert sum(lost_writes(s, [clean]).values()) == 0
        broken = Tally(user_id=1, reviews=[Decision(ids[1], "approve", 0, 7)],  # no audit, no review row, revision 0
                       saves=[Save(ids[0], 0, 1, ("a",), False), Save(ids[0], 0, 1, ("b",), False),  # version 1 twice
                              Save(ids[0], 1, 2, ("not what is stored",), False),
                              Save(ids[1], 0, 1, ("never stored",), False),  # frame 1 has no annotation
                              Save(ids[1], 0, 0, ("answered, not written",), False)])
        assert lost_writes(s, [broken]) == {
            "review_audit": 1, "review_rows": 1, "frame_revisions": 1, "annotation_versions_not_advanced": 1,
            "annotation_versions_twice": 1, "annotation_versions_missing": 1, "annotation_content": 1}
