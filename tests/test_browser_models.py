"""The Models page in a real browser: an admin launches a short run and watches its chart grow;
an annotator cannot launch."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from dataset.db import migrate, transaction
from dataset.services import users as user_service
from dataset.tables import Role
from tests.browser import login, serving
from tests.conftest import PASSWORD, make_settings
from tests.runs_data import add_accepted_samples
from webapp.runtime import Runtime

pytestmark = [pytest.mark.browser, pytest.mark.slow]


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """A workspace with one user per role and accepted samples of three videos; its server and a train worker."""
    settings = make_settings(tmp_path_factory.mktemp("models") / "ws")
    migrate(settings.database_url)
    rt = Runtime(settings)
    with transaction(rt.sessions) as s:
        for role in Role:
            user_service.create_user(s, role.value, role, PASSWORD)
        add_accepted_samples(s, rt.media, videos=3)
    rt.close()
    with serving(settings.home, train_worker=True) as url:
        yield url


def test_a_crop_too_large_for_the_data_is_refused_under_the_crop_field(browser, server: str) -> None:  # type: ignore[no-untyped-def]
    page = browser.new_page()
    login(page, server, "admin", PASSWORD)
    page.goto(f"{server}/models")
    form = page.locator("#launch")
    assert "64x96 fits the accepted samples" in form.locator("[name=crop]").get_attribute("placeholder")
    form.locator("[name=crop]").fill("4000x8000")
    form.locator("[name=steps]").fill("1e12")
    form.locator("button[type=submit]").click()
    steps = form.locator("[data-error-for=steps]")
    steps.wait_for(state="visible")
    assert "at most 1000000" in steps.inner_text()
    form.locator("[name=steps]").fill("4")
    form.locator("button[type=submit]").click()
    crop = form.locator("[data-error-for=crop]")
    page.wait_for_function("() => document.querySelector('[data-error-for=crop]').textContent.includes('smallest')")
    assert crop.is_visible() and "try 64x96" in crop.inner_text()
    assert steps.is_hidden() and form.locator("[name=crop]").get_attribute("aria-invalid") == "true"
    assert page.url == f"{server}/models"  # refused: no run, the browser stays on the form
    page.keyboard.press("?")
    assert page.locator("#keys-help").is_visible()
    page.context.close()


def test_a_crop_the_estimate_cannot_read_is_marked_under_the_crop_field(browser, server: str) -> None:  # type: ignore[no-untyped-def]
    page = browser.new_page()
    login(page, server, "admin", PASSWORD)
    page.goto(f"{server}/models")
    form = page.locator("#launch")
    estimate = page.locator("#launch-estimate")
    form.locator("[name=crop]").fill("abc")
    crop = form.locator("[data-error-for=crop]")
    crop.wait_for(state="visible")
    assert "expected HxW in pixels" in crop.inner_text()
    assert estimate.inner_text() == "Estimated length: unknown until crop is corrected."
    form.locator("[name=crop]").fill("64x96")
    crop.wait_for(state="hidden")
    page.wait_for_function("() => document.querySelector('#launch-estimate').textContent.includes('finished lite run')")
    assert page.url == f"{server}/models"
    page.context.close()


@pytest.mark.timeout(900)  # the run's own waits allow 10 minutes on a loaded machine
def test_admin_launches_a_run_and_sees_its_chart_grow(browser, server: str, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    page = browser.new_page()
    login(page, server, "admin", PASSWORD)
    page.click("[data-nav=models]")
    page.wait_for_selector("#runs tbody td:has-text('No runs yet.')")
    form = page.locator("#launch")
    # Long enough for several step events (the engine writes one every 2 s, and the first and last):
    # a run that ends before the page's first poll would show its whole curve at once.
    form.locator("[name=steps]").fill("150")
    form.locator("[name=batch]").fill("2")
    form.locator("[name=crop]").fill("32x64")
    form.locator("[name=iters]").fill("2")
    form.locator("[name=devices]").select_option("cpu")
    form.locator("button[type=submit]").click()
    page.wait_for_url(f"{server}/models/runs/*")
    points = "Number(document.querySelector('#charts svg[aria-label=\"training loss\"]').dataset.points || 0)"
    page.wait_for_function(f"() => {points} > 0", timeout=180_000)
    first = page.evaluate(points)
    page.wait_for_function(f"() => {points} > {first} || document.getElementById('run').dataset.state === 'succeeded'",
                           timeout=180_000)
    # The rest of the run: minutes where other work loads the machine.
    page.wait_for_function("() => document.getElementById('run').dataset.state === 'succeeded'", timeout=600_000)
    assert page.evaluate(points) > first, "the chart never grew while the run went"
    assert page.locator("#fig-step").inner_text() == "150/150"
    assert page.locator("#checkpoints tbody a").count() >= 1
    page.screenshot(path=str(tmp_path / "run.png"), full_page=True)
    page.click("#run-promote")
    page.wait_for_selector("#run-current:not([hidden])")
    page.close()


def test_an_annotator_cannot_launch(browser, server: str) -> None:  # type: ignore[no-untyped-def]
    page = browser.new_page()
    login(page, server, "annotator", PASSWORD)
    assert page.locator("[data-nav=models]").count() == 0
    assert page.goto(f"{server}/models").status == 403
    status = page.evaluate("""async () => {
        const csrf = document.querySelector('meta[name="csrf-token"]').content;
        const r = await fetch('/api/v1/runs', {method: 'POST', headers: {'Content-Type': 'application/json',
                                                'X-CSRFToken': csrf}, body: JSON.stringify({steps: 2})});
        return r.status; }""")
    assert status == 403
    page.close()
