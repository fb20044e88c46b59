"""What a newcomer tripped over, in a real browser at 1366×768: a malformed number in the launch form
(refused under its field, not launched with the preset's value), the run-length estimate, the runs
list's "current" badge, Annotate's `?` help opening at its title, one place for `?` on every page, the
charts' axes, and an open tab told why its session ended."""

from __future__ import annotations

import json
from collections.abc import Iterator
from datetime import timedelta
from pathlib import Path

import pytest

from dataset.db import migrate, transaction
from dataset.services import training
from dataset.services import users as user_service
from dataset.tables import Role, RunState, TrainingRun, utcnow
from model.presets import load_preset
from tests.browser import login, page_with_errors, serving
from tests.conftest import PASSWORD, make_settings
from webapp.runtime import Runtime

pytestmark = pytest.mark.browser

STEP_S = 0.5  # the run's steps: batch 2 at 4 samples/s
LOSSES = [0.101 + 0.0804 * i / 9 for i in range(10)]  # a range whose round ticks once fell to one


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, Path]]:
    """Users of every role; run 1 (lite, crop 64x96) finished with its step times, and the current model."""
    settings = make_settings(tmp_path_factory.mktemp("newcomer") / "ws")
    migrate(settings.database_url)
    rt = Runtime(settings)
    with transaction(rt.sessions) as s:
        for role in Role:
            user_service.create_user(s, role.value, role, PASSWORD)
        config = load_preset("lite", {"train.steps": 10, "train.batch_size": 2, "train.crop": (64, 96)}).to_dict()
        run = TrainingRun(preset="lite", config=config,
                          dataset_id="ab" * 32, dataset={"id": "ab" * 32, "items": []},
                          splits={"train": [1], "val": [2], "test": []}, launch={"data": {}}, state=RunState.succeeded,
                          started_at=utcnow() - timedelta(seconds=5), finished_at=utcnow())
        s.add(run)
        s.flush()
        training.apply_events(s, run, [{"event": "step", "step": i + 1, "steps": 10, "loss": loss, "lr": 2e-4,
                                        "samples_per_s": 2 / STEP_S} for i, loss in enumerate(LOSSES)])
    rt.close()
    (settings.models_dir).mkdir(parents=True, exist_ok=True)
    (settings.models_dir / "current.json").write_text(json.dumps({"run": 1, "checkpoint": "runs/1/checkpoints/best.pt",
                                                                  "file": "best.pt", "step": 10}))
    with serving(settings.home) as url:
        yield url, settings.home


def test_a_malformed_number_is_refused_under_its_field_and_the_estimate_uses_the_last_run(browser, server) -> None:  # type: ignore[no-untyped-def]
    url, _ = server
    page, errors = page_with_errors(browser)
    login(page, url, "admin", PASSWORD)
    page.goto(url + "/models")
    page.wait_for_function("() => document.querySelector('#runs tbody tr[data-run-id]')")
    number, badge = page.locator("#runs tbody td:nth-child(2) a"), page.locator("#runs tbody .badge.current")
    # "#1 current", the badge apart from the number (its pill once began at the number's last pixel)
    assert badge.inner_text() == "current"
    assert badge.bounding_box()["x"] - (number.bounding_box()["x"] + number.bounding_box()["width"]) >= 3
    form = page.locator("#launch")
    estimate = page.locator("#launch-estimate")
    page.wait_for_function("() => !document.getElementById('launch-estimate').textContent.includes('…')")
    # The form starts at run 1's batch, crop and iterations: its estimate goes by run 1 from the start.
    assert form.locator("[name=crop]").input_value() == "64x96"
    assert "measured on run 1 at batch 2, 64×96" in estimate.inner_text(), estimate.inner_text()
    # empty fields name what the launch will take: the preset's values
    assert form.locator("[name=steps]").get_attribute("placeholder") == "2000 (lite's)"
    assert form.locator("[name=batch]").get_attribute("placeholder") == "2 (lite's)"
    for field, typed in (("steps", "1e"), ("batch", "--2")):
        form.locator(f"[name={field}]").fill("")  # batch starts at run 1's
        form.locator(f"[name={field}]").press_sequentially(typed)
        form.locator(f"[name={field}]").press("Enter")
        note = form.locator(f"[data-error-for={field}]")
        note.wait_for(state="visible")
        assert "not a number" in note.inner_text()
        assert form.locator(f"[name={field}]").get_attribute("aria-invalid") == "true"
        form.locator(f"[name={field}]").fill("")
    assert page.url == url + "/models"
    assert len(page.request.get(url + "/api/v1/runs").json()["items"]) == 1  # nothing launched
    form.locator("[name=steps]").fill("100")
    page.wait_for_function("() => document.getElementById('launch-estimate').textContent.includes('about 50 s')")
    assert "(100 steps × 0.5 s measured on run 1" in estimate.inner_text()
    form.locator("[name=batch]").fill("4")  # twice the samples a step: twice as long, and said so
    page.wait_for_function("() => document.getElementById('launch-estimate').textContent.includes('about 1 min 40 s')")
    assert "scaled ×2 for batch, crop and iterations" in estimate.inner_text()
    assert errors == []
    page.close()


def test_annotate_help_opens_at_its_title_and_help_sits_in_the_top_bar(browser, server) -> None:  # type: ignore[no-untyped-def]
    url, _ = server
    page, errors = page_with_errors(browser)
    login(page, url, "annotator", PASSWORD)
    places = []
    for path in ("/annotate", "/jobs", "/"):
        page.goto(url + path)
        button = page.locator("[data-help]")
        button.wait_for(state="visible")
        assert page.locator(".topbar [data-help]").count() == 1
        places.append(button.bounding_box())
    assert len({(round(b["x"]), round(b["y"])) for b in places}) == 1, places
    page.goto(url + "/annotate")
    page.locator("#empty").wait_for(state="visible")
    page.keyboard.press("?")
    dialog = page.locator("#keys-help")
    dialog.wait_for(state="visible")
    assert page.evaluate("document.getElementById('keys-help').scrollTop") == 0
    box, title = dialog.bounding_box(), page.locator("#keys-help-title").bounding_box()
    assert title["y"] >= box["y"] and dialog.locator("h3").first.is_visible()
    assert page.evaluate("document.getElementById('keys-help').scrollHeight > document.getElementById('keys-help').clientHeight")
    # With no frame to annotate, the page's asks for one are answered 404, which the console logs.
    assert [e for e in errors if "404" not in e] == []
    page.close()


def test_charts_name_their_x_axis_and_show_several_y_ticks(browser, server) -> None:  # type: ignore[no-untyped-def]
    url, _ = server
    page, errors = page_with_errors(browser)
    login(page, url, "curator", PASSWORD)
    page.goto(url + "/models/runs/1")
    page.wait_for_function("() => Number(document.querySelector('#charts svg[aria-label=\"training loss\"]').dataset.points) > 0")
    for name in ("training loss", "learning rate"):
        chart = page.locator(f'#charts svg[aria-label="{name}"]')
        assert chart.locator("text.chart-axis").text_content() == "step"
        assert chart.locator('text.chart-tick[text-anchor="end"]').count() >= 3, name
    assert errors == []
    page.close()


def test_an_open_tab_says_its_session_ended_for_a_new_password(browser, server) -> None:  # type: ignore[no-untyped-def]
    url, home = server
    page, _ = page_with_errors(browser)  # the refused polls log console errors: expected here
    login(page, url, "curator", PASSWORD)
    page.goto(url + "/jobs")
    settings = make_settings(home)
    rt = Runtime(settings)
    with transaction(rt.sessions) as s:
        admin = user_service.get_user(s, "admin")
        user_service.reset_password(s, admin.id, user_service.get_user(s, "curator"), "a-brand-new-password")
    rt.close()
    banner = page.locator("#session-ended")
    page.wait_for_function("() => document.getElementById('session-ended')?.textContent.includes('password')", timeout=20_000)
    assert "your password was changed (by admin" in banner.inner_text()
    assert banner.locator("a").inner_text() == "log in with the new password"
    banner.locator("a").click()
    page.wait_for_url(url + "/login?*")
    assert "your password was changed" in page.locator("#session-reason").inner_text()
    page.close()

