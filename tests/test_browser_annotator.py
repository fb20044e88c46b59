"""An annotator clicks a mask on a synthetic frame, pairs it with its support, submits and sees the next
frame; a second annotator works in parallel without ever touching the same frame; drafts survive a reload."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from pycocotools import mask as coco_mask
from scipy import ndimage

from tests.browser import ROOT, running_demo

pytestmark = pytest.mark.browser


def interior(mask: np.ndarray) -> tuple[float, float]:
    """The point deepest inside a mask, (x, y) in pixels: where a person clicks first."""
    depth = ndimage.distance_transform_edt(mask)
    y, x = np.unravel_index(int(depth.argmax()), depth.shape)
    return float(x), float(y)


def truth(home: Path, index: int, name: str) -> np.ndarray:
    path = home / "synthetic" / "synthetic-0000" / "frames" / f"{index:06d}" / f"{name}.png"
    return cv2.imread(str(path), cv2.IMREAD_GRAYSCALE) > 127


def login(page, url: str, name: str, password: str) -> None:  # type: ignore[no-untyped-def]
    page.goto(url + "/login")
    page.fill("input[name=name]", name)
    page.fill("input[name=password]", password)
    page.click("button[type=submit]")
    page.wait_for_url(url + "/")


def click_image(page, x: float, y: float, **kw: object) -> None:  # type: ignore[no-untyped-def]
    cx, cy = page.evaluate("([x, y]) => window.annotator.imageToClient(x, y)", [x, y])
    page.mouse.click(cx, cy, **kw)


def csrf(page) -> str:  # type: ignore[no-untyped-def]
    return page.locator('meta[name="csrf-token"]').get_attribute("content")


def test_annotate_pair_submit_next_and_a_second_annotator(browser, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    home = tmp_path / "demo"
    with running_demo(home) as url:
        subprocess.run([sys.executable, "-m", "webapp.cli", "--data-dir", str(home), "users", "create", "ann2",
                        "--role", "annotator", "--password-stdin"], input="ann2-password\n", text=True, check=True,
                       cwd=ROOT, capture_output=True)
        one = browser.new_context(viewport={"width": 1400, "height": 900})
        page = one.new_page()
        errors: list[str] = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        login(page, url, "annotator", "annotator-demo")
        page.click("[data-nav=annotate]")
        page.wait_for_function("window.annotator && window.annotator.frame && window.annotator.frame.id")
        frame = page.evaluate("window.annotator.frame")
        assert frame["state"] == "approved" and frame["lease"]["mine"]

        picture = truth(home, frame["index"], "illusion_00")
        click_image(page, *interior(picture))
        page.wait_for_function("window.annotator.pairs[0].illusion > 0")
        assert "mask in" in page.locator("#status").inner_text()
        page.keyboard.press("s")
        click_image(page, *interior(truth(home, frame["index"], "support_00")))
        page.wait_for_function("window.annotator.pairs[0].support > 0")
        page.select_option("#illusion-type", "picture")
        page.screenshot(path=str(tmp_path / "annotate.png"))
        page.locator("#canvas").focus()
        page.keyboard.press("Enter")
        page.wait_for_function(f"window.annotator.frame && window.annotator.frame.id !== {frame['id']}")
        assert page.url.endswith(f"/annotate/{page.evaluate('window.annotator.frame.id')}")

        saved = page.request.get(f"{url}/api/v1/frames/{frame['id']}").json()
        assert saved["state"] in ("annotated", "generated") and saved["illusion_type"] == "picture"
        kinds = {r["kind"]: r for r in saved["regions"]}
        assert set(kinds) == {"illusion", "support"}
        rle = kinds["illusion"]["mask"]
        got = coco_mask.decode({"size": rle["size"], "counts": rle["counts"].encode()}).astype(bool)
        assert (got & picture).sum() / (got | picture).sum() >= 0.7

        # a stale version is refused and overwrites nothing
        stale = page.request.post(f"{url}/api/v1/frames/{frame['id']}/annotation",
                                  data={"version": 0, "regions": [], "submit": False},
                                  headers={"X-CSRFToken": csrf(page)})
        assert stale.status == 409
        assert len(page.request.get(f"{url}/api/v1/frames/{frame['id']}").json()["regions"]) == 2

        # the second annotator, in parallel, gets another frame and cannot take the first one's
        two = browser.new_context(viewport={"width": 1400, "height": 900})
        other = two.new_page()
        login(other, url, "ann2", "ann2-password")
        other.goto(url + "/annotate")
        other.wait_for_function("window.annotator && window.annotator.frame && window.annotator.frame.id")
        mine = page.evaluate("window.annotator.frame.id")
        theirs = other.evaluate("window.annotator.frame.id")
        assert theirs != mine
        taken = other.request.post(f"{url}/api/v1/frames/{mine}/lease", headers={"X-CSRFToken": csrf(other)})
        assert taken.status == 409
        other.goto(f"{url}/annotate/{mine}")
        other.wait_for_function(f"window.annotator.frame && window.annotator.frame.id === {mine}")
        assert "read-only" in other.locator("#status").inner_text()

        # work in progress survives a reload: the draft is saved and restored
        current = page.evaluate("window.annotator.frame")
        click_image(page, *interior(truth(home, current["index"], "illusion_01")))
        page.wait_for_function("window.annotator.pairs[0].illusion > 0")
        page.wait_for_function("!window.annotator.dirty", timeout=10_000)
        page.reload()
        page.wait_for_function(f"window.annotator && window.annotator.frame && window.annotator.frame.id === {current['id']}")
        assert page.evaluate("window.annotator.pairs[0].illusion") > 0
        page.keyboard.press("?")
        assert page.locator("#help").is_visible()
        assert errors == []
        one.close()
        two.close()
