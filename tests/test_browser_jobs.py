"""Ingest and the Jobs pages in a real browser at 1366x768: a double-click uploads once, a
re-upload says the video is already there, the jobs table fits the window, and a job's page
shows its log, parameters, timings and links to what it made."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.browser import login, running_demo

pytestmark = pytest.mark.browser


def test_upload_once_reupload_said_plainly_and_the_job_pages(browser, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    home = tmp_path / "ws"
    with running_demo(home, videos=1) as url:
        page = browser.new_page(viewport={"width": 1366, "height": 768})
        console: list[str] = []
        page.on("console", lambda m: console.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: console.append(str(e)))
        login(page, url, "curator", "curator-demo")
        video = home / "synthetic" / "synthetic-0000" / "video.mp4"

        page.click("[data-nav=ingest]")
        page.set_input_files("#upload input[type=file]", str(video))
        page.dblclick("#upload button[type=submit]")
        rows = page.locator("#uploads li")
        expect(rows.first.locator(".status")).to_contain_text("succeeded", timeout=60_000)
        assert rows.count() == 1  # the second click found the button disabled
        expect(rows.first.locator(".status")).to_contain_text(re.compile(r"\d+ frames, \d+ near-duplicates? dropped"))

        page.set_input_files("#upload input[type=file]", str(video))
        page.click("#upload button[type=submit]")
        expect(rows.first.locator(".status")).to_contain_text(
            re.compile(r"already in the workspace as video \d+ \(“video\.mp4”\) with \d+ frames: nothing new to ingest"),
            timeout=60_000)
        assert rows.count() == 2

        page.click("[data-nav=jobs]")
        page.wait_for_selector("#jobs tbody tr[data-state=succeeded]")
        expect(page.locator("#jobs tbody tr").first.locator(".outcome")).to_contain_text("already in the workspace")
        assert page.evaluate("document.documentElement.scrollWidth") <= 1366  # the table fits the window
        page.screenshot(path=str(tmp_path / "jobs.png"))

        ingest = page.locator("#jobs tbody tr", has=page.locator("td:nth-child(2)", has_text="ingest")).last
        job_id = ingest.get_attribute("data-job-id")
        ingest.locator("td:first-child a").click()
        page.wait_for_url(f"{url}/jobs/{job_id}")
        expect(page.locator("#job-state")).to_have_text("succeeded")
        expect(page.locator("#job-log")).to_contain_text("sampling at")
        expect(page.locator("#job-params")).to_contain_text("fps")
        expect(page.locator("#job-times")).to_contain_text("took")
        expect(page.locator("#job-made a").first).to_have_attribute("href", re.compile(r"^/review\?video_id=\d+$"))
        assert str(home) not in page.locator("#job").inner_text()  # no server folders on the page
        page.screenshot(path=str(tmp_path / "job.png"), full_page=True)

        missing = page.goto(f"{url}/jobs/99999")  # the app's 404 page, as its API answers
        assert missing.status == 404
        expect(page.locator("main")).to_contain_text("no job 99999")
        console = [c for c in console if "404" not in c]  # the missing job's page, on purpose
        assert console == []
        page.close()
