"""An evaluation's report and the Samples pages in a real browser at 1366×768: the metrics table fits,
samples are named as the app names them and linked, pictures are captioned, the first click on a
column puts the worst first, `?` helps; a sample offers only the decisions its state allows, the
session's count survives a reload, and Back from the 3D preview lands on the sample's page."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import pytest

from dataset.db import migrate, transaction
from dataset.services import users as user_service
from dataset.tables import Frame, FrameState, Role, Sample, SampleState
from tests.browser import login, page_with_errors, serving
from tests.conftest import PASSWORD, make_settings
from tests.evaluations_data import evaluated_database
from webapp.runtime import Runtime

pytestmark = [pytest.mark.browser, pytest.mark.slow]
PLACE = re.compile(r"^plane \d · frame #\d+ · \d+\.\d s$")  # labels.js framePlace


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, dict[str, int], list[int]]]:
    """A finished database evaluation of 6 samples (best first); then one sample back to generated
    and one rejected, the others accepted."""
    tmp = tmp_path_factory.mktemp("report")
    settings = make_settings(tmp / "ws")
    migrate(settings.database_url)
    rt = Runtime(settings)
    with transaction(rt.sessions) as s:
        for role in Role:
            user_service.create_user(s, role.value, role, PASSWORD)
    _, ids = evaluated_database(rt, tmp)
    states = {"generated": ids[0], "rejected": ids[1], "accepted": ids[2]}
    with transaction(rt.sessions) as s:
        for state, frame_state in (("generated", FrameState.generated), ("rejected", FrameState.approved)):
            sample = s.get(Sample, states[state])
            sample.state = SampleState(state)
            s.get(Frame, sample.frame_id).state = frame_state
    rt.close()
    with serving(settings.home) as url:
        yield url, states, ids


def test_the_report_fits_names_its_samples_and_sorts_worst_first(browser, server, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    url, _, ids = server
    page, errors = page_with_errors(browser)
    login(page, url, "curator", PASSWORD)
    page.goto(f"{url}/evaluations/1")
    paper = page.locator("#paper-table")
    expect(paper.locator("tbody[data-region=all] th[scope=row]")).to_have_text(["predictions", "sgbm"])
    regions = paper.locator("th[scope=rowgroup]").all_inner_texts()
    assert "picture" in regions, regions  # the per-type region, once cut off at the right
    box = paper.bounding_box()
    assert box["x"] + box["width"] <= 1366 and page.evaluate("document.documentElement.scrollWidth") <= 1366

    names = page.locator("#per-sample td.sample-name a")
    expect(names).to_have_count(2 * len(ids))
    assert all(PLACE.match(t) for t in names.all_inner_texts()), names.all_inner_texts()
    assert "video_" not in page.locator("#per-sample").inner_text()
    first = page.locator("#per-sample tbody tr[data-method=predictions] td.sample-name a").first
    href = first.get_attribute("href")
    assert re.fullmatch(r"/evaluations/1/samples/\d+\?method=predictions", href), href

    all_column = page.locator("#per-sample thead th", has_text="all").first
    all_column.click()
    expect(all_column).to_have_attribute("data-order", "desc")
    top = page.locator("#per-sample tbody tr").first
    expect(top.locator("td").first).to_have_text("predictions")  # the worst: 2.5 px off everywhere
    expect(top.locator("td.sample-name")).to_have_attribute("data-sample", str(ids[-1]))
    all_column.click()
    expect(all_column).to_have_attribute("data-order", "asc")

    worst = page.locator(".evaluation-pictures").first
    expect(worst.locator("h3")).to_have_text(re.compile(r"^worst: plane \d · frame #\d+ · \d+\.\d s$"))
    captions = worst.locator("figcaption").all_inner_texts()
    assert captions[:2] == ["left image", "ground truth"] and "predictions prediction" in captions \
        and "sgbm error (0–8 px)" in captions, captions
    page.wait_for_function("() => [...document.querySelectorAll('.evaluation-pictures img')]"
                           ".every(i => i.complete && i.naturalWidth > 0)")
    page.screenshot(path=str(tmp_path / "report.png"), full_page=True)

    page.keyboard.press("?")
    expect(page.locator("#keys-help")).to_be_visible()
    page.keyboard.press("Escape")
    page.keyboard.press("3")  # sorts by the 3rd column: all
    expect(all_column).to_have_attribute("data-order", "desc")
    first.click()
    page.wait_for_url(re.compile(rf"{url}/evaluations/1/samples/\d+\?method=predictions"))
    assert errors == []
    page.close()


def test_samples_offer_what_their_state_allows_and_count_across_reloads(browser, server, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    url, states, _ = server
    page, errors = page_with_errors(browser)
    login(page, url, "curator", PASSWORD)

    page.goto(f"{url}/samples?state=accepted")
    tile = page.locator(f"#samples-grid .tile[data-id='{states['accepted']}']")
    tile.click()
    expect(page.locator("#accept")).to_be_disabled()
    expect(page.locator("#reject")).to_be_enabled()
    page.keyboard.press("a")
    expect(page.locator("#samples-status")).to_have_text(re.compile(r"is already accepted"))
    expect(tile).to_have_attribute("data-state", "accepted")

    page.goto(f"{url}/samples")
    tile = page.locator(f"#samples-grid .tile[data-id='{states['generated']}']")
    expect(tile).to_be_focused()
    expect(page.locator("#accept")).to_be_enabled()
    page.keyboard.press("a")
    expect(tile).to_have_attribute("data-state", "accepted")
    expect(page.locator("#count-accepted")).to_have_text("1")
    page.reload()
    expect(page.locator("#count-accepted")).to_have_text("1")

    page.goto(f"{url}/samples/{states['accepted']}")
    expect(page.locator("#accept")).to_be_hidden()
    expect(page.locator("#reject")).to_be_visible()
    expect(page.locator("#decision-note")).to_have_text(re.compile(r"^In the dataset"))
    # The state is said once, by the badge: the note under the buttons says what it means.
    expect(page.locator(".sample-head")).to_have_text(re.compile(r"^(?![\s\S]*accepted[\s\S]*accepted)", re.I))
    page.goto(f"{url}/samples/{states['rejected']}")
    expect(page.locator("#accept")).to_be_hidden()
    expect(page.locator("#reject")).to_be_hidden()
    expect(page.locator("#decision-note")).to_have_text(re.compile(r"^Its frame went back"))
    expect(page.locator(".sample-head")).to_have_text(re.compile(r"^(?![\s\S]*rejected[\s\S]*rejected)", re.I))
    assert errors == []
    page.close()


def test_back_from_the_3d_preview_lands_on_the_sample_page(browser, server) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    url, states, _ = server
    page, _ = page_with_errors(browser)
    login(page, url, "curator", PASSWORD)
    page.goto(f"{url}/samples?state=all")
    page.locator(f"#samples-grid .tile[data-id='{states['accepted']}']").click()
    page.keyboard.press("Enter")
    page.wait_for_url(f"{url}/samples/{states['accepted']}")
    page.keyboard.press("v")
    expect(page.locator("#viewer3d")).to_be_visible()
    page.wait_for_url(f"{url}/samples/{states['accepted']}/preview")
    page.go_back()
    page.wait_for_url(f"{url}/samples/{states['accepted']}")
    expect(page.locator("#viewer3d")).to_be_hidden()
    page.go_back()
    page.wait_for_url(re.compile(rf"{url}/samples\?"))

    # opened at …/preview (the annotation page's link): Back closes it to the sample's page
    page.goto(f"{url}/samples/{states['accepted']}/preview")
    expect(page.locator("#viewer3d")).to_be_visible()
    page.go_back()
    page.wait_for_url(f"{url}/samples/{states['accepted']}")
    expect(page.locator("#viewer3d")).to_be_hidden()
    # Esc closes it too, and takes its history entry along
    page.keyboard.press("v")
    page.wait_for_url(f"{url}/samples/{states['accepted']}/preview")
    page.keyboard.press("Escape")
    page.wait_for_url(f"{url}/samples/{states['accepted']}")
    page.close()
