"""The curators' review page in a real browser: a page of frames reviewed with the keyboard alone."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.browser import login, running_demo

pytestmark = pytest.mark.browser


def test_curator_reviews_frames_with_the_keyboard_and_the_funnel_follows(browser, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    with running_demo(tmp_path / "ws", videos=1) as url:
        page = browser.new_page(viewport={"width": 1400, "height": 900})
        errors: list[str] = []
        page.on("pageerror", lambda error: errors.append(str(error)))
        login(page, url, "curator", "curator-demo")
        approved_before = int(page.locator("[data-stage=approved] .count").inner_text())

        page.click("[data-nav=review]")
        # the demo's worker ingests and prefilters its video meanwhile; the empty grid keeps looking
        page.wait_for_function("() => document.querySelectorAll('#review-grid .tile').length >= 6", timeout=120_000)
        tiles = page.locator("#review-grid .tile")
        ids = [int(i) for i in tiles.evaluate_all("nodes => nodes.map(n => n.dataset.id)")]
        tile = [tiles.nth(i) for i in range(6)]
        expect(tile[0]).to_be_focused()
        expect(tile[0]).to_have_class(re.compile(r"\bfocused\b"))
        assert tile[0].locator(".answers li").count() == 12
        assert tile[0].locator(".metrics dt").count() > 0
        assert page.locator("#review-range").inner_text().startswith("1–")
        expect(page.locator(".pager #prev-page")).to_be_disabled()  # the first page: the pager macro's buttons

        keys = page.keyboard
        keys.press("p")
        expect(page.locator("#review-status")).to_have_text("This is the first page.")
        expect(tile[0]).to_be_focused()
        keys.press("a")
        keys.press("a")
        expect(tile[0]).to_have_attribute("data-state", "approved")
        expect(tile[1]).to_have_attribute("data-state", "approved")
        expect(tile[2]).to_be_focused()  # each decision moves on to the next frame

        keys.press("r")
        expect(page.locator("#reason-picker")).to_be_visible()
        keys.press("1")  # blurry
        expect(page.locator("#reason-picker")).to_be_hidden()
        expect(tile[2]).to_have_attribute("data-state", "rejected")
        expect(page.locator("#review-status")).to_have_text(f"Rejected #{ids[2]}: blurry.")
        expect(tile[2]).to_have_class(re.compile(r"\bsettled\b"))  # dimmed, but kept in place under the curator's hands

        keys.press("Shift+ArrowRight")
        expect(page.locator("#review-grid .tile[aria-selected=true]")).to_have_count(2)
        keys.press("a")  # applies to the selection, through the bulk endpoint
        expect(tile[3]).to_have_attribute("data-state", "approved")
        expect(tile[4]).to_have_attribute("data-state", "approved")
        expect(page.locator("#count-approved")).to_have_text("4")
        expect(page.locator("#count-rejected")).to_have_text("1")

        keys.press("u")  # undoes the whole bulk decision
        expect(tile[3]).to_have_attribute("data-state", "prefiltered")
        expect(tile[4]).to_have_attribute("data-state", "prefiltered")
        expect(tile[3]).to_be_focused()
        keys.press("a")
        expect(tile[3]).to_have_attribute("data-state", "approved")
        keys.press("Control+z")  # and a single one
        expect(tile[3]).to_have_attribute("data-state", "prefiltered")
        expect(page.locator("#count-approved")).to_have_text("2")

        keys.press("Enter")  # the large view of the focused frame
        viewer = page.locator("#viewer")
        expect(viewer).to_be_visible()
        expect(viewer.locator("h2")).to_contain_text(f"Frame #{ids[3]}")
        expect(viewer.locator(".questions tr")).to_have_count(12)
        page.wait_for_function("() => document.getElementById('viewer-image').naturalWidth > 0")
        keys.press("Escape")
        expect(viewer).to_be_hidden()
        expect(tile[3]).to_be_focused()

        keys.press("?")
        expect(page.locator("#keys-help")).to_be_visible()
        keys.press("Escape")
        expect(page.locator("#keys-help")).to_be_hidden()
        expect(tile[3]).to_be_focused()

        expect(page.locator("#count-funnel")).to_have_text(str(approved_before + 2))
        page.screenshot(path=str(tmp_path / "review.png"))

        items = page.request.get(url + "/api/v1/review/frames?state=all&limit=500").json()["items"]
        by_id = {item["id"]: item for item in items}
        assert [by_id[i]["state"] for i in ids[:5]] == ["approved", "approved", "rejected", "prefiltered", "prefiltered"]
        assert by_id[ids[2]]["last_review"]["reason"] == "blurry"
        assert by_id[ids[2]]["last_review"]["user"] == "curator"

        # the default prefilter visibly decides: it says what it does not answer, and drops the demo's
        # captioned and blurred frames
        note = page.locator("#backend-note")
        expect(note).to_contain_text("answers only Q7 (excessive watermark/caption), Q8 (corner watermark/caption), "
                                     "Q9 (too blurry)")
        expect(note).to_contain_text("the other 9 questions to you")
        page.select_option("#review-filters select[name=state]", "rejected")
        page.select_option("#review-filters select[name=keep]", "false")
        expect(page.locator("#review-range")).to_have_text("1–2 of 2")
        reasons = page.locator("#review-grid .tile .verdict").evaluate_all("nodes => nodes.map(n => n.title)")
        assert sorted(r.split(" (")[0] for r in reasons) == ["rejected: Q7", "rejected: Q9"], reasons
        page.screenshot(path=str(tmp_path / "review-dropped.png"))

        page.click("[data-nav=dashboard]")
        expect(page.locator("[data-stage=approved] .count")).to_have_text(str(approved_before + 2))
        assert errors == []
        page.close()
