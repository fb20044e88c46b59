"""The curator→annotator loop and the run pages a newcomer tripped over,
their service parts: frames sent back to an annotator who holds another one are named with it
(and the held one keeps its lease); a rejection's note, curator and time on the sample, and a rejected
sample and its frame's resubmission linked both ways; a cancelled run's job says cancelled and took
the time of every attempt; an evaluation's worst and best samples never overlap; the jobs page of a
job not one's own is the app's 404; the predictions method is off without a dataset root."""

from __future__ import annotations

from collections.abc import Iterator
from datetime import timedelta
from pathlib import Path
from typing import Any

import pytest
from sqlalchemy import select

from dataset.db import transaction
from dataset.services import users as user_service
from dataset.services.annotate import frame_detail, save_annotation, take_lease
from dataset.services.errors import InvalidInput
from dataset.services.jobs import job_json, mark_for_retry
from dataset.services.sample_review import review_sample, sample_detail
from dataset.tables import Annotation, Frame, Job, JobState, Role, RunState, Sample, SampleState, TrainingRun, User, utcnow
from model.runs.report import ranked_samples
from tests.conftest import login
from tests.test_annotate import auth
from tests.test_generate import prepare
from tests.test_returned_frames import submitted_and_generated
from webapp.runtime import Runtime

REASON, NOTE = "mask misses the illusion", "the picture's left edge is outside the mask"


@pytest.fixture
def loop(runtime: Runtime, tmp_path: Path) -> Iterator[dict[str, Any]]:
    """Four approved frames; `ana` submitted the third and the fourth, whose samples a curator may review."""
    prepare(runtime, tmp_path, n_frames=4, annotate=False)
    with transaction(runtime.sessions) as s:
        people = {name: user_service.create_user(s, name, role, "long-enough-pw")
                  for name, role in (("ana", Role.annotator), ("bo", Role.annotator), ("cy", Role.curator))}
        frames = s.scalars(select(Frame).order_by(Frame.index)).all()
        samples = [submitted_and_generated(s, runtime.media, frames[i], people["ana"]).id for i in (2, 3)]
    yield {"people": people, "frames": [f.id for f in frames], "samples": samples}


def test_a_frame_sent_back_is_named_beside_the_frame_the_annotator_holds(runtime: Runtime, loop: dict[str, Any]) -> None:
    people, frames = loop["people"], loop["frames"]
    with transaction(runtime.sessions) as s:
        take_lease(s, frames[0], people["ana"], 600)  # she is at work on the first frame
        assert frame_detail(s, frames[0], people["ana"])["returned_waiting"] is None
        review_sample(s, loop["samples"][0], people["cy"], "reject", REASON, NOTE)
        review_sample(s, loop["samples"][1], people["cy"], "reject", "bad right view")
    with transaction(runtime.sessions) as s:
        waiting = frame_detail(s, frames[0], people["ana"])["returned_waiting"]
        assert waiting["count"] == 2 and [f["frame_id"] for f in waiting["frames"]] == [frames[2], frames[3]]
        first = waiting["frames"][0]
        assert (first["reason"], first["note"], first["by"], first["sample_id"]) == (REASON, NOTE, "cy", loop["samples"][0])
        # on a returned frame, the other one is named; the frame on screen is not
        on_returned = frame_detail(s, frames[2], people["ana"])
        assert on_returned["returned"]["note"] == NOTE
        assert [f["frame_id"] for f in on_returned["returned_waiting"]["frames"]] == [frames[3]]
        # frames sent back to her wait for her, not for bo; one bo holds now waits for no one else
        assert frame_detail(s, frames[0], people["bo"])["returned_waiting"] is None
        take_lease(s, frames[3], people["bo"], 600)
        assert frame_detail(s, frames[0], people["ana"])["returned_waiting"]["count"] == 1
        # opening the returned frame leaves her lease on the first one as it was
        held = s.scalar(select(Annotation).where(Annotation.frame_id == frames[0]))
        take_lease(s, frames[2], people["ana"], 600)
        assert held.lease_user_id == people["ana"].id and held.lease_expires_at > utcnow()


def test_the_lease_renewal_names_the_frames_sent_back_meanwhile(client, tokens, runtime: Runtime,  # type: ignore[no-untyped-def]
                                                               tmp_path: Path) -> None:
    prepare(runtime, tmp_path, n_frames=2, annotate=False)
    with transaction(runtime.sessions) as s:
        annotator = s.scalar(select(User).where(User.name == "annotator"))
        curator = s.scalar(select(User).where(User.name == "curator"))
        first, second = s.scalars(select(Frame.id).order_by(Frame.index)).all()
        sample = submitted_and_generated(s, runtime.media, s.get(Frame, second), annotator).id
    renewed = client.post(f"/api/v1/frames/{first}/lease", headers=auth(tokens))
    assert renewed.status_code == 200 and renewed.json["returned_waiting"] is None
    with transaction(runtime.sessions) as s:
        review_sample(s, sample, curator, "reject", REASON, NOTE)
    renewed = client.post(f"/api/v1/frames/{first}/lease", headers=auth(tokens)).json
    assert renewed["returned_waiting"]["count"] == 1
    assert renewed["returned_waiting"]["frames"][0] | {"at": None} == {
        "frame_id": second, "sample_id": sample, "reason": REASON, "note": NOTE, "by": "curator", "at": None,
        "annotator": "annotator"}


def test_a_rejected_sample_says_who_when_why_and_links_to_its_resubmission(runtime: Runtime, loop: dict[str, Any]) -> None:
    people, frames, [rejected, _] = loop["people"], loop["frames"], loop["samples"]
    with transaction(runtime.sessions) as s:
        before = sample_detail(s, rejected)
        assert before["rejection"] is None and before["replaces"] is None and before["replaced_by"] is None
        review_sample(s, rejected, people["cy"], "reject", f" {REASON} ", f"  {NOTE} ")
    with transaction(runtime.sessions) as s:
        said = sample_detail(s, rejected)["rejection"]
        assert (said["reason"], said["note"], said["by"]) == (REASON, NOTE, "cy") and said["at"].endswith("Z")
        # she fixes the frame and submits it again: a new sample, the two linked both ways
        ann = s.scalar(select(Annotation).where(Annotation.frame_id == frames[2]))
        regions = frame_detail(s, frames[2], people["ana"])["regions"]
        save_annotation(s, frames[2], people["ana"], version=ann.version, regions=regions, illusion_type=None,
                        submit=True)
        again = Sample(frame_id=frames[2], annotation_version=ann.version, state=SampleState.generated)
        s.add(again)
        s.flush()
        assert sample_detail(s, rejected)["replaced_by"] == {"id": again.id, "state": "generated"}
        newer = sample_detail(s, again.id)
        assert newer["replaces"] == {"id": rejected, "state": "rejected"} and newer["replaced_by"] is None
        assert newer["rejection"] is None


def test_a_rejection_note_is_bounded_and_goes_with_a_rejection_only(client, tokens, runtime: Runtime,  # type: ignore[no-untyped-def]
                                                                    loop: dict[str, Any]) -> None:
    rejected, accepted = loop["samples"]
    with transaction(runtime.sessions) as s:
        with pytest.raises(InvalidInput, match="note must have at most 256 characters"):
            review_sample(s, rejected, loop["people"]["cy"], "reject", REASON, "x" * 257)
        with pytest.raises(InvalidInput, match="a note goes with a rejection"):
            review_sample(s, accepted, loop["people"]["cy"], "accept", "", NOTE)
    url = f"/api/v1/samples/{rejected}"
    refused = client.post(f"{url}/review", headers=auth(tokens, "curator"), json={"decision": "reject", "reason": REASON,
                                                                                   "note": ["not", "text"]})
    assert refused.status_code == 400 and refused.json["error"] == "note must be a string"
    done = client.post(f"{url}/review", headers=auth(tokens, "curator"),
                       json={"decision": "reject", "reason": REASON, "note": NOTE})
    assert done.status_code == 200 and done.json["rejection"]["note"] == NOTE and done.json["rejection"]["by"] == "curator"
    assert client.get(url, headers=auth(tokens)).json["rejection"]["reason"] == REASON


def test_a_cancelled_runs_job_says_cancelled_and_took_every_attempt(runtime: Runtime) -> None:
    start = utcnow() - timedelta(hours=1)
    with transaction(runtime.sessions) as s:
        job = Job(kind="train", params={"run_id": 1}, state=JobState.failed, attempts=1, error="run 1 cancelled: by ann",
                  started_at=start, finished_at=start + timedelta(seconds=90))
        s.add(job)
        s.flush()
        run = TrainingRun(preset="lite", job_id=job.id, state=RunState.cancelled, dataset_id="ab" * 32)
        s.add(run)
        s.flush()
        assert (job_json(job)["state"], job_json(job)["took_s"]) == ("cancelled", 90.0)
        # resumed: queued again, its first attempt kept; the second runs 30 s and is cancelled again
        run.state = RunState.queued
        mark_for_retry(s, job.id)
        assert job.started_at is None and job_json(job)["took_s"] is None and job_json(job)["state"] == "queued"
        job.state, job.attempts = JobState.failed, 2
        job.started_at, job.finished_at = start + timedelta(minutes=30), start + timedelta(minutes=30, seconds=30)
        run.state = RunState.cancelled
        assert (job_json(job)["state"], job_json(job)["took_s"]) == ("cancelled", 120.0)
        run.state = RunState.failed  # a run that failed is a failed job
        assert job_json(job)["state"] == "failed"
        other = Job(kind="encode", state=JobState.failed, created_at=start)
        s.add(other)
        s.flush()
        assert (job_json(other)["state"], job_json(other)["took_s"]) == ("failed", None)  # never started


@pytest.mark.parametrize(("n", "worst", "best"), [(1, 1, 0), (2, 1, 1), (3, 2, 1), (5, 3, 2), (6, 3, 3), (10, 3, 3)])
def test_the_worst_and_best_samples_never_overlap(n: int, worst: int, best: int) -> None:
    report = {"methods": {"m": {"per_sample": [{"sample": f"s{i}", "regions": {"all": {"epe": float(i)}}}
                                               for i in range(n)]}}}
    got_worst, got_best = ranked_samples(report, "m", count=3)
    assert len(got_worst) == worst and len(got_best) == best and not set(got_worst) & set(got_best)
    assert got_worst == [f"s{i}" for i in range(n - 1, n - 1 - worst, -1)]  # the worst first
    assert got_best == [f"s{i}" for i in range(best)]  # the best first


def test_a_job_page_not_ones_own_is_the_apps_404(app, client, runtime: Runtime) -> None:  # type: ignore[no-untyped-def]
    with transaction(runtime.sessions) as s:
        users = {u.name: u for u in s.scalars(select(User))}
        theirs = Job(kind="encode", created_by_id=users["curator"].id)
        mine = Job(kind="encode", created_by_id=users["annotator"].id)
        s.add_all([theirs, mine])
        s.flush()
        ids = theirs.id, mine.id
    login(client, "annotator")
    for job_id in (ids[0], 9999):
        page = client.get(f"/jobs/{job_id}")
        assert page.status_code == 404 and f"no job {job_id}" in page.get_data(as_text=True)
        assert 'id="job"' not in page.get_data(as_text=True)  # no page polling the API
    assert client.get(f"/jobs/{ids[1]}").status_code == 200
    curator = app.test_client()
    login(curator, "curator")
    assert curator.get(f"/jobs/{ids[0]}").status_code == 200


def test_predictions_is_off_without_a_dataset_root(client, tokens) -> None:  # type: ignore[no-untyped-def]
    login(client, "curator")
    html = client.get("/evaluations").get_data(as_text=True)
    box = html[html.index('value="predictions"') - 80:html.index('value="predictions"') + 300]
    assert "disabled" in box and "no dataset root is registered" in box
