"""The Export page in a real browser: a curator finds it in the navigation, launches an export, watches
its job end, downloads the zip (its manifest inside) and deletes it."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import zipfile
from collections.abc import Iterator
from pathlib import Path

import pytest

from dataset.db import migrate, transaction
from dataset.services import users as user_service
from dataset.tables import Role
from tests.browser import ROOT, login, page_with_errors, serving, stop
from tests.conftest import PASSWORD, make_settings
from tests.runs_data import add_accepted_samples
from webapp.runtime import Runtime

pytestmark = pytest.mark.browser


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """A curator, two videos of accepted samples, the server and a worker."""
    settings = make_settings(tmp_path_factory.mktemp("exports") / "ws")
    migrate(settings.database_url)
    rt = Runtime(settings)
    with transaction(rt.sessions) as s:
        user_service.create_user(s, "curator", Role.curator, PASSWORD)
        add_accepted_samples(s, rt.media, videos=2, frames=2)
    rt.close()
    env = {k: v for k, v in os.environ.items() if not k.startswith("ILLUSION_STUDIO_")}
    worker = subprocess.Popen([sys.executable, "-m", "webapp.cli", "--data-dir", str(settings.home), "worker"], cwd=ROOT,
                              env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        with serving(settings.home) as url:
            yield url
    finally:
        stop(worker)


def test_a_curator_exports_follows_downloads_and_deletes(browser, server: str, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    page, errors = page_with_errors(browser)
    login(page, server, "curator", PASSWORD)
    page.click("[data-nav=export]")
    page.wait_for_url(server + "/exports")
    form = page.locator("#export-form")
    form.locator("[name=split]").fill("train=0.5,test=0.5")
    form.locator("button[type=submit]").click()
    page.wait_for_url(server + "/exports#export-1")
    row = page.locator("#export-1")
    assert "train=0.5,test=0.5" in row.inner_text() and "curator" in row.inner_text()
    # The row follows its job (queued, running) until it has succeeded, then offers the zip.
    page.wait_for_function("() => document.getElementById('export-1').dataset.state === 'succeeded'", timeout=60_000)
    assert row.locator("[data-part=summary]").inner_text() == "4 samples"
    assert row.locator("progress").is_hidden()
    with page.expect_download() as download_info:
        row.locator("a.download").click()
    download = download_info.value
    assert download.suggested_filename == "export-1-native.zip"
    path = tmp_path / "export.zip"
    download.save_as(path)
    with zipfile.ZipFile(path) as archive:
        manifest = json.loads(archive.read("export-1-native/manifest.json"))
    assert len(manifest["samples"]) == 4 and {s["split"] for s in manifest["samples"]} <= {"train", "test"}
    page.on("dialog", lambda dialog: dialog.accept())
    row.locator("button", has_text="Delete").click()
    page.locator(".flash", has_text="Export 1 deleted.").wait_for()
    assert page.locator("#export-1").count() == 0
    assert errors == []
    page.close()
