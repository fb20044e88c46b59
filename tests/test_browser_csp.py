"""The pages and viser's 3D client work under the Content-Security-Policy: no violations in a real browser."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.browser import login, running_demo

PAGES = ("/", "/frames", "/jobs", "/annotate", "/review", "/ingest", "/samples", "/samples/1", "/admin/users",
         "/samples/1/preview")


def test_security_headers_on_pages_and_the_viser_client(client, tokens) -> None:  # type: ignore[no-untyped-def]
    from webapp.headers import PAGES as PAGE_CSP
    from webapp.headers import VISER

    page = client.get("/login")
    assert page.headers["Content-Security-Policy"] == PAGE_CSP and "frame-ancestors 'self'" in PAGE_CSP
    assert page.headers["X-Content-Type-Options"] == "nosniff" and page.headers["X-Frame-Options"] == "SAMEORIGIN"
    assert page.headers["Referrer-Policy"] == "same-origin" and "Strict-Transport-Security" not in page.headers
    viser = client.get("/viser/index.html", headers={"Authorization": f"Bearer {tokens['annotator']}"})
    assert viser.headers["Content-Security-Policy"] == VISER
    assert "'unsafe-inline'" not in PAGE_CSP.split("script-src")[1].split(";")[0]


def test_https_setting_marks_cookies_secure_and_sends_hsts(tmp_path: Path) -> None:
    from dataset.db import migrate
    from tests.conftest import make_settings
    from webapp.app import create_app

    settings = make_settings(tmp_path / "tls", https=True)
    migrate(settings.database_url)
    app = create_app(settings)
    response = app.test_client().get("/login")
    assert "Strict-Transport-Security" in response.headers
    assert "Secure" in response.headers["Set-Cookie"]


@pytest.mark.slow
def test_no_csp_violations_on_the_main_pages_and_the_3d_preview(browser, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    with running_demo(tmp_path / "ws", videos=1) as url:
        page = browser.new_page()
        problems: list[str] = []
        page.on("console", lambda m: problems.append(m.text) if "Content Security Policy" in m.text else None)
        page.on("pageerror", lambda e: problems.append(str(e)))
        login(page, url, "admin", "admin-demo")
        for path in PAGES:
            page.goto(url + path)
            page.wait_for_load_state("networkidle")
        page.wait_for_timeout(3000)  # the 3D client compiles and loads its scene
        frames = [f.url for f in page.frames]
        assert any("/viser/" in f for f in frames), f"the 3D preview did not open: {frames}"
        assert not problems, "\n".join(problems)
