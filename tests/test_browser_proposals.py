"""The machine's proposals on the Annotate page in a real browser: the demo's approved frames come with
plane-break's proposals, dashed on the frame with their source and score. The annotator accepts one as
it is and submits, rejects one on the next frame (Tab walks them), and on a third, whose proposals come
while the page looks, accepts one and corrects it with a click before submitting; the dashboard's
Proposers table counts each fate."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from tests.browser import ROOT, login, page_with_errors, running_demo
from tests.test_browser_annotate import click_image, decode, shown_frame
from tests.waiting import until

pytestmark = pytest.mark.browser

# The README's picture of the page: a tracked file, rewritten only when ILLUSION_SCREENSHOTS=1.
SCREENSHOT = ROOT / "docs" / "img" / "annotate-proposals.png"


def proposals_shown(page) -> list[dict]:  # type: ignore[no-untyped-def]
    """The proposals the page shows for its frame once they have come, the highlighted one first."""
    page.wait_for_function("() => window.annotator?.frame && window.annotator.proposals.length > 0", timeout=60_000)
    return sorted(page.evaluate("window.annotator.proposals"), key=lambda p: not p["highlighted"])


def shown_ids(page) -> list[int]:  # type: ignore[no-untyped-def]
    return [p["id"] for p in page.evaluate("window.annotator.proposals")]


def highlighted_id(page) -> int:  # type: ignore[no-untyped-def]
    return page.evaluate("window.annotator.proposals.find((p) => p.highlighted).id")


def detail(page, url: str, frame_id: int) -> dict:  # type: ignore[no-untyped-def]
    return page.request.get(f"{url}/api/v1/frames/{frame_id}").json()


def proposal(page, url: str, frame_id: int, proposal_id: int) -> dict:  # type: ignore[no-untyped-def]
    """The server's view of one proposal of a frame: its masks, fate and IoU."""
    return next(p for p in detail(page, url, frame_id)["proposals"] if p["id"] == proposal_id)


def still_computing(page, frame_id: int) -> Callable[[], None]:  # type: ignore[no-untyped-def]
    """Until the function returned is called, the page gets ``frame_id``'s detail as the server answers
    while the proposers have not looked at the frame yet."""
    pattern = f"**/api/v1/frames/{frame_id}"

    def answer(route) -> None:  # type: ignore[no-untyped-def]
        response = route.fetch()
        route.fulfill(response=response, json={**response.json(), "proposals": [], "proposals_ready": False,
                                                "proposals_note": "proposals are being computed (plane-break)"})

    page.route(pattern, answer)
    return lambda: page.unroute(pattern, answer)


def left_frame(page, frame_id: int) -> None:  # type: ignore[no-untyped-def]
    """Wait until a submit has taken the page off ``frame_id`` (to the next frame, or to none left)."""
    page.wait_for_function("(id) => window.annotator.frame?.id !== id", arg=frame_id, timeout=20_000)


def test_annotator_accepts_rejects_and_corrects_proposals(browser, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    with running_demo(tmp_path / "ws", videos=1) as url:
        page, errors = page_with_errors(browser)
        login(page, url, "annotator", "annotator-demo")
        page.goto(url + "/annotate")
        first = shown_frame(page)
        assert first["state"] == "approved" and not first["regions"]
        best = proposals_shown(page)[0]
        assert best["source"] == "plane-break" and best["type"] in ("picture", "mirror"), best
        row = page.locator("#proposals .proposal[aria-current=true]")
        expect(row.locator(".source")).to_have_text("plane-break")
        expect(row.locator("kbd")).to_have_text(["A", "R"])
        expect(page.locator("#message")).to_contain_text("A accepts the highlighted one")

        # A fills the empty plane with the proposal's masks and type, and its outline goes; an undo
        # brings the proposal back, a redo takes it again
        page.keyboard.press("a")
        page.wait_for_function("() => window.annotator.pairs[0].illusion > 0")
        [pair] = page.evaluate("window.annotator.pairs")
        assert pair["support"] > 0 and pair["type"] == best["type"], pair
        assert best["id"] not in shown_ids(page)
        expect(page.locator("#message")).to_contain_text("click to correct it")
        page.keyboard.press("Control+z")
        page.wait_for_function("(id) => window.annotator.proposals.some((p) => p.id === id)", arg=best["id"])
        assert page.evaluate("window.annotator.pairs[0].illusion") == 0
        page.keyboard.press("Control+Shift+z")
        page.wait_for_function("() => window.annotator.pairs[0].illusion > 0")

        # submitted as it was: the regions name the proposal, which the server counts as accepted
        page.keyboard.press("Enter")
        second = shown_frame(page, other_than=first["id"])
        saved = detail(page, url, first["id"])
        assert saved["submitted"] and all({"proposal_id": best["id"]} in r["clicks"] for r in saved["regions"])
        assert proposal(page, url, first["id"], best["id"])["fate"] == "accepted"

        # the next frame: Tab and Shift+Tab walk its proposals; R rejects the highlighted one at once
        shown = proposals_shown(page)
        assert len(shown) >= 2, shown
        focused = "document.activeElement.id || document.activeElement.tagName"
        before = page.evaluate(focused)
        page.keyboard.press("Tab")
        assert highlighted_id(page) == shown[1]["id"] and page.evaluate(focused) == before  # the focus stays
        page.keyboard.press("Shift+Tab")
        assert highlighted_id(page) == shown[0]["id"]
        page.keyboard.press("r")
        expect(page.locator("#message")).to_contain_text("Rejected plane-break")
        assert shown[0]["id"] not in shown_ids(page) and highlighted_id(page) == shown[1]["id"]
        until(lambda: proposal(page, url, second["id"], shown[0]["id"])["fate"] == "rejected",
              what="the rejection to reach the server")

        # a third frame, opened by its link while its proposals are still being computed: the panel says
        # so, and they come with one of the page's next looks
        approved = page.request.get(url + "/api/v1/frames?state=approved&limit=100").json()["items"]
        third = next(f["id"] for f in approved if f["id"] != second["id"])
        computed = still_computing(page, third)
        page.goto(f"{url}/annotate/{third}")
        assert shown_frame(page)["id"] == third
        expect(page.locator("#proposals-note")).to_have_text("Proposals are being computed (plane-break)")
        assert page.evaluate("window.annotator.proposals") == []
        computed()
        taken = proposals_shown(page)[0]
        expect(page.locator("#proposals-note")).to_have_text("Dashed on the frame; Tab highlights the next one.")

        # accept the best one, correct it with a click, submit
        expect(page.locator("#preparing")).to_be_hidden(timeout=60_000)  # its embedding is there: clicks are quick
        page.evaluate("() => new Promise(requestAnimationFrame)")  # the outlines drawn
        page.screenshot(path=str(SCREENSHOT if os.environ.get("ILLUSION_SCREENSHOTS") == "1"
                                 else tmp_path / "annotate-proposals.png"))
        page.keyboard.press("a")
        page.wait_for_function("() => window.annotator.pairs[0].illusion > 0")
        before = page.evaluate("window.annotator.pairs[0].illusion")
        proposed = decode(proposal(page, url, third, taken["id"])["illusion"])
        ys, _ = np.nonzero(proposed)
        y = int(np.median(ys))
        x = int(np.flatnonzero(proposed[y])[3])  # just inside its left edge: "not this" takes a piece off
        click_image(page, x, y, button="right")
        page.wait_for_function("(b) => window.annotator.pairs[0].illusion !== b"
                               " || document.getElementById('status').dataset.kind === 'error'", arg=before)
        expect(page.locator("#message")).not_to_contain_text("failed")
        assert 0 < page.evaluate("window.annotator.pairs[0].illusion") != before
        page.keyboard.press("Enter")
        left_frame(page, third)
        edited = until(lambda: (p := proposal(page, url, third, taken["id"]))["fate"] == "edited" and p,
                       what="the submit to record the corrected proposal")
        assert 0 < edited["iou"] < 1, edited

        # the dashboard counts each fate per proposer
        stats = page.request.get(url + "/api/v1/stats/proposers").json()["proposers"]["plane-break"]
        assert (stats["accepted"], stats["edited"]) == (1, 1) and stats["rejected"] >= 1, stats
        assert 0 < stats["median_iou"] < 1, stats
        page.goto(url + "/")
        row = page.locator("#proposers tr[data-proposer=plane-break]")
        for column, value in (("accepted", "1"), ("edited", "1"), ("rejected", str(stats["rejected"])),
                              ("median_iou", f"{stats['median_iou']:.2f}")):
            expect(row.locator(f"[data-column={column}]")).to_have_text(value)
        page.screenshot(path=str(tmp_path / "dashboard-proposers.png"))
        page.keyboard.press("?")
        expect(page.locator("#keys-help tr", has_text="Median IoU")).to_contain_text("over accepted (1.0) and edited")
        assert errors == []
        page.close()
