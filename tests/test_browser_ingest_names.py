"""Two uploads of files with one name on the Ingest page, in a real browser at 1366x768: each row
says what tells it apart, its size and when its upload began under the name, and once ingested the
video it became beside its frame count; a reload keeps the list."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from dataset.db import migrate, transaction
from dataset.services import jobs as job_service
from dataset.services import users as user_service
from dataset.synthetic import write_synthetic_dataset
from dataset.tables import Role
from tests.browser import collect_errors, login, serving
from tests.conftest import PASSWORD, make_settings
from webapp.jobs.handlers import HANDLERS
from webapp.runtime import Runtime

pytestmark = pytest.mark.browser
VIEWPORT = {"width": 1366, "height": 768}
FACTS = r"\d+(\.\d+)? (bytes|KiB|MiB) · \d{1,2}:\d\d:\d\d(\s?[AP]M)?"  # the browser's own time format


def test_two_files_of_one_name_are_told_apart(browser, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    settings = make_settings(tmp_path / "ws")
    migrate(settings.database_url)
    rt = Runtime(settings)
    with transaction(rt.sessions) as s:
        user_service.create_user(s, "curator", Role.curator, PASSWORD)
    # two different videos, both called video.mp4, of different lengths
    short, long = (write_synthetic_dataset(tmp_path / f"s{n}", videos=1, seed=seed, n_frames=n, width=160, height=90)[0]
                   for seed, n in ((3, 3), (4, 8)))
    files = [{"name": "video.mp4", "mimeType": "video/mp4", "buffer": (scene / "video.mp4").read_bytes()}
             for scene in (short, long)]
    assert len(files[0]["buffer"]) != len(files[1]["buffer"])

    with serving(settings.home) as url:
        context = browser.new_context(viewport=VIEWPORT)
        page = context.new_page()
        errors = collect_errors(page)
        login(page, url, "curator", PASSWORD)
        page.click("[data-nav=ingest]")
        page.set_input_files("input[name=file]", files=files)
        page.uncheck("input[name=prefilter]")
        page.click("#upload button[type=submit]")
        rows = page.locator("#uploads li")
        expect(rows).to_have_count(2)
        for row in (rows.nth(0), rows.nth(1)):
            expect(row.locator(".status")).to_contain_text("queued")
            expect(row.locator(".name")).to_have_text("video.mp4")
            expect(row.locator(".file-facts")).to_have_text(re.compile(f"^{FACTS}$"))
        before = [rows.nth(k).locator(".file-facts").inner_text() for k in (0, 1)]
        assert before[0] != before[1], before  # the sizes differ

        job_service.run_queued_jobs(HANDLERS, rt)  # the worker's part
        made = []
        for row in (rows.nth(0), rows.nth(1)):
            status = row.locator(".status")
            expect(status).to_contain_text(re.compile(r"succeeded — \d+ frames?, .* · video #\d+$"), timeout=15_000)
            video = status.locator("a", has_text="video #")
            expect(video).to_have_attribute("href", re.compile(r"^/review\?video_id=\d+$"))
            made.append(video.inner_text())
            expect(row.locator(".file-facts")).to_have_text(re.compile(f"^{FACTS}$"))
        assert made[0] != made[1], made
        # a reload keeps the list: the same rows, each with its video, the time of its upload under the name
        page.reload()
        expect(rows).to_have_count(2)
        for row, video in zip((rows.nth(0), rows.nth(1)), made, strict=True):
            expect(row.locator(".name")).to_have_text("video.mp4")
            expect(row.locator(".status")).to_contain_text(re.compile(rf"succeeded — .* · {video}$"))
            expect(row.locator(".file-facts")).to_have_text(re.compile(r"^uploaded \d{1,2}:\d\d:\d\d(\s?[AP]M)?$"))
        # the facts sit on one line under the name, and the page keeps the window's width
        name_box, facts_box = rows.nth(0).locator(".name").bounding_box(), rows.nth(0).locator(".file-facts").bounding_box()
        assert facts_box["y"] >= name_box["y"] + name_box["height"] and abs(facts_box["x"] - name_box["x"]) < 1
        assert facts_box["height"] < 1.5 * name_box["height"]
        assert page.evaluate("document.documentElement.scrollWidth") <= VIEWPORT["width"]
        page.screenshot(path=str(tmp_path / "ingest-names.png"), full_page=True)
        assert errors == []
        context.close()
