"""`make demo` in a real browser: every role logs in and sees its navigation; the funnel fills up."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.browser import running_demo

pytestmark = pytest.mark.browser

NAV = {
    "annotator": ["dashboard", "annotate", "frames", "samples", "jobs"],
    "curator": ["dashboard", "annotate", "frames", "review", "samples", "export", "ingest", "models", "evaluation", "jobs"],
    "admin": ["dashboard", "annotate", "frames", "review", "samples", "export", "ingest", "models", "evaluation", "jobs",
              "users"],
}


@pytest.fixture(scope="module")
def demo_url(tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    with running_demo(tmp_path_factory.mktemp("demo") / "ws") as url:
        yield url


@pytest.mark.parametrize("role", list(NAV))
def test_each_role_logs_in_and_sees_its_navigation(browser, demo_url: str, role: str, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    page = browser.new_page()
    page.goto(demo_url + "/")
    assert page.url.startswith(demo_url + "/login")
    page.fill("input[name=name]", role)
    page.fill("input[name=password]", "wrong-password")
    page.click("button[type=submit]")
    assert page.locator(".flash.error").inner_text() == "Wrong user name or password."
    page.fill("input[name=name]", role)
    page.fill("input[name=password]", f"{role}-demo")
    page.click("button[type=submit]")
    page.wait_for_url(demo_url + "/")
    nav = page.locator("nav a").evaluate_all("links => links.map(a => a.dataset.nav)")
    assert nav == NAV[role]
    assert page.locator(".user").get_attribute("data-role") == role
    # the import job of the demo's video lands while we watch: the live funnel shows its frames
    page.wait_for_function("() => Number(document.querySelector('[data-stage=frames] .count').textContent) > 0",
                           timeout=120_000)
    page.screenshot(path=str(tmp_path / f"dashboard-{role}.png"), full_page=True)
    if role == "admin":
        page.click("[data-nav=users]")
        assert page.locator("table.users").inner_text().count("-demo") == 0  # passwords are never shown
        assert "curator" in page.locator("table.users").inner_text()
    page.click("[data-nav=frames]")
    page.wait_for_function("() => [...document.querySelectorAll('#frame-grid img')].some(i => i.complete && i.naturalWidth > 0)")
    page.click("[data-nav=jobs]")
    page.wait_for_selector("#jobs tbody tr[data-state=succeeded]", timeout=120_000)
    kinds = set(page.locator("#jobs tbody tr td:nth-child(2)").all_inner_texts())
    # annotators see only the jobs they launched (the demo's generation jobs), not the admin's ingests
    assert ("ingest" in kinds) == (role != "annotator"), kinds
    page.click("button.link")  # log out
    page.wait_for_url(demo_url + "/login")
    page.close()
