"""A workspace that cannot make samples from an uploaded video says so where the work starts, in a
real browser: the Ingest page and the upload's row, the review tile, and above the annotation stage."""

from __future__ import annotations

from pathlib import Path

import pytest
from sqlalchemy import update

from dataset.db import migrate, transaction
from dataset.models import Frame, FrameState, Role
from dataset.services import users as user_service
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
        context.close()
    assert errors == [], errors
