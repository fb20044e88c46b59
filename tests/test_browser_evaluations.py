"""The Evaluation page in a real browser: a curator opens a report, sorts its samples, and sorts the
Samples page by the evaluation's error; an annotator gets 403."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from dataset.db import migrate, transaction
from dataset.services import users as user_service
from dataset.tables import Role
from tests.browser import login, serving
from tests.conftest import PASSWORD, make_settings
from tests.evaluations_data import evaluated_database
from webapp.runtime import Runtime

pytestmark = [pytest.mark.browser, pytest.mark.slow]
PICTURES_LOADED = "() => [...document.querySelectorAll('.evaluation-pictures img')].every(i => i.complete && i.naturalWidth > 0)"


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, list[int]]]:
    """A workspace with one user per role and a finished database evaluation; its server."""
    tmp = tmp_path_factory.mktemp("evaluations")
    settings = make_settings(tmp / "ws")
    migrate(settings.database_url)
    rt = Runtime(settings)
    with transaction(rt.sessions) as s:
        for role in Role:
            user_service.create_user(s, role.value, role, PASSWORD)
    _, ids = evaluated_database(rt, tmp)
    rt.close()
    with serving(settings.home) as url:
        yield url, ids


def test_curator_opens_a_report_and_sorts_samples_by_error(browser, server, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    url, ids = server
    page = browser.new_page(viewport={"width": 1400, "height": 900})
    errors: list[str] = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    login(page, url, "curator", PASSWORD)
    page.click("[data-nav=evaluation]")
    row = page.locator("#evaluation-list tbody tr[data-evaluation-id='1']")
    expect(row).to_have_attribute("data-state", "succeeded")
    row.locator("a", has_text="#1").click()
    page.wait_for_url(f"{url}/evaluations/1")
    expect(page.locator("#paper-table tbody[data-region=all] th[scope=row]")).to_have_text(["predictions", "sgbm"])
    page.wait_for_function(PICTURES_LOADED)

    table = page.locator("#per-sample")
    all_column = table.locator("thead th", has_text="all").first
    all_column.click()  # report.js: the worst first (descending EPE on all), again for the best
    expect(all_column).to_have_attribute("data-order", "desc")
    first = table.locator("tbody tr").first.locator("td")
    expect(first.nth(0)).to_have_text("predictions")  # the worst: 2.5 px off everywhere
    page.screenshot(path=str(tmp_path / "report.png"), full_page=True)

    page.click("#samples-by-error")
    page.wait_for_url(f"{url}/samples?evaluation=1&sort=error")
    tiles = page.locator("#samples-grid .tile")
    expect(tiles).to_have_count(len(ids))
    assert [int(i) for i in tiles.evaluate_all("nodes => nodes.map(n => n.dataset.id)")] == ids[::-1]
    expect(tiles.nth(0).locator(".evaluation-error")).to_contain_text("predictions epe on all: 2.50 px")
    tiles.nth(0).locator(".evaluation-error a").click()
    page.wait_for_url(f"{url}/evaluations/1/samples/{ids[-1]}?method=predictions")
    page.wait_for_function(PICTURES_LOADED)
    assert page.locator(".evaluation-pictures img").evaluate_all("n => n.map(i => i.dataset.image)") == \
        ["gt", "prediction", "error"]
    page.screenshot(path=str(tmp_path / "evaluated-sample.png"), full_page=True)
    assert not errors, errors
    page.close()


def test_the_form_refuses_without_a_method_then_launches_on_a_runs_test_split(browser, server) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    url, _ = server
    page = browser.new_page(viewport={"width": 1366, "height": 768})
    login(page, url, "curator", PASSWORD)
    page.goto(f"{url}/evaluations")
    form = page.locator("#launch-evaluation")
    for box in form.locator("input[name=methods]").all():
        box.uncheck()
    form.locator("button[type=submit]").click()
    expect(form.locator("[data-error-for=methods]")).to_have_text("tick at least one method to score")
    assert page.url == f"{url}/evaluations"
    form.locator("input[name=methods][value=sgbm]").check()
    form.locator("select[name=run]").select_option("1")
    form.locator("button[type=submit]").click()
    page.wait_for_url(f"{url}/evaluations/2")
    page.goto(f"{url}/evaluations")
    expect(page.locator("#evaluation-list tbody tr[data-evaluation-id='2']")).to_contain_text("test split of run 1")
    page.close()


def test_an_annotator_gets_403(browser, server) -> None:  # type: ignore[no-untyped-def]
    url, _ = server
    page = browser.new_page()
    login(page, url, "annotator", PASSWORD)
    assert page.locator("[data-nav=evaluation]").count() == 0
    assert page.goto(f"{url}/evaluations").status == 403
    assert page.goto(f"{url}/evaluations/1").status == 403
    page.close()
