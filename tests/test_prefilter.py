"""The VLM prefilter as jobs: keep rule → frame states, sparse mode, one verdict per frame across workers."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from sqlalchemy import func, select

from benchmarks.vlm_server import ChatRequest, LocalVLMServer, Reply
from dataset.db import transaction
from dataset.services import jobs as job_service
from dataset.services.frames import funnel_counts
from dataset.services.ingest import ingest_params
from dataset.services.prefilter import launch_prefilter
from dataset.synthetic import write_synthetic_dataset
from dataset.tables import Frame, Job, PrefilterResult
from tests.conftest import make_settings
from tests.workers import wait_for
from webapp.jobs.handlers import HANDLERS
from webapp.runtime import Runtime

KEEP = "no,yes,no,no,no,no,no,no,no,no,no,no"  # Q2 perspective illusion: keep
BLURRY = "no,yes,no,no,no,no,no,no,yes,no,no,no"  # Q9 too blurry: reject


def answer_by_brightness(request: ChatRequest) -> Reply:
    """Dark frames are 'blurry', mid-grey ones get an unreadable answer, the rest are kept."""
    mean = float(request.image().mean())
    if mean < 60:
        return Reply(BLURRY)
    if 110 < mean < 150:
        return Reply("I am not sure what this image shows.")
    return Reply(KEEP)


@pytest.fixture(scope="module")
def vlm() -> Iterator[LocalVLMServer]:
    with LocalVLMServer(answer_by_brightness) as server:
        yield server


def write_video(path: Path, levels: list[int]) -> Path:
    """An AVI whose frame k is a noisy image of mean brightness ``levels[k]`` (never near-duplicates)."""
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10, (96, 64))
    rng = np.random.default_rng(0)
    for level in levels:
        writer.write(np.clip(level + rng.normal(0, 12, (64, 96, 3)), 0, 255).astype(np.uint8))
    writer.release()
    return path


def ingest(rt: Runtime, path: Path, **kw: Any) -> None:
    with transaction(rt.sessions) as s:
        rt.submit(s, "ingest", ingest_params(str(path), fps=None, dedup_hamming=None, **kw), None)
    job_service.run_queued_jobs(HANDLERS, rt)


def states(rt: Runtime) -> list[str]:
    with rt.sessions() as s:
        return [f.state.value for f in s.scalars(select(Frame).order_by(Frame.index))]


@pytest.fixture
def openai_rt(tmp_path: Path, vlm: LocalVLMServer) -> Iterator[Runtime]:
    from dataset.db import migrate

    settings = make_settings(tmp_path / "ws", vlm_backend="openai", vlm_base_url=vlm.base_url, vlm_model="test-vlm")
    migrate(settings.database_url)
    runtime = Runtime(settings)
    yield runtime
    runtime.close()


def test_heuristic_prefilter_after_ingest_sends_frames_to_curators(runtime: Runtime, tmp_path: Path) -> None:
    [scene] = write_synthetic_dataset(tmp_path / "s", videos=1, seed=4, n_frames=4, width=320, height=180)
    ingest(runtime, scene, prefilter=True)
    assert states(runtime) == ["prefiltered"] * 4
    with runtime.sessions() as s:
        results = s.scalars(select(PrefilterResult)).all()
        assert funnel_counts(s)["prefiltered"] == 4
    assert len(results) == 4
    for r in results:
        assert (r.backend, r.model_id, r.prompt_version) == ("heuristic", "heuristic-v1", "paper-v1")
        assert len(r.answers) == 12 and r.answers[0] is None and r.answers[8] is False  # sharp: not blurry
        assert r.keep is None and r.metrics["laplacian_var"] > 0 and r.reason


def test_openai_verdicts_move_frames_by_the_keep_rule(openai_rt: Runtime, tmp_path: Path, vlm: LocalVLMServer) -> None:
    ingest(openai_rt, write_video(tmp_path / "v.avi", [200, 30, 130, 220]))
    with transaction(openai_rt.sessions) as s:
        [job] = launch_prefilter(s, openai_rt.submit, None)
    job_service.run_queued_jobs(HANDLERS, openai_rt)
    assert states(openai_rt) == ["prefiltered", "rejected", "prefiltered", "prefiltered"]
    with openai_rt.sessions() as s:
        results = {r.frame_id: r for r in s.scalars(select(PrefilterResult))}
        job = s.get(Job, job.id)
    by_index = [results[i] for i in sorted(results)]
    assert [r.keep for r in by_index] == [True, False, None, True]
    assert by_index[1].reason.startswith("rejected") and "Q9" in by_index[1].reason
    assert not by_index[2].parsed and "not sure" in by_index[2].raw_answer  # unreadable → a human decides
    assert by_index[0].model_id == "test-vlm" and by_index[0].backend == "openai"
    assert job.result == {"frames": 4, "keep": 2, "reject": 1, "undecided": 1, "unparsed": 1,
                          "backend": "openai", "model_id": "test-vlm"}


def test_sparse_mode_removes_the_window_around_a_rejected_sample(openai_rt: Runtime, tmp_path: Path,
                                                                  vlm: LocalVLMServer) -> None:
    levels = [200] * 40
    levels[10] = 30  # step = 4, samples at 2, 6, 10, …: the dark frame is a sample
    ingest(openai_rt, write_video(tmp_path / "v.avi", levels))
    before = vlm.request_count
    with transaction(openai_rt.sessions) as s:
        launch_prefilter(s, openai_rt.submit, None, sparse=True)
    job_service.run_queued_jobs(HANDLERS, openai_rt)
    assert vlm.request_count - before == 10  # one question per step-block, not per frame
    got = states(openai_rt)
    assert [i for i, st in enumerate(got) if st == "rejected"] == [8, 9, 10, 11, 12]
    with openai_rt.sessions() as s:
        inferred = s.scalars(select(PrefilterResult).where(PrefilterResult.backend == "openai+sparse")).all()
    assert len(inferred) == 30 and all(r.metrics["sparse_step"] == 4 for r in inferred)


def test_frames_are_claimed_once_and_retries_do_not_ask_again(openai_rt: Runtime, tmp_path: Path,
                                                               vlm: LocalVLMServer) -> None:
    ingest(openai_rt, write_video(tmp_path / "v.avi", [200] * 10))
    with transaction(openai_rt.sessions) as s:
        jobs = launch_prefilter(s, openai_rt.submit, None, chunk=4)
    assert [len(j.params["frame_ids"]) for j in jobs] == [4, 4, 2]
    with transaction(openai_rt.sessions) as s:
        assert launch_prefilter(s, openai_rt.submit, None) == []  # all claimed by queued jobs
    job_service.run_queued_jobs(HANDLERS, openai_rt)
    before = vlm.request_count
    with transaction(openai_rt.sessions) as s:  # a retry of a finished chunk finds nothing left to ask
        job = s.get(Job, jobs[0].id)
        job.state = job.state.failed
        job_service.mark_for_retry(s, job.id)
    job_service.run_queued_jobs(HANDLERS, openai_rt)
    assert vlm.request_count == before
    with openai_rt.sessions() as s:
        per_frame = s.execute(select(PrefilterResult.frame_id, func.count()).group_by(PrefilterResult.frame_id)).all()
    assert len(per_frame) == 10 and {n for _, n in per_frame} == {1}


@pytest.fixture
def extra_settings(vlm: LocalVLMServer) -> dict[str, Any]:
    return {"vlm_backend": "openai", "vlm_base_url": vlm.base_url, "vlm_model": "test-vlm"}


def test_workers_share_the_backlog_without_asking_twice(rt: Runtime, start_worker, tmp_path: Path,
                                                         vlm: LocalVLMServer) -> None:
    ingest(rt, write_video(tmp_path / "v.avi", [200] * 24))
    before = vlm.request_count
    start_worker()
    start_worker()
    with transaction(rt.sessions) as s:
        jobs = launch_prefilter(s, rt.submit, None, chunk=3)
    finished = [wait_for(rt, j.id, lambda job: job.state.finished) for j in jobs]
    assert all(j.state.value == "succeeded" for j in finished), [j.error for j in finished]
    assert all(j.attempts == 1 for j in finished)
    assert vlm.request_count - before == 24
    assert states(rt) == ["prefiltered"] * 24


def test_the_keep_rule_comes_from_settings(tmp_path: Path, vlm: LocalVLMServer) -> None:
    """A lab that doesn't care about corner watermarks drops the veto; one that wants only screens
    (Q5) narrows keep_any_of."""
    from dataset.db import migrate

    settings = make_settings(tmp_path / "ws", vlm_backend="openai", vlm_base_url=vlm.base_url, vlm_model="rule-test",
                             vlm_keep_any_of=(5,))
    migrate(settings.database_url)
    runtime = Runtime(settings)
    ingest(runtime, write_video(tmp_path / "v.avi", [200, 200]))
    with transaction(runtime.sessions) as s:
        launch_prefilter(s, runtime.submit, None)
    job_service.run_queued_jobs(HANDLERS, runtime)
    assert states(runtime) == ["rejected", "rejected"]  # the answers say Q2 yes, but only Q5 counts now
    runtime.close()
