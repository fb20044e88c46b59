"""The loops between curator and annotator in a real browser at 1366x768: a frame whose sample a curator
rejected comes back first to its annotator with who, when and why; planes carry their own illusion
type; a right-click before any click inside says where to start, without asking the server; the
Ingest page stays as wide as the window for a 200-character file name and says when an upload copies a
video already there; the dashboard's "prefiltered" leaves out what the prefilter rejected, and `?`
explains Dashboard and Ingest."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from sqlalchemy import select, update

from dataset.db import migrate, transaction
from dataset.services import jobs as job_service
from dataset.services import users as user_service
from dataset.services.ingest import ingest_params
from dataset.services.sample_review import review_sample
from dataset.synthetic import write_synthetic_dataset
from dataset.tables import Frame, FrameState, PrefilterResult, Role, User
from tests.browser import collect_errors, login, serving
from tests.conftest import PASSWORD, make_settings
from tests.test_browser_annotate import click_image, interior, shown_frame
from tests.test_returned_frames import submitted_and_generated
from tests.test_scene_groups import reencode
from webapp.jobs.handlers import HANDLERS
from webapp.runtime import Runtime

pytestmark = pytest.mark.browser
VIEWPORT = {"width": 1366, "height": 768}
REASON = "the support band misses the wall below the picture"


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Any]]:
    """One synthetic video of 5 frames: the prefilter dropped the last, a curator approved the rest;
    the annotator submitted the third, and a curator rejected its sample. Served, with no worker
    (tests run the jobs they need here)."""
    tmp = tmp_path_factory.mktemp("loop")
    settings = make_settings(tmp / "ws")
    migrate(settings.database_url)
    rt = Runtime(settings)
    [scene] = write_synthetic_dataset(tmp / "s", videos=1, seed=8, n_frames=5, width=320, height=180)
    with transaction(rt.sessions) as s:
        people = {role: user_service.create_user(s, role.value, role, PASSWORD) for role in Role}
        rt.submit(s, "ingest", ingest_params(str(scene), fps=None, dedup_hamming=None), None)
    job_service.run_queued_jobs(HANDLERS, rt)
    with transaction(rt.sessions) as s:
        frames = s.scalars(select(Frame).order_by(Frame.index)).all()
        s.execute(update(Frame).values(state=FrameState.approved))
        s.execute(update(Frame).where(Frame.id == frames[-1].id).values(state=FrameState.rejected))
        s.add(PrefilterResult(frame_id=frames[-1].id, backend="heuristic", model_id="m", prompt_version="v1",
                              answers=[None] * 12, keep=False))
    with transaction(rt.sessions) as s:
        returned = s.get(Frame, frames[2].id)
        sample = submitted_and_generated(s, rt.media, returned, s.get(User, people[Role.annotator].id))
        review_sample(s, sample.id, s.get(User, people[Role.curator].id), "reject", REASON)
    try:
        with serving(settings.home) as url:
            yield {"url": url, "rt": rt, "scene": scene, "frames": [f.id for f in frames], "returned": returned.id}
    finally:
        rt.close()


@pytest.fixture
def open_page(browser, server: dict[str, Any]):  # type: ignore[no-untyped-def]
    """A page logged in as a role, with the lists its script errors and console errors go to."""
    contexts = []

    def open_(role: str):  # type: ignore[no-untyped-def]
        context = browser.new_context(viewport=VIEWPORT)
        contexts.append(context)
        page = context.new_page()
        errors = collect_errors(page)
        login(page, server["url"], role, PASSWORD)
        return page, errors

    yield open_
    for context in contexts:
        for page in context.pages:
            page.unroute_all(behavior="ignoreErrors")
        context.close()


def test_dashboard_counts_what_passed_the_prefilter_and_explains_itself(open_page, server, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    page, errors = open_page("annotator")
    counts = page.request.get(server["url"] + "/api/v1/stats/funnel").json()
    assert (counts["frames"], counts["prefiltered"]) == (5, 4)  # the prefilter's rejection is not a pass
    expect(page.locator("[data-stage=prefiltered] .count")).to_have_text("4")
    expect(page.locator("[data-stage=frames] .count")).to_have_text("5")
    page.keyboard.press("?")
    help_ = page.locator("#keys-help")
    expect(help_).to_be_visible()
    expect(help_.locator("tr", has_text="prefiltered")).to_contain_text("its rejections not counted")
    page.screenshot(path=str(tmp_path / "dashboard-help.png"))
    page.keyboard.press("Escape")
    page.click("[data-help]")
    expect(help_).to_be_visible()
    assert errors == []


def test_a_returned_frame_comes_first_with_the_curators_reason(open_page, server, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    page, errors = open_page("annotator")
    page.click("[data-nav=annotate]")
    frame = shown_frame(page)
    assert frame["id"] == server["returned"]  # before the older frames nobody has touched
    note = page.locator("#returned")
    expect(note).to_be_visible()
    expect(note.locator("h2")).to_have_text(re.compile(r"^Sent back to you by curator on .+, who rejected its sample:$"))
    expect(note.locator("blockquote")).to_have_text(REASON)
    expect(page.locator("#message")).to_have_text(re.compile(r"^Draft loaded: \d+ planes?, sent back by curator: "))
    pairs = page.evaluate("window.annotator.pairs")
    assert pairs and all(p["illusion"] > 0 for p in pairs)  # the draft, typed per plane as the scene says
    assert {p["type"] for p in pairs} == {"picture", "mirror"}
    page.screenshot(path=str(tmp_path / "annotate-returned.png"))

    # another frame says nothing of it
    page.keyboard.press("ArrowLeft")
    shown_frame(page, other_than=server["returned"])
    expect(note).to_be_hidden()
    assert errors == []


def test_planes_carry_their_type_and_a_right_click_first_says_where_to_start(open_page, server, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    page, errors = open_page("annotator")
    asked: list[dict] = []
    page.on("request", lambda r: r.url.endswith("/segment") and asked.append(r.post_data_json))
    page.goto(f"{server['url']}/annotate/{server['frames'][0]}")
    frame = shown_frame(page)
    assert frame["id"] == server["frames"][0] and not frame["regions"]

    # one place for the type: each plane's own; the frame-wide control is gone, and the page says why
    assert page.locator("#illusion-type").count() == 0
    expect(page.locator("#planes-hint")).to_contain_text("Each plane has its own illusion type")
    plane = page.locator("#pairs [data-pair='1'] select.pair-type")
    expect(plane).to_have_value("")
    page.keyboard.press("t")
    expect(page.locator("#type-title")).to_have_text("Illusion type of plane 1")
    page.keyboard.press("2")
    expect(plane).to_have_value("picture")
    page.keyboard.press("n")  # a new plane starts with the selected plane's type, in view
    expect(page.locator("#pairs [data-pair='2'] select.pair-type")).to_have_value("picture")
    expect(page.locator("#message")).to_have_text("Added plane 2 (picture; T changes it): click its illusion.")
    page.screenshot(path=str(tmp_path / "annotate-plane-types.png"))
    page.keyboard.press("Backspace")

    # a right-click before any click inside: the page says where to start; no request, no error
    picture = _truth(server["scene"], frame["index"], "illusion_00")
    x, y = interior(picture)
    click_image(page, 5, 5, button="right")
    expect(page.locator("#message")).to_have_text(
        "Start with a click inside the object: a right-click only takes away from a mask.")
    assert asked == []
    # the click inside that follows takes the red dot along and gets its mask
    click_image(page, x, y)
    page.wait_for_function("() => window.annotator.pairs[0].illusion > 0")
    assert [len(a["points"]) for a in asked] == [2] and asked[0]["labels"] == [0, 1]
    assert errors == []


def test_ingest_keeps_its_width_for_a_long_name_and_says_when_a_video_is_a_copy(open_page, server, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    page, errors = open_page("curator")
    page.click("[data-nav=ingest]")
    page.keyboard.press("?")
    help_ = page.locator("#keys-help")
    expect(help_.locator("tr", has_text="A copy")).to_contain_text("scene group")
    page.keyboard.press("Escape")

    name = ("holiday_" + "very_long_name_" * 14)[:196] + ".avi"  # nowhere to break a line
    assert len(name) == 200
    copy = reencode(server["scene"] / "video.mp4", tmp_path / "copy.avi")
    page.set_input_files("input[name=file]", files=[{"name": name, "mimeType": "video/x-msvideo",
                                                     "buffer": copy.read_bytes()}])
    page.uncheck("input[name=prefilter]")
    page.click("#upload button[type=submit]")
    row = page.locator("#uploads li").first
    expect(row.locator(".status")).to_contain_text("queued")
    job_service.run_queued_jobs(HANDLERS, server["rt"])  # the worker's part
    expect(row.locator(".status")).to_contain_text("succeeded", timeout=15_000)
    expect(row.locator(".copy-note")).to_have_text(re.compile(
        r"^Looks like a copy of video 1 \(“synthetic-0008”; \d+ of \d+ frames alike\): kept in the same scene group"))
    page.screenshot(path=str(tmp_path / "ingest-long-name.png"), full_page=True)

    width = page.evaluate("document.documentElement.scrollWidth")
    assert width <= VIEWPORT["width"], width  # the name is cut with an ellipsis, in full on hover
    shown = row.locator(".name")
    expect(shown).to_have_attribute("title", name)
    assert shown.evaluate("n => n.scrollWidth > n.clientWidth")
    assert errors == []


def _truth(scene: Path, index: int, name: str):  # type: ignore[no-untyped-def]
    import cv2

    return cv2.imread(str(scene / "frames" / f"{index:06d}" / f"{name}.png"), cv2.IMREAD_GRAYSCALE) > 127
