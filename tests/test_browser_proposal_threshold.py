"""The proposal threshold on the Annotate page in a real browser: with the demo's threshold at its
highest, the proposals scoring under it are not shown until "Show all" is on (the `?` help lists its
key), and the page names the threshold; one is taken into the annotation, and on submit a hidden
proposal left untouched is `hidden`, not rejected, and the dashboard's Proposers table has a row for
the threshold."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from dataset.settings import SETTINGS_FILE
from tests.browser import login, page_with_errors, running_demo
from tests.test_browser_annotate import shown_frame
from tests.test_browser_proposals import detail, left_frame, shown_ids
from tests.waiting import until
from webapp.cli.demo import DEMO_MARKER

pytestmark = pytest.mark.browser

THRESHOLD = 1.0  # only what the proposer is certain of (score 1.0) is shown unasked


def test_hidden_proposals_wait_for_show_all_and_stay_hidden(browser, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    # A demo workspace whose settings file an admin has edited before the demo fills it.
    home = tmp_path / "ws"
    home.mkdir()
    (home / DEMO_MARKER).write_text("made for this test\n", encoding="utf-8")
    (home / SETTINGS_FILE).write_text(f"proposal_threshold = {THRESHOLD}\n", encoding="utf-8")
    with running_demo(home, videos=1) as url:
        page, errors = page_with_errors(browser)
        login(page, url, "annotator", "annotator-demo")
        page.goto(url + "/annotate")
        frame = shown_frame(page)
        offered = until(lambda: (d := detail(page, url, frame["id"]))["proposals_ready"] and d["proposals"],
                        what="the frame's proposals", timeout=60)
        hidden = [p["id"] for p in offered if p["hidden"]]
        assert hidden and all(p["hidden"] == (p["score"] < THRESHOLD) for p in offered), offered
        assert {p["threshold"] for p in offered} == {THRESHOLD}
        over = [p["id"] for p in offered if not p["hidden"]]
        page.wait_for_function("() => !document.getElementById('proposals-section').hidden")
        toggle = page.locator("#show-all-proposals")
        expect(toggle).not_to_be_checked()
        assert shown_ids(page) == over
        if not over:  # the threshold in force is named
            expect(page.locator("#proposals-note")).to_contain_text(f"under the threshold {THRESHOLD:.2f}")
        # the box sits on its label's line, not alone above it
        label, box = page.locator("label:has(#show-all-proposals)").bounding_box(), toggle.bounding_box()
        assert label["height"] < 2.2 * box["height"] and label["width"] > 3 * box["width"], (label, box)

        # "Show all" brings the hidden ones, marked as such; off again, they go
        toggle.click()
        expect(toggle).to_be_checked()
        assert shown_ids(page) == over + hidden
        expect(page.locator(f"#proposals [data-proposal='{hidden[0]}']")).to_have_attribute("data-hidden", "true")
        expect(page.locator(f"#proposals [data-proposal='{hidden[0]}'] .score")).to_have_attribute(
            "title", re.compile(f"under the threshold {THRESHOLD:.2f}"))
        expect(page.locator("#message")).to_contain_text(f"under the threshold {THRESHOLD:.2f} too")
        page.keyboard.press("?")
        expect(page.locator("#keys-help tr", has_text="show all proposals")).to_contain_text("V")
        page.keyboard.press("Escape")

        # the best one taken (a hidden one when none is over the threshold), the others left as they are
        page.keyboard.press("a")
        page.wait_for_function("() => window.annotator.pairs[0]?.illusion > 0")
        taken = (over or hidden)[0]
        page.keyboard.press("v")  # the key does what the box does
        expect(toggle).not_to_be_checked()
        assert shown_ids(page) == [i for i in over if i != taken]
        untouched = [i for i in hidden if i != taken]
        assert untouched, offered
        page.keyboard.press("Enter")
        left_frame(page, frame["id"])
        fates = until(lambda: (f := {p["id"]: p["fate"] for p in detail(page, url, frame["id"])["proposals"]})[taken]
                      == "accepted" and f, what="the submit to record the fates")
        assert {fates[i] for i in untouched} == {"hidden"}, fates
        assert {fates[i] for i in over if i != taken} <= {"rejected"}, fates

        page.goto(url + "/")
        row = page.locator(f"#proposers tr[data-proposer=plane-break][data-threshold='{THRESHOLD:g}']")
        expect(row.locator("[data-column=threshold]")).to_have_text(f"{THRESHOLD:.2f}")
        expect(row.locator("[data-column=hidden]")).to_have_text(str(len(untouched)))
        assert errors == []
        page.close()
