"""The list pages and the sample page in a real browser at 1366x768: the Frames pager never runs
past the end and keeps its place in the address, the pager takes odd addresses with care, tiles
open their frame, every page with shortcuts explains them under `?`, labels agree, a refused retry
stays said, and an ended session says so politely and leads back."""

from __future__ import annotations

import json
import re
import urllib.parse
from collections import Counter
from pathlib import Path

import pytest

from tests.browser import login, running_demo

pytestmark = pytest.mark.browser
VIEWPORT = {"width": 1366, "height": 768}


@pytest.fixture(scope="module")
def demo_url(tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    with running_demo(tmp_path_factory.mktemp("demo") / "ws", videos=1) as url:
        yield url


@pytest.fixture
def open_page(browser, demo_url: str):  # type: ignore[no-untyped-def]
    """Opens a page in a fresh context logged in as a role: (page, the list its script errors go
    to). Every context is closed after the test, its routes first: a page left polling would run
    its route handlers against a server the next test has stopped."""
    contexts = []

    def open_(role: str):  # type: ignore[no-untyped-def]
        context = browser.new_context(viewport=VIEWPORT)
        contexts.append(context)
        page = context.new_page()
        errors: list[str] = []
        page.on("pageerror", lambda error: errors.append(str(error)))
        login(page, demo_url, role, f"{role}-demo")
        return page, errors

    yield open_
    for context in contexts:
        for page in context.pages:
            page.unroute_all(behavior="ignoreErrors")
        context.close()


def _place(item: dict, frame_id: int | None = None) -> str:
    """Where a frame is, as every page says it (labels.js framePlace): video name, frame id, time."""
    return f"{item['video']} · frame #{frame_id or item['id']} · {item['time_s']:.1f} s"


def _tile_ids(page) -> list[int]:  # type: ignore[no-untyped-def]
    return [int(i) for i in page.locator("#frame-grid li[data-frame-id]").evaluate_all(
        "nodes => nodes.map(n => n.dataset.frameId)")]


def test_frames_pages_within_bounds_keeps_its_place_and_opens_frames(open_page, demo_url: str, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    page, errors = open_page("annotator")
    every = json.loads(page.evaluate("u => fetch(u).then(r => r.text())", "/api/v1/frames?limit=500"))
    ids, total = [f["id"] for f in every["items"]], every["total"]
    assert total == len(ids) > 10

    page.goto(demo_url + "/frames?limit=3")
    expect(page.locator("#frame-total")).to_have_text(f"1–3 of {total}")
    assert _tile_ids(page) == ids[:3]
    caption = page.locator("#frame-grid .caption").first
    expect(caption).to_contain_text(_place(every["items"][0]))
    page.screenshot(path=str(tmp_path / "frames.png"))

    # Keys pressed faster than pages load: each moves one page, and the range says which.
    for _ in range(3):
        page.keyboard.press("]")
    expect(page.locator("#frame-total")).to_have_text(f"10–12 of {total}")
    assert _tile_ids(page) == ids[9:12]
    page.keyboard.press("[")
    expect(page.locator("#frame-total")).to_have_text(f"7–9 of {total}")
    assert _tile_ids(page) == ids[6:9]
    # to the last page, and once more: nothing past the end
    n_last = total % 3 or 3
    last = f"{total - n_last + 1}–{total} of {total}"
    for _ in range(total // 3 + 1):
        page.keyboard.press("n")
    expect(page.locator("#frame-total")).to_have_text(last)
    assert _tile_ids(page) == ids[-n_last:]
    expect(page.locator("#next-page")).to_be_disabled()
    page.keyboard.press("]")
    page.wait_for_load_state("networkidle")
    expect(page.locator("#frame-total")).to_have_text(last)
    assert _tile_ids(page) == ids[-n_last:]

    # The place is in the address: a reload shows the same frames.
    shown = _tile_ids(page)
    assert "after=" in page.url
    page.reload()
    expect(page.locator("#frame-total")).to_have_text(last)
    assert _tile_ids(page) == shown

    # A link past the end (the frames left the filter meanwhile) lands on the last frames, not on nothing.
    for past in (f"after={every['items'][-1]['video_id']}-999999", "offset=100000"):
        page.goto(demo_url + f"/frames?limit=3&{past}")
        expect(page.locator("#frame-total")).to_have_text(f"{total - 2}–{total} of {total}")
        assert _tile_ids(page) == ids[-3:]

    # The filter is kept in the address too, and comes back from it.
    state = Counter(f["state"] for f in every["items"]).most_common(1)[0][0]
    page.goto(demo_url + "/frames")
    page.select_option("#frame-filters select[name=state]", state)
    expect(page).to_have_url(re.compile(rf"/frames\?state={state}$"))
    chosen = _tile_ids(page)
    assert len(chosen) > 1 and set(page.locator("#frame-grid li").evaluate_all(
        "nodes => nodes.map(n => n.dataset.state)")) == {state}
    page.reload()
    expect(page.locator("#frame-filters select[name=state]")).to_have_value(state)
    assert _tile_ids(page) == chosen

    # A tile is a link to its frame; the keyboard reaches it too.
    page.locator("#frame-grid a").first.focus()
    page.keyboard.press("ArrowRight")
    expect(page.locator("#frame-grid a").nth(1)).to_be_focused()
    page.keyboard.press("Enter")
    page.wait_for_url(f"{demo_url}/annotate/{chosen[1]}")
    expect(page.locator("#frame-title")).to_contain_text(f"#{chosen[1]}")
    assert errors == []


def test_each_page_with_shortcuts_explains_them_under_question_mark(open_page, demo_url: str, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    page, errors = open_page("curator")
    help_dialog = page.locator("#keys-help")
    expected = {"/frames": ["next page", "open the frame"], "/jobs": ["next page (older jobs)"],
                "/": ["passed the VLM prefilter"], "/ingest": ["scene group", "upload and ingest the chosen files"],
                # Annotate's own table, every group of it, and its note
                "/annotate/1": ["Segment", "include a point (green)", "Right-click Alt+Click", "Touch up",
                                "Ctrl+Shift+Z Ctrl+Y", "View", "masks more / less opaque", "Frame",
                                "delete the frame (redundant or imperceptible)", "saved as a draft"],
                "/samples/1": ["accept the sample", "before ↔ after rectification", "back to the samples"],
                "/review": ["first / last frame of the page", "approve the frame", "reject: 1 blurry, 2 ",
                            "select the page", "Mouse: click focuses"],
                "/samples": ["first / last sample of the page", "accept the sample", "reject: 1 surface not flat",
                             "thumbnails: image + masks", "next / previous page"]}
    for path, rows in expected.items():
        page.goto(demo_url + path)
        page.locator("body").press("?")
        expect(help_dialog).to_be_visible()
        for row in rows:
            expect(help_dialog).to_contain_text(row)
        expect(help_dialog.locator("kbd", has_text="?")).to_have_count(1)
        page.screenshot(path=str(tmp_path / f"help-{path.strip('/').replace('/', '-')}.png"))
        page.keyboard.press("?")
        expect(help_dialog).to_be_hidden()
        page.click("[data-help]")  # the button opens it too
        expect(help_dialog).to_be_visible()
        page.keyboard.press("Escape")
        expect(help_dialog).to_be_hidden()

    # While the help is open, the page's own keys rest: no accept from behind the dialog.
    page.goto(demo_url + "/samples/1")
    state = page.locator("#sample-state").inner_text()
    page.locator("body").press("?")
    page.keyboard.press("a")
    page.keyboard.press("Escape")
    expect(page.locator("#sample-state")).to_have_text(state)
    assert page.locator("#sample-status").inner_text() == ""
    # nor on a grid, whose keys are its own; closing the help gives the keyboard back to the grid
    page.goto(demo_url + "/samples?state=all")
    first = page.locator("#samples-grid .tile").first
    expect(first).to_be_focused()
    state = first.get_attribute("data-state")
    page.keyboard.press("?")
    expect(help_dialog).to_be_visible()
    page.keyboard.press("a")
    page.keyboard.press("Escape")
    expect(help_dialog).to_be_hidden()
    expect(first).to_be_focused()
    expect(first).to_have_attribute("data-state", state)
    # Ctrl+digit in the reason picker is the browser's (switch tabs), not a reason
    page.keyboard.press("r")
    picker = page.locator("#reason-picker")
    expect(picker).to_be_visible()
    page.keyboard.press("Control+1")
    expect(picker).to_be_visible()
    page.keyboard.press("Escape")
    expect(picker).to_be_hidden()
    expect(first).to_have_attribute("data-state", state)
    assert page.locator("#samples-status").inner_text() == ""
    assert errors == []


def test_pager_takes_the_address_with_care(open_page, demo_url: str) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    page, errors = open_page("curator")
    total = json.loads(page.evaluate("u => fetch(u).then(r => r.text())", "/api/v1/frames?limit=1"))["total"]
    assert 2 < total < 60
    # ?limit= is a whole number of items in 1..500, the API's largest page; anything else is the page's own
    for asked, shown, kept in (("2.5", 2, "limit=2"), ("100000", total, "limit=500"), ("-4", 1, "limit=1"),
                               ("lots", total, "/frames")):
        page.goto(demo_url + f"/frames?limit={asked}")
        expect(page.locator("#frame-total")).to_have_text(f"1–{shown} of {total}")
        expect(page).to_have_url(re.compile(re.escape(kept) + "$"))
        expect(page.locator("#frame-status")).to_have_text("")

    # a link's video that is gone: the filter shows, and ✕ leads back to every frame
    page.goto(demo_url + "/frames?video_id=999999")
    chip = page.locator("#video-filter")
    expect(chip).to_contain_text("video #999999 (not found)")
    expect(page.locator("#frame-grid .empty")).to_be_visible()
    chip.locator("button").click()
    expect(chip).to_have_count(0)
    expect(page).to_have_url(demo_url + "/frames")
    expect(page.locator("#frame-total")).to_have_text(f"1–{total} of {total}")

    # Jobs has no total, so past its end (no job is older than #1) the first page, whose place is
    # known: its range and buttons agree
    jobs = json.loads(page.evaluate("u => fetch(u).then(r => r.text())", "/api/v1/jobs?limit=500"))["items"]
    assert len(jobs) > 2
    page.goto(demo_url + "/jobs?limit=2&offset=40&after=1")
    expect(page.locator("#jobs-range")).to_have_text("1–2")
    expect(page.locator("#prev-page")).to_be_disabled()
    expect(page.locator("#next-page")).to_be_enabled()
    expect(page).to_have_url(demo_url + "/jobs?limit=2")
    assert [int(i) for i in page.locator("#jobs tbody tr").evaluate_all("rows => rows.map(r => r.dataset.jobId)")] \
        == [j["id"] for j in jobs[:2]]
    assert errors == []


def test_a_refused_retry_stays_said_while_the_jobs_refresh(open_page, demo_url: str) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    page, errors = open_page("curator")
    listed = re.compile(r"/api/v1/jobs\?")

    def newest_failed(route) -> None:  # type: ignore[no-untyped-def]
        # The newest job shown as failed, so that it offers Retry; the server still knows it succeeded.
        response = route.fetch()
        body = response.json()
        body["items"][0]["state"] = "failed"
        route.fulfill(response=response, json=body)

    page.route(listed, newest_failed)
    page.goto(demo_url + "/jobs")
    row = page.locator("#jobs tbody tr").first
    job_id = row.get_attribute("data-job-id")
    row.get_by_role("button", name="Retry").click()
    status = page.locator("#jobs-status")
    said = re.compile(rf"^Job #{job_id} was not retried: job {job_id} is \w+; only failed or interrupted jobs can be")
    expect(status).to_have_text(said)
    for _ in range(2):  # the table refreshes every 2 s; the answer stays
        with page.expect_response(listed):
            pass
    expect(status).to_have_text(said)
    assert errors == []


def test_labels_agree_and_counts_read_as_words(open_page, demo_url: str) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    page, errors = open_page("curator")
    sample = json.loads(page.evaluate("u => fetch(u).then(r => r.text())", "/api/v1/samples/1"))
    place = _place(sample, sample["frame_id"])
    page.goto(demo_url + "/samples/1")
    head = page.locator(".sample-head p.muted")
    expect(head).to_contain_text(place)
    assert "index" not in head.inner_text()
    inliers = page.locator(".qa-pairs tbody td:nth-child(6)")
    assert inliers.count() and all(re.fullmatch(r"\d+\.\d %|–", t) for t in inliers.all_inner_texts())
    # pairs counted from 1, as the Annotate page counts planes, whatever the stored ids (the demo's start at 0)
    expect(page.locator(".qa-pairs tbody td:first-child")).to_have_text(
        [str(n) for n in range(1, len(sample["qa"]["pairs"]) + 1)])

    # the same frame named alike on the Samples tiles (inliers as a share, like the sample page) and on Annotate
    page.goto(demo_url + "/samples?state=all")
    tile = page.locator(f"#samples-grid .tile[data-id='{sample['id']}']")
    expect(tile.locator(".meta")).to_contain_text(place)
    expect(tile.locator(".metrics div", has=page.locator("dt", has_text="inliers")).locator("dd")).to_have_text(
        re.compile(r"^(\d+\.\d %|–)$"))
    page.goto(demo_url + f"/annotate/{sample['frame_id']}")
    expect(page.locator("#frame-info")).to_contain_text(place)

    # and on Review: its tiles and its large view
    frame = json.loads(page.evaluate("u => fetch(u).then(r => r.text())", "/api/v1/review/frames?state=all&limit=1"))
    frame = frame["items"][0]
    page.goto(demo_url + "/review?state=all")
    tile = page.locator("#review-grid .tile").first
    expect(tile.locator(".meta")).to_contain_text(_place(frame))
    expect(tile).to_have_attribute("aria-label", re.compile("^" + re.escape(_place(frame))))
    page.keyboard.press("Enter")
    expect(page.locator("#viewer-info p.muted").first).to_have_text(f"{_place(frame)} · {frame['width']}×{frame['height']}")
    page.keyboard.press("Escape")

    page.goto(demo_url + "/jobs")
    page.wait_for_selector("#jobs tbody tr[data-state=succeeded]")
    made = page.locator("#jobs tbody tr", has=page.locator("td:nth-child(2)", has_text="ingest")).last.locator(".made a")
    expect(made.first).to_have_text(sample["video"])
    assert not re.search(r"\b1 (frames|samples|jobs|near-duplicates|embeddings)\b", page.locator("main").inner_text())
    assert errors == []


def test_an_ended_session_says_so_once_and_leads_back_to_the_same_place(open_page, demo_url: str, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    page, errors = open_page("curator")
    page.goto(demo_url + "/frames?state=prefiltered")
    expect(page.locator("#frame-grid li[data-frame-id]").first).to_be_visible()
    jobs = page.context.new_page()
    jobs.goto(demo_url + "/jobs")
    sample = page.context.new_page()
    sample.goto(demo_url + "/samples/1")

    # Logged out in another tab: the server-side session is gone for every tab of this browser.
    other = page.context.new_page()
    other.goto(demo_url + "/")
    other.click("button.link")
    other.wait_for_url(demo_url + "/login")
    other.close()

    banner = page.locator("#session-ended")
    page.select_option("#frame-filters select[name=state]", "generated")
    expect(banner).to_have_text("Your session ended — log in again.")
    expect(banner).to_have_attribute("role", "status")
    expect(page.locator(".topbar .who")).to_have_text("signed out")  # no name of a session that is gone
    expect(page.locator("#frame-status")).to_have_text("")  # no second, technical message
    page.select_option("#frame-filters select[name=state]", "prefiltered")
    expect(page.locator(".session-ended")).to_have_count(1)
    assert "Bearer" not in page.locator("body").inner_text()
    page.screenshot(path=str(tmp_path / "session-ended-frames.png"))

    expect(jobs.locator("#session-ended")).to_be_visible(timeout=10_000)  # the live table's next refresh
    sample.click("#accept")
    expect(sample.locator("#session-ended")).to_be_visible()
    expect(sample.locator("#sample-status")).to_have_text("")
    sample.screenshot(path=str(tmp_path / "session-ended-sample.png"))

    link = banner.get_by_role("link", name="log in again")
    href = link.get_attribute("href")
    assert href == "/login?" + urllib.parse.urlencode({"next": "/frames?state=prefiltered"})
    link.click()
    page.wait_for_url(re.compile(r"/login\?next="))
    page.fill("input[name=name]", "curator")
    page.fill("input[name=password]", "curator-demo")
    page.click("button[type=submit]")
    page.wait_for_url(demo_url + "/frames?state=prefiltered")
    expect(page.locator("#frame-filters select[name=state]")).to_have_value("prefiltered")
    expect(page.locator("#session-ended")).to_have_count(0)
    assert errors == []
