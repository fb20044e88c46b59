"""Samples in a real browser: the grid reviewed with the keyboard, a sample's 2D views, and its 3D
preview played back by viser's client (WebGL through Chromium's SwiftShader)."""

from __future__ import annotations

import re
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.browser import login, running_demo

pytestmark = pytest.mark.browser


def _magenta_pixels(png: bytes) -> int:
    """Pixels of the illusion tint (magenta over the image colour) in a screenshot."""
    bgr = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR).astype(int)
    b, g, r = bgr[..., 0], bgr[..., 1], bgr[..., 2]
    return int(((r > 140) & (b > 140) & (g < 110)).sum())


def _wait_for_magenta(frame, minimum: int = 200, timeout_s: float = 60) -> bytes:  # type: ignore[no-untyped-def]
    """The viewer's screenshot once the tinted illusion region shows: the scene was rendered."""
    deadline = time.monotonic() + timeout_s
    while True:
        shot = frame.screenshot()
        if _magenta_pixels(shot) >= minimum or time.monotonic() > deadline:
            return shot
        time.sleep(0.5)


def test_curator_reviews_samples_and_sees_them_in_2d_and_3d(browser, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    with running_demo(tmp_path / "ws", videos=1) as url:
        anonymous = browser.new_context()
        for path in ("/samples", "/samples/1", "/samples/1/preview", "/samples/1/scene.viser",
                     "/samples/1/views/anaglyph.png", "/viser/index.html", "/frames/1/preview"):
            response = anonymous.request.get(url + path, max_redirects=0)
            assert response.status == 302 and "/login?next=" in response.headers["location"], path
        anonymous.close()

        page = browser.new_page(viewport={"width": 1400, "height": 900})
        errors: list[str] = []
        page.on("pageerror", lambda error: errors.append(str(error)))
        login(page, url, "curator", "curator-demo")

        # ---- the grid: the demo generated samples for 3 frames before the server started
        page.goto(url + "/samples")
        tiles = page.locator("#samples-grid .tile")
        expect(tiles).to_have_count(3)
        ids = [int(i) for i in tiles.evaluate_all("nodes => nodes.map(n => n.dataset.id)")]
        expect(tiles.nth(0)).to_be_focused()
        assert tiles.nth(0).locator(".metrics dt").all_inner_texts() == ["holes", "EPE", "inliers", "scale"]
        page.wait_for_function("() => [...document.querySelectorAll('#samples-grid img')]"
                               ".every(i => i.complete && i.naturalWidth > 0)")
        page.screenshot(path=str(tmp_path / "samples-grid.png"))

        keys = page.keyboard
        keys.press("a")
        expect(tiles.nth(0)).to_have_attribute("data-state", "accepted")
        expect(tiles.nth(0)).to_have_class(re.compile(r"\bsettled\b"))  # left the filter, kept in place
        expect(tiles.nth(1)).to_be_focused()
        keys.press("r")
        expect(page.locator("#reason-picker")).to_be_visible()
        page.screenshot(path=str(tmp_path / "samples-reason.png"))
        keys.press("1")
        expect(page.locator("#reason-picker")).to_be_hidden()
        expect(tiles.nth(1)).to_have_attribute("data-state", "rejected")
        expect(page.locator("#samples-status")).to_have_text(f"Rejected #{ids[1]}: surface not flat.")
        expect(page.locator("#count-accepted")).to_have_text("1")
        expect(page.locator("#count-rejected")).to_have_text("1")
        expect(tiles.nth(2)).to_be_focused()
        keys.press("d")  # disparity thumbnails
        expect(tiles.nth(2).locator("img")).to_have_attribute("src", re.compile(r"/views/disparity_after\.png"))

        # ---- one sample's page: 2D views, colour bar, QA figures
        keys.press("Enter")
        page.wait_for_url(url + f"/samples/{ids[2]}")
        views = page.locator(".views figure.view img")
        expect(views).to_have_count(5)
        page.wait_for_function("() => [...document.querySelectorAll('.views img')].every(i => i.complete && i.naturalWidth > 0)")
        lo = float(page.locator(".colorbar [data-end=lo]").inner_text())
        hi = float(page.locator(".colorbar [data-end=hi]").inner_text())
        assert 0 < lo < hi
        expect(page.locator(".colorbar .ticks span")).to_have_count(5)
        expect(page.locator(".qa-summary tr")).to_have_count(6)
        assert page.locator(".qa-pairs tbody tr").count() >= 1
        expect(page.locator("#sample-state")).to_have_text("generated")
        page.screenshot(path=str(tmp_path / "samples-page.png"), full_page=True)

        # ---- its 3D preview: viser's client plays the scene served by Flask
        with page.expect_response(lambda r: "/scene.viser?stage=after" in r.url) as scene:
            keys.press("v")
        assert scene.value.ok and len(scene.value.body()) > 10_000
        expect(page.locator("#viewer3d")).to_be_visible()
        assert page.url == url + f"/samples/{ids[2]}/preview"
        viewer = page.frame_locator("#viser-frame")
        expect(viewer.locator("canvas").first).to_be_visible(timeout=60_000)
        after = _wait_for_magenta(page.locator("#viser-frame"))
        assert _magenta_pixels(after) >= 200, "the illusion region never showed in the 3D view"
        (tmp_path / "preview-after.png").write_bytes(after)
        with page.expect_response(lambda r: "/scene.viser?stage=before" in r.url) as scene:
            page.click("#viewer3d [data-stage=before]")
        assert scene.value.ok
        expect(page.locator("#viewer3d [data-stage=before]")).to_have_attribute("aria-pressed", "true")
        (tmp_path / "preview-before.png").write_bytes(_wait_for_magenta(page.locator("#viser-frame")))
        page.click("#viewer3d [data-action=close]")
        expect(page.locator("#viewer3d")).to_be_hidden()

        # ---- accept from the sample page too, then the API agrees with what the pages showed
        keys.press("a")
        expect(page.locator("#sample-state")).to_have_text("accepted")
        items = page.request.get(url + "/api/v1/samples?limit=500").json()["items"]
        states = {item["id"]: item["state"] for item in items}
        assert [states[i] for i in ids] == ["accepted", "rejected", "accepted"]

        # the annotation page's entry point: a frame's newest sample, 3D preview open
        frame_id = next(item["frame_id"] for item in items if item["id"] == ids[0])
        page.goto(url + f"/frames/{frame_id}/preview")
        page.wait_for_url(url + f"/samples/{ids[0]}/preview")
        expect(page.locator("#viewer3d")).to_be_visible()
        assert errors == []
        page.close()
