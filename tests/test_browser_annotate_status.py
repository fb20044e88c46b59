"""The Annotate page's status line and panel say what is true now: planes are numbered from 1 whatever
ids the server stored, a brush stroke after a failed click clears the failure and the old timing, and a
request refused because the session ended leaves the talking to the page-wide notice. The review tiles'
measurement labels are whole words with their meaning on hover."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.browser import login, running_demo
from tests.test_browser_annotate import click_image, interior, shown_frame, truth

pytestmark = pytest.mark.browser


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    home = tmp_path_factory.mktemp("demo") / "ws"
    with running_demo(home) as url:
        yield url, home


def test_planes_of_a_demo_annotation_are_numbered_from_1(browser, demo, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    url, _ = demo
    page = browser.new_page(viewport={"width": 1400, "height": 860})
    login(page, url, "annotator", "annotator-demo")
    frame_id = page.request.get(url + "/api/v1/samples?limit=1").json()["items"][0]["frame_id"]
    stored = sorted({r["pair"] for r in page.request.get(f"{url}/api/v1/frames/{frame_id}").json()["regions"]})
    assert stored[0] == 0 and len(stored) >= 2, stored  # the demo stores its planes from 0

    page.goto(f"{url}/annotate/{frame_id}")
    assert shown_frame(page)["id"] == frame_id
    rows = page.locator("#pairs .pair")
    expect(rows).to_have_count(len(stored))
    names = rows.locator(".name").evaluate_all("nodes => nodes.map(n => n.firstChild.textContent)")
    keys = rows.locator(".name kbd").all_inner_texts()
    labels = rows.locator(".remove").evaluate_all("nodes => nodes.map(n => n.ariaLabel)")
    numbers = [str(n) for n in range(1, len(stored) + 1)]
    assert names == [f"Plane {n}" for n in numbers] and keys == numbers, (names, keys)
    assert labels == [f"Remove plane {n}" for n in numbers]
    expect(rows.first.locator("[data-chip=illusion]")).to_have_attribute("title", re.compile(r"^Illusion of plane 1: "))
    page.locator(".panel").screenshot(path=str(tmp_path / "annotate-planes.png"))
    page.close()


def test_a_brush_stroke_clears_a_failed_click_and_a_session_end_says_nothing_of_its_own(browser, demo) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    url, home = demo
    page = browser.new_page(viewport={"width": 1400, "height": 860})
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    login(page, url, "annotator", "annotator-demo")
    page.goto(url + "/annotate")
    frame = shown_frame(page)
    picture = truth(home, frame["index"], "illusion_00")
    x, y = interior(picture)
    status, message, timing = page.locator("#status"), page.locator("#message"), page.locator("#timing")

    click_image(page, x, y)
    page.wait_for_function("() => window.annotator.pairs[0].illusion > 0")
    expect(timing).to_have_text(re.compile(r"^mask in "))

    # a click the server fails: said in red, and the timing of the click before goes
    page.route("**/segment", lambda route: route.fulfill(status=500, json={"error": "the model crashed"}))
    click_image(page, x + 2, y)
    expect(message).to_have_text("Segmentation failed: the model crashed")
    expect(status).to_have_attribute("data-kind", "error")
    expect(timing).to_have_text("")

    # a brush stroke that succeeds is the latest word: the failure goes
    page.unroute("**/segment")
    page.keyboard.press("b")
    cx, cy = page.evaluate("([x, y]) => window.annotator.imageToClient(x, y)", [x, y])
    page.mouse.move(cx, cy)
    page.mouse.down()
    page.mouse.move(cx + 15, cy, steps=4)
    page.mouse.up()
    expect(message).to_have_text("Illusion of plane 1: painted by hand.")
    expect(status).to_have_attribute("data-kind", "info")
    expect(timing).to_have_text("")

    # the session ends: the page-wide notice says so; no "Segmentation failed" beside it, and the
    # region does not wait for a mask forever
    page.keyboard.press("c")
    page.route("**/segment", lambda route: route.fulfill(status=401, json={"error": "authentication required"}))
    click_image(page, x - 2, y)
    expect(page.get_by_text("Your session ended")).to_be_visible()
    expect(page.locator("#pairs [data-pair] [data-chip=illusion] .mark").first).to_have_text("✓")
    expect(message).not_to_contain_text("failed")
    expect(status).not_to_have_attribute("data-kind", "error")
    assert errors == []
    page.close()


def test_review_tiles_show_whole_measurement_labels_with_their_meaning(browser, demo, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    url, _ = demo
    page = browser.new_page(viewport={"width": 1366, "height": 768})
    login(page, url, "curator", "curator-demo")
    page.goto(url + "/review?state=all")
    page.wait_for_function("() => document.querySelectorAll('#review-grid .tile .metrics dt').length > 0", timeout=120_000)
    entries = page.locator("#review-grid .tile").first.locator(".metrics > div")
    shown = entries.evaluate_all("""nodes => nodes.map(n => {
        const dt = n.querySelector('dt');
        return { label: dt.textContent, title: n.title, cut: dt.scrollWidth > dt.clientWidth };
    })""")
    page.screenshot(path=str(tmp_path / "review-tiles.png"))
    by_label = {entry["label"]: entry for entry in shown}
    assert "sharpness" in by_label and "laplacian" not in " ".join(by_label), shown
    assert by_label["sharpness"]["title"].endswith("(laplacian_var)"), shown
    assert not [entry for entry in shown if entry["cut"]], shown
    page.close()
