"""A workspace that cannot make samples from an uploaded video says so where the work starts, in a
real browser: the Ingest page and the upload's row, the review tile, and above the annotation stage."""

from __future__ import annotations

import io
import re
from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import update

from dataset.db import migrate, transaction
from dataset.services import jobs as job_service
from dataset.services import users as user_service
from dataset.tables import Frame, FrameState, JobState, Role
from tests.browser import collect_errors, login, serving
from tests.conftest import PASSWORD, make_settings
from tests.test_ingest import run_ingest, write_avi
from webapp.runtime import Runtime

pytestmark = pytest.mark.browser
VIEWPORT = {"width": 1366, "height": 768}


def test_ingest_review_and_annotate_say_why_no_samples(browser, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    settings = make_settings(tmp_path / "ws")
    migrate(settings.database_url)
    rt = Runtime(settings)
    with transaction(rt.sessions) as s:
        user_service.create_user(s, "curator", Role.curator, PASSWORD)
        user_service.create_user(s, "ann", Role.annotator, PASSWORD)
    run_ingest(rt, write_avi(tmp_path / "plain.avi", 3), fps=None, dedup_hamming=None)
    with transaction(rt.sessions) as s:
        s.execute(update(Frame).values(state=FrameState.approved))

    with serving(settings.home) as url:
        context = browser.new_context(viewport=VIEWPORT)
        page = context.new_page()
        errors = collect_errors(page)
        login(page, url, "curator", PASSWORD)
        expect(page.locator("#blocked-videos")).to_contain_text("1 video")
        page.click("[data-nav=ingest]")
        expect(page.locator("#sample-blocker")).to_contain_text("no monocular depth of its own")
        page.set_input_files("input[name=file]", files=[
            {"name": "mine.avi", "mimeType": "video/x-msvideo", "buffer": write_avi(tmp_path / "u.avi", 4, seed=2).read_bytes()}])
        page.uncheck("input[name=prefilter]")
        page.click("#upload button[type=submit]")
        expect(page.locator("#uploads li .sample-blocker")).to_contain_text("No samples from this video")
        # with its disparities beside it, a video can: its row says nothing of the kind
        depth = io.BytesIO()
        np.save(depth, np.ones((90, 160), np.float32))
        page.set_input_files("input[name=file]", files=[
            {"name": "own.avi", "mimeType": "video/x-msvideo", "buffer": write_avi(tmp_path / "o.avi", 2, seed=3).read_bytes()}])
        page.set_input_files("input[name=mono]", files=[
            {"name": "frame_000000.npy", "mimeType": "application/octet-stream", "buffer": depth.getvalue()}])
        page.uncheck("input[name=prefilter]")
        page.click("#upload button[type=submit]")
        expect(page.locator("#uploads li")).to_have_count(2)
        expect(page.locator("#uploads li").first.locator(".status")).to_contain_text("ingest job")
        expect(page.locator("#uploads li").first.locator(".sample-blocker")).to_have_count(0)
        page.goto(url + "/review?state=approved")
        expect(page.locator(".tile .sample-blocker").first).to_contain_text("depth_backend")
        context.close()

        context = browser.new_context(viewport=VIEWPORT)
        page = context.new_page()
        errors += collect_errors(page)
        login(page, url, "ann", PASSWORD)
        page.goto(url + "/annotate")
        expect(page.locator("#sample-note")).to_be_visible()
        expect(page.locator("#sample-note-title")).to_contain_text("a submit is refused")
        expect(page.locator("#sample-note-reason")).to_contain_text("depth_model_path")
        page.screenshot(path=str(tmp_path / "annotate-blocked.png"))

        # a submit is refused with the reason; the planes stay, saved as a draft, and saving goes on
        frame_id = int(page.url.rsplit("/", 1)[1])
        page.wait_for_function("() => window.annotator?.pairs?.length === 1")
        for key, (x, y) in (("b", (40, 30)), ("s", (110, 60))):
            page.keyboard.press(key)
            cx, cy = page.evaluate("([x, y]) => window.annotator.imageToClient(x, y)", [x, y])
            page.mouse.move(cx, cy)
            page.mouse.down()
            page.mouse.move(cx + 20, cy + 10, steps=5)
            page.mouse.up()
        page.wait_for_function("() => window.annotator.pairs[0].illusion > 0 && window.annotator.pairs[0].support > 0")
        page.keyboard.press("t")
        page.keyboard.press("2")
        page.wait_for_function("() => window.annotator.pairs[0].type === 'picture'")
        page.locator("#canvas").focus()
        page.keyboard.press("Enter")
        expect(page.locator("#message")).to_contain_text(re.compile(r"not submitted \(your regions are saved as a draft\)",
                                                                    re.IGNORECASE))
        assert page.url.endswith(f"/annotate/{frame_id}")
        saved = page.request.get(f"{url}/api/v1/frames/{frame_id}").json()
        assert (saved["submitted"], saved["state"], len(saved["regions"])) == (False, "approved", 2), saved
        page.keyboard.press("b")
        cx, cy = page.evaluate("([x, y]) => window.annotator.imageToClient(x, y)", [20, 70])
        page.mouse.move(cx, cy)
        page.mouse.down()
        page.mouse.move(cx + 10, cy, steps=3)
        page.mouse.up()
        page.wait_for_function("() => !window.annotator.dirty", timeout=10_000)  # no stale-version conflict
        expect(page.locator("#message")).not_to_contain_text("changed since")
        context.close()

        # a generate job that failed anyway: the Dashboard counts it, and the retry says what still blocks it
        with transaction(rt.sessions) as s:
            s.execute(update(Frame).where(Frame.id == frame_id).values(state=FrameState.annotated))
            job = job_service.create_job(s, "generate", {"frame_id": frame_id}, None)
            job.state, job.error = JobState.failed, "no monocular disparity"
        context = browser.new_context(viewport=VIEWPORT)
        page = context.new_page()
        errors += collect_errors(page)
        login(page, url, "curator", PASSWORD)
        expect(page.locator("#generate-failed")).to_contain_text("1 annotated frame has no sample")
        page.click("#retry-generates")
        expect(page.locator("#retry-generates-result")).to_contain_text("Queued 0 again. 1 still cannot: this workspace")
        context.close()
    assert errors == [], errors
