"""The curator→annotator loop and the run pages in a real browser at 1366×768:
Annotate names the frame a curator sent back while the annotator holds another, and its link
opens it with the held frame's lease kept; the proposals panel counts a frame's decided proposals
instead of saying it had none; a curator rejects a sample with a note, and the page says who, when
and why, a rejected sample and its frame's resubmission linking each other; a cancelled run's job
reads cancelled, plainly, with the time of both its attempts; Compare warns of runs of one dataset
version split with different seeds; "predictions" is off without a dataset root; and an annotator
opening someone else's job gets the app's 404 page."""

from __future__ import annotations

from collections.abc import Iterator
from datetime import timedelta
from typing import Any

import numpy as np
import pytest
from sqlalchemy import select

from core.formats import mask_to_rle
from dataset.db import migrate, transaction
from dataset.services import users as user_service
from dataset.services.annotate import frame_detail, save_annotation, take_lease
from dataset.services.frames import update_frame
from dataset.services.sample_review import review_sample
from dataset.tables import (
    Annotation,
    Frame,
    FrameState,
    Job,
    JobState,
    Proposal,
    ProposalFate,
    ProposalScan,
    Role,
    RunState,
    Sample,
    SampleState,
    TrainingRun,
    utcnow,
)
from tests.browser import login, page_with_errors, serving
from tests.conftest import PASSWORD, make_settings
from tests.test_generate import prepare
from tests.test_returned_frames import submitted_and_generated
from webapp.runtime import Runtime

pytestmark = pytest.mark.browser

REASON, NOTE = "mask misses the illusion", "the picture's left edge is outside the mask"


def _sample(s: Any, media: Any, frame: Frame, annotator: Any) -> int:
    """The annotator submits the frame; its sample is made, with the QA figure its page shows first."""
    sample = submitted_and_generated(s, media, frame, annotator)
    sample.qa = {"hole_fraction": 0.01, "flags": []}
    return sample.id


def _proposals(s: Any, frame: Frame, fates: tuple[ProposalFate, ...]) -> None:
    """plane-break looked at the frame and proposed one illusion per fate, decided as given."""
    scan = ProposalScan(frame_id=frame.id, source="plane-break", content_sha256=frame.content_sha256)
    region = mask_to_rle(np.zeros((frame.height, frame.width), bool))
    scan.proposals = [Proposal(frame_id=frame.id, source="plane-break", rank=i, type_guess="picture", score=0.9 - i / 10,
                               illusion_rle=region, support_rle=region, fate=fate) for i, fate in enumerate(fates)]
    s.add(scan)


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, dict[str, Any]]]:
    """Six approved frames. The annotator holds the first (its 2 proposals rejected); the curator sent the
    third back with a note (its proposals decided at submit: 1 taken, 1 rejected); the fourth's sample
    awaits review; the fifth's sample was rejected and its resubmission made another. Two runs of one
    dataset version, seeds 0 and 7; the first was cancelled after two attempts of its job (the admin's)."""
    home = tmp_path_factory.mktemp("loop") / "ws"
    settings = make_settings(home)
    migrate(settings.database_url)
    rt = Runtime(settings)
    prepare(rt, tmp_path_factory.mktemp("scene"), n_frames=6, annotate=False)
    with transaction(rt.sessions) as s:
        people = {role.value: user_service.create_user(s, role.value, role, PASSWORD) for role in Role}
        annotator, curator = people["annotator"], people["curator"]
        frames = s.scalars(select(Frame).order_by(Frame.index)).all()
        take_lease(s, frames[0].id, annotator, 3600)
        _proposals(s, frames[0], (ProposalFate.rejected, ProposalFate.rejected))
        returned = _sample(s, rt.media, frames[2], annotator)
        _proposals(s, frames[2], (ProposalFate.accepted, ProposalFate.rejected))  # as its submit decided them
        review_sample(s, returned, curator, "reject", REASON, NOTE)
        pending = _sample(s, rt.media, frames[3], annotator)
        first = _sample(s, rt.media, frames[4], annotator)
        review_sample(s, first, curator, "reject", "bad right view")
        ann = s.scalar(select(Annotation).where(Annotation.frame_id == frames[4].id))
        again = save_annotation(s, frames[4].id, annotator, version=ann.version,
                                regions=frame_detail(s, frames[4].id, annotator)["regions"], illusion_type=None, submit=True)
        update_frame(s, frames[4], state=FrameState.generated)
        second = Sample(frame_id=frames[4].id, annotation_version=again.version, state=SampleState.generated,
                        qa={"hole_fraction": 0.01, "flags": []})
        s.add(second)
        start = utcnow() - timedelta(hours=1)
        job = Job(kind="train", params={"run_id": 1}, state=JobState.failed, attempts=2, ran_s=60.0,
                  error="run 1 cancelled: cancelled by admin at step 20", created_by_id=people["admin"].id,
                  started_at=start, finished_at=start + timedelta(seconds=30))
        s.add(job)
        s.flush()
        for seed, state in ((0, RunState.cancelled), (7, RunState.succeeded)):
            s.add(TrainingRun(preset="lite", config={"train": {"steps": 40}}, dataset_id="ab" * 32,
                              dataset={"id": "ab" * 32, "items": []}, splits={"train": [1], "val": [2], "test": []},
                              launch={"split": {"train": 0.8, "val": 0.1, "test": 0.1}, "seed": seed},
                              state=state, job_id=job.id if seed == 0 else None))
        s.flush()
        ids = {"frames": [f.id for f in frames], "returned": returned, "pending": pending, "first": first,
               "second": second.id, "job": job.id}
    rt.close()
    with serving(home) as url:
        yield url, ids


def test_annotate_names_the_frame_sent_back_and_counts_decided_proposals(browser, server) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    url, ids = server
    held, returned = ids["frames"][0], ids["frames"][2]
    page, errors = page_with_errors(browser)
    login(page, url, "annotator", PASSWORD)
    page.goto(url + "/annotate")
    page.wait_for_function("(id) => window.annotator?.frame?.id === id", arg=held)
    # the held frame, with the frame that came back named above the stage
    banner = page.locator("#came-back")
    expect(banner).to_be_visible()
    expect(banner).to_contain_text(f"Frame #{returned} came back to you: curator rejected its sample")
    expect(banner).to_contain_text(f"{REASON} — {NOTE}")
    expect(page.locator("#returned")).to_be_hidden()
    # its two rejected proposals are counted, not "found nothing"
    note = page.locator("#proposals-note")
    expect(note).to_have_text("The proposers found 2 proposals in this frame; none is left to decide: 2 rejected.")

    page.locator("#came-back-link").click()
    page.wait_for_function("(id) => window.annotator?.frame?.id === id", arg=returned)
    assert page.url == f"{url}/annotate/{returned}"
    expect(page.locator("#returned-reason")).to_have_text(f"{REASON} — {NOTE}")
    expect(banner).to_be_hidden()
    expect(note).to_have_text("The proposers found 2 proposals in this frame; none is left to decide: "
                              "1 taken as a plane, 1 rejected.")
    lease = page.request.get(f"{url}/api/v1/frames/{held}").json()["lease"]
    assert lease["mine"] and lease["expires"], lease  # the frame left keeps its lease
    page.go_back()  # Back returns to the held frame, still the annotator's
    page.wait_for_function("(id) => window.annotator?.frame?.id === id", arg=held)
    assert page.url == f"{url}/annotate/{held}"
    expect(banner).to_be_visible()
    assert errors == [], errors

    # someone else's job: the app's 404 page (the only error logged: its own status), nothing polling an API
    response = page.goto(f"{url}/jobs/{ids['job']}")
    assert response.status == 404
    expect(page.locator("main h1")).to_have_text("404")
    expect(page.locator("main")).to_contain_text(f"no job {ids['job']}")
    page.wait_for_timeout(2000)  # the job page polled every 1.5 s
    assert [e for e in errors if "404" not in e] == [] and len(errors) == 1, errors


def test_a_curator_rejects_with_a_note_and_the_sample_pages_say_it(browser, server) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    url, ids = server
    page, errors = page_with_errors(browser)
    login(page, url, "curator", PASSWORD)
    page.goto(f"{url}/samples/{ids['pending']}")
    expect(page.locator("#rejection")).to_be_hidden()
    page.keyboard.press("r")
    picker = page.locator("#reason-picker")
    expect(picker).to_be_visible()
    expect(picker.locator("button.reason").first).to_be_focused()  # 1–5 pick at once; the note is a click away
    picker.locator("input[name=note]").fill(NOTE)
    picker.locator("input[name=note]").press("Enter")  # picks nothing
    expect(picker).to_be_visible()
    picker.locator("input[name=note]").press("2")  # typed into the note, not a reason's key
    expect(picker).to_be_visible()
    picker.locator("input[name=note]").press("Backspace")
    picker.locator("button.reason", has_text=REASON).click()
    rejection = page.locator("#rejection")
    expect(rejection).to_be_visible()
    expect(rejection).to_contain_text("Rejected by curator on ")
    expect(rejection).to_contain_text(f": {REASON} — {NOTE}")
    stored = page.request.get(f"{url}/api/v1/samples/{ids['pending']}").json()["rejection"]
    assert (stored["reason"], stored["note"], stored["by"]) == (REASON, NOTE, "curator")
    page.reload()  # said again from the server
    expect(rejection).to_contain_text(f": {REASON} — {NOTE}")

    # a rejected sample and its frame's resubmission link each other
    page.goto(f"{url}/samples/{ids['first']}")
    expect(page.locator("#rejection")).to_contain_text("Rejected by curator on ")
    expect(page.locator("#rejection")).to_contain_text(": bad right view")
    page.locator("#replaced-by a").click()
    page.wait_for_url(f"{url}/samples/{ids['second']}")
    expect(page.locator("#replaces")).to_contain_text(f"sample #{ids['first']} (rejected)")
    expect(page.locator("#rejection")).to_be_hidden()
    assert errors == [], errors


def test_cancelled_job_compare_warning_and_rootless_predictions(browser, server) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    url, ids = server
    page, errors = page_with_errors(browser)
    login(page, url, "admin", PASSWORD)
    page.goto(f"{url}/jobs/{ids['job']}")
    state = page.locator("#job-state")
    expect(state).to_have_text("cancelled")
    assert state.evaluate("(e) => getComputedStyle(e).color") == page.locator("h1").evaluate(
        "(e) => getComputedStyle(e).color")  # neutral: the heading's colour, not the failed red
    expect(page.locator("#job-summary")).not_to_have_class("error")
    expect(page.locator("#job-times")).to_contain_text("1 min 30 s over 2 attempts")
    page.goto(f"{url}/jobs")
    row = page.locator(f"#jobs tr[data-job-id='{ids['job']}']")
    expect(row.locator(".state")).to_have_text("cancelled")
    expect(row.locator("button", has_text="Retry")).to_be_visible()  # a retry resumes the run

    page.goto(f"{url}/models/compare?ids=1,2")
    warning = page.locator("#compare-versions")
    expect(warning).to_be_visible()
    expect(warning).to_contain_text("share dataset version abababababab but split it differently")
    expect(warning).to_contain_text("run 1: seed 0")
    expect(warning).to_contain_text("run 2: seed 7")

    page.goto(f"{url}/evaluations")
    expect(page.locator("input[name=methods][value=predictions]")).to_be_disabled()
    expect(page.locator("label", has=page.locator("input[value=predictions]"))).to_contain_text(
        "no dataset root is registered")
    assert errors == [], errors
