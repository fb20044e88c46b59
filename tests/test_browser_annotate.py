"""The annotation page in a real browser: an annotator clicks the picture of a synthetic frame, pairs it
with its wall, submits with the keyboard and lands on the next frame; a draft survives a reload; a second
annotator works in parallel without ever getting or overwriting the first one's frame."""

from __future__ import annotations

import re
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
from pycocotools import mask as coco_mask
from scipy import ndimage

from tests.browser import ROOT, login, running_demo

pytestmark = pytest.mark.browser

SHOTS = Path("/tmp")


def truth(home: Path, index: int, name: str) -> np.ndarray:
    """A true mask of the synthetic room: illusion_00 is the picture, support_00 its wall band."""
    path = home / "synthetic" / "synthetic-0000" / "frames" / f"{index:06d}" / f"{name}.png"
    return cv2.imread(str(path), cv2.IMREAD_GRAYSCALE) > 127


def interior(mask: np.ndarray) -> tuple[int, int]:
    """The pixel deepest inside a mask: where a person clicks first."""
    depth = ndimage.distance_transform_edt(mask)
    y, x = np.unravel_index(int(depth.argmax()), depth.shape)
    return int(x), int(y)


def decode(rle: dict) -> np.ndarray:
    return coco_mask.decode({"size": rle["size"], "counts": rle["counts"].encode()}).astype(bool)


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / (a | b).sum())


def logged_in_page(context, url: str, name: str, password: str):  # type: ignore[no-untyped-def]
    page = context.new_page()
    login(page, url, name, password)
    return page


def csrf(page) -> dict[str, str]:  # type: ignore[no-untyped-def]
    return {"X-CSRFToken": page.locator('meta[name="csrf-token"]').get_attribute("content")}


def click_image(page, x: int, y: int, **options: object) -> None:  # type: ignore[no-untyped-def]
    cx, cy = page.evaluate("([x, y]) => window.annotator.imageToClient(x, y)", [x, y])
    page.mouse.click(cx, cy, **options)


def shown_frame(page, other_than: int | None = None) -> dict:  # type: ignore[no-untyped-def]
    """The frame the page shows once it is ready (and, if given, once it is not `other_than`)."""
    page.wait_for_function("([other]) => window.annotator?.frame && window.annotator.frame.id !== other",
                           arg=[other_than], timeout=20_000)
    return page.evaluate("window.annotator.frame")


def approve_all(curator, url: str) -> None:  # type: ignore[no-untyped-def]
    """Wait for the demo's worker to ingest and prefilter its video, then approve what passed."""
    deadline = time.monotonic() + 60
    while True:
        jobs = curator.request.get(url + "/api/v1/jobs").json()["items"]
        if any(j["kind"] == "prefilter" for j in jobs) and all(j["state"] == "succeeded" for j in jobs):
            break
        assert time.monotonic() < deadline, f"the demo's jobs did not finish: {jobs}"
        time.sleep(0.3)
    items = curator.request.get(url + "/api/v1/review/frames?state=prefiltered&limit=100").json()["items"]
    assert len(items) >= 4
    body = {"decision": "approve", "reason": "", "items": [{"id": f["id"], "revision": f["revision"]} for f in items]}
    results = curator.request.post(url + "/api/v1/review/bulk", data=body, headers=csrf(curator)).json()["results"]
    assert all(r["status"] == 200 for r in results)


def test_annotator_clicks_pairs_submits_and_a_second_annotator_works_alongside(browser, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    home = tmp_path / "ws"
    with running_demo(home, videos=1) as url:
        subprocess.run([sys.executable, "-m", "webapp.cli", "--data-dir", str(home), "users", "create", "ann2",
                        "--role", "annotator", "--password-stdin"], input="ann2-secret\n", text=True, check=True,
                       cwd=ROOT, capture_output=True)
        errors: list[str] = []
        curators = browser.new_context()
        approve_all(logged_in_page(curators, url, "curator", "curator-demo"), url)
        curators.close()

        one = browser.new_context(viewport={"width": 1400, "height": 860})
        page = logged_in_page(one, url, "annotator", "annotator-demo")
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.click("[data-nav=annotate]")
        frame = shown_frame(page)
        assert frame["state"] == "approved" and frame["lease"]["mine"]
        expect(page.locator("#frame-title")).to_have_text(f"Frame #{frame['id']}")
        assert page.url.endswith(f"/annotate/{frame['id']}")

        # a click inside the picture gives its mask; the round trip is on show
        picture = truth(home, frame["index"], "illusion_00")
        click_image(page, *interior(picture))
        page.wait_for_function("() => window.annotator.pairs[0].illusion > 0")
        # "mask in 48 ms", or seconds on a loaded machine: only that a figure is shown matters here
        expect(page.locator("#timing")).to_have_text(re.compile(r"^mask in (\d+ ms|\d+(\.\d+)? s)$"))
        expect(page.locator("[data-pair='1'] [data-chip=illusion]")).to_have_attribute("data-done", "yes")

        # a reload before the draft reached the server brings the work back from this browser
        page.reload()
        assert shown_frame(page)["id"] == frame["id"]
        assert page.evaluate("window.annotator.pairs[0].illusion") > 0
        expect(page.locator("#message")).to_have_text("Restored your unsaved changes from this browser.")
        page.wait_for_function("() => !window.annotator.dirty", timeout=10_000)  # and the autosave follows
        expect(page.locator("#save-state")).to_have_text("Draft saved")
        draft = page.request.get(f"{url}/api/v1/frames/{frame['id']}").json()
        assert [r["kind"] for r in draft["regions"]] == ["illusion"] and not draft["submitted"]

        # correcting it: a right-click on the picture's edge takes a piece off, a click on the wall adds
        # one; each sends the previous mask along and gets a new one back, with no error on the page
        ys, xs = np.nonzero(picture)
        row = int(np.median(ys))
        inside = np.flatnonzero(picture[row])
        for point, button, grows in (((int(inside[3]), row), "right", False),
                                     ((int(inside[0]) - 6, row), "left", True)):
            before = page.evaluate("window.annotator.pairs[0].illusion")
            click_image(page, *point, button=button)
            page.wait_for_function("([before]) => window.annotator.pairs[0].illusion !== before"
                                   " || document.getElementById('status').dataset.kind === 'error'",
                                   arg=[before], timeout=10_000)
            expect(page.locator("#message")).not_to_contain_text("failed")
            after_area = page.evaluate("window.annotator.pairs[0].illusion")
            assert (after_area > before) if grows else (0 < after_area < before), (button, before, after_area)
            page.keyboard.press("Control+z")  # back to the first mask for what follows
            page.wait_for_function("([before]) => window.annotator.pairs[0].illusion === before", arg=[before])
        page.wait_for_function("() => !window.annotator.dirty", timeout=10_000)

        # a brush stroke is the latest word on the mask: the last click's timing and message go
        page.keyboard.press("b")
        before = page.evaluate("window.annotator.pairs[0].illusion")
        cx, cy = page.evaluate("([x, y]) => window.annotator.imageToClient(x, y)", [int(inside[0]) - 8, row])
        page.mouse.move(cx, cy)
        page.mouse.down()
        page.mouse.move(cx, cy + 20, steps=5)
        page.mouse.up()
        page.wait_for_function("([b]) => window.annotator.pairs[0].illusion > b", arg=[before])
        expect(page.locator("#message")).to_have_text("Illusion of plane 1: painted by hand.")
        expect(page.locator("#timing")).to_have_text("")
        page.keyboard.press("Control+z")
        page.keyboard.press("c")
        page.wait_for_function("() => !window.annotator.dirty", timeout=10_000)

        # its support: the wall band around the picture
        page.keyboard.press("s")
        band = truth(home, frame["index"], "support_00")
        click_image(page, *interior(band))
        page.wait_for_function("() => window.annotator.pairs[0].support > 0")
        page.keyboard.press("Enter")  # no type yet: the dialog asks, with its first type focused
        expect(page.locator("#type-dialog")).to_be_visible()
        expect(page.locator("#type-dialog .choice").first).to_be_focused()
        page.keyboard.press("Escape")  # a dismissed submit says why nothing happened
        expect(page.locator("#message")).to_have_text(re.compile(r"^Not submitted: plane 1 needs an illusion type"))
        page.keyboard.press("t")
        expect(page.locator("#type-dialog")).to_be_visible()
        page.keyboard.press("2")
        expect(page.locator("#pairs [data-pair='1'] select.pair-type")).to_have_value("picture")
        # each pair has a type of its own (a frame can hold a picture and a mirror), changed in its row
        page.select_option("#pairs [data-pair='1'] select.pair-type", "mirror")
        page.wait_for_function("() => window.annotator.pairs[0].type === 'mirror'")
        page.locator("#canvas").focus()
        page.screenshot(path=str(SHOTS / "annotate-1-pair.png"))

        # on a laptop screen with two planes, the frame's actions stay in view (a sticky bar)
        page.set_viewport_size({"width": 1366, "height": 768})
        page.keyboard.press("n")
        assert len(page.evaluate("window.annotator.pairs")) == 2
        for button in ("#submit", "#delete"):
            assert page.evaluate("""(sel) => { const b = document.querySelector(sel).getBoundingClientRect();
                const hit = document.elementFromPoint(b.left + b.width / 2, b.top + b.height / 2);
                return b.bottom <= innerHeight && hit?.closest(sel) !== null; }""", button), button
        page.screenshot(path=str(SHOTS / "annotate-1366.png"))
        page.keyboard.press("Backspace")  # the empty plane goes again
        assert len(page.evaluate("window.annotator.pairs")) == 1
        page.set_viewport_size({"width": 1400, "height": 860})

        page.keyboard.press("Enter")
        after = shown_frame(page, other_than=frame["id"])
        assert page.url.endswith(f"/annotate/{after['id']}")
        expect(page.locator("#frame-title")).to_have_text(f"Frame #{after['id']}")
        expect(page.locator("#message")).to_have_text(f"Submitted frame #{frame['id']}. This is the next one.")
        page.screenshot(path=str(SHOTS / "annotate-2-next.png"))

        saved = page.request.get(f"{url}/api/v1/frames/{frame['id']}").json()
        assert saved["submitted"] and saved["state"] in ("annotated", "generated")
        assert saved["illusion_type"] == "mirror"  # the annotation's: its first plane's
        regions = {(r["pair"], r["kind"]): r for r in saved["regions"]}
        assert set(regions) == {(1, "illusion"), (1, "support")}
        assert {r["illusion_type"] for r in saved["regions"]} == {"mirror"}
        assert iou(decode(regions[1, "illusion"]["mask"]), picture) >= 0.7
        support = decode(regions[1, "support"]["mask"])
        assert support[interior(band)[::-1]] and (support & band).sum() > 0.5 * band.sum()

        # the second annotator, in parallel, gets another frame and can't take or overwrite this one's
        mine = after["id"]
        click_image(page, *interior(truth(home, after["index"], "illusion_01")))  # the mirror
        page.wait_for_function("() => window.annotator.pairs[0].illusion > 0 && !window.annotator.dirty", timeout=10_000)
        version = page.request.get(f"{url}/api/v1/frames/{mine}").json()["annotation_version"]
        assert version >= 1

        # propagation carries the mirror to the next frames as drafts, with a progress bar meanwhile
        page.keyboard.press("p")
        expect(page.locator("#propagate-dialog")).to_be_visible()
        page.fill("#propagate-count", "2")
        page.keyboard.press("Enter")
        expect(page.locator("#message")).to_have_text(re.compile(r"^Propagated plane 1 to 2 frames as drafts"),
                                                      timeout=20_000)
        expect(page.locator("#propagate-progress")).to_have_attribute("value", "1")
        following = page.request.get(f"{url}/api/v1/frames/{after['next_id']}").json()
        assert [(r["pair"], r["kind"]) for r in following["regions"]] == [(1, "illusion")]
        assert following["regions"][0]["clicks"] == [{"propagated_from": mine}] and not following["submitted"]

        two = browser.new_context(viewport={"width": 1400, "height": 860})
        other = logged_in_page(two, url, "ann2", "ann2-secret")
        other.on("pageerror", lambda e: errors.append(str(e)))
        other.goto(url + "/annotate")
        theirs = shown_frame(other)["id"]
        assert theirs not in (mine, frame["id"])
        again = other.request.post(url + "/api/v1/queue/annotate/next", headers=csrf(other)).json()
        assert again["frame_id"] == theirs  # the queue hands ann2 their own frame, never the annotator's
        assert other.request.post(f"{url}/api/v1/frames/{mine}/lease", headers=csrf(other)).status == 409
        overwrite = other.request.post(f"{url}/api/v1/frames/{mine}/annotation", headers=csrf(other),
                                       data={"version": version, "regions": [], "submit": False})
        assert overwrite.status == 409
        stale = page.request.post(f"{url}/api/v1/frames/{mine}/annotation", headers=csrf(page),
                                  data={"version": version - 1, "regions": [], "submit": False})
        assert stale.status == 409 and "changed since you loaded it" in stale.json()["error"]
        kept = page.request.get(f"{url}/api/v1/frames/{mine}").json()
        assert kept["annotation_version"] == version and [r["kind"] for r in kept["regions"]] == ["illusion"]

        other.goto(f"{url}/annotate/{mine}")  # looking is fine, but read-only
        assert shown_frame(other)["id"] == mine
        expect(other.locator("#status")).to_contain_text("read-only: another annotator is working on it")
        expect(other.locator("#banner")).to_be_visible()
        other.screenshot(path=str(SHOTS / "annotate-3-read-only.png"))
        other.keyboard.press("n")  # no planes added on someone else's frame
        assert other.evaluate("window.annotator.pairs.length") == 1
        other.keyboard.press("Enter")  # read-only: Enter takes the next frame from the queue
        assert shown_frame(other, other_than=mine)["id"] not in (mine, frame["id"])

        # a save from elsewhere makes the page's version stale: it says so and overwrites nothing
        elsewhere = page.request.post(f"{url}/api/v1/frames/{mine}/annotation", headers=csrf(page),
                                      data={"version": version, "regions": kept["regions"], "submit": False})
        assert elsewhere.ok
        page.keyboard.press("s")
        click_image(page, *interior(truth(home, after["index"], "support_01")))
        expect(page.locator("#banner")).to_contain_text("Someone else saved this frame", timeout=10_000)
        expect(page.locator("#save-state")).to_have_text("Not saved")
        assert page.request.get(f"{url}/api/v1/frames/{mine}").json()["annotation_version"] == version + 1
        page.screenshot(path=str(SHOTS / "annotate-4-conflict.png"))

        page.keyboard.press("?")
        expect(page.locator("#keys-help")).to_be_visible()
        expect(page.locator("#keys-help")).to_contain_text("propagate the current pair to the next frames")
        page.screenshot(path=str(SHOTS / "annotate-5-help.png"))
        page.keyboard.press("Escape")
        expect(page.locator("#keys-help")).to_be_hidden()

        # reloading takes the server's version and offers this browser's changes back
        page.reload()
        assert shown_frame(page)["id"] == mine
        expect(page.locator("#banner-action")).to_have_text("Use my changes")
        page.click("#banner-action")
        page.wait_for_function("() => window.annotator.pairs[0].support > 0 && !window.annotator.dirty", timeout=10_000)
        assert page.request.get(f"{url}/api/v1/frames/{mine}").json()["annotation_version"] == version + 2

        # delete with a reason: the frame leaves the pipeline and the next one comes
        page.keyboard.press("x")
        expect(page.locator("#delete-dialog")).to_be_visible()
        page.keyboard.press("1")
        assert shown_frame(page, other_than=mine)["id"] not in (mine, theirs)
        assert page.request.get(f"{url}/api/v1/frames/{mine}").json()["state"] == "deleted"
        assert errors == []
        one.close()
        two.close()
