"""The Models page in a real browser: an admin starts a run's stereo branch from an
imported RAFT-Stereo checkpoint, and the run page says which tensors came from the file."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from dataset.db import migrate, transaction
from dataset.services import users as user_service
from dataset.tables import Role
from model.checkpoint import save_checkpoint
from model.network import FusionNetwork
from model.presets import load_preset
from model.raft_import import convert, strip_module
from model.runs import registry
from tests.browser import login, serving
from tests.conftest import PASSWORD, make_settings
from tests.raft_golden import fixture_state, load_fixture
from tests.runs_data import add_accepted_samples
from tests.test_init_stereo import LITE_WIDTHS
from webapp.runtime import Runtime

pytestmark = [pytest.mark.browser, pytest.mark.slow]


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """A workspace with an admin, accepted samples and an imported RAFT-Stereo checkpoint; its server
    and a train worker."""
    settings = make_settings(tmp_path_factory.mktemp("raft") / "ws")
    migrate(settings.database_url)
    rt = Runtime(settings)
    with transaction(rt.sessions) as s:
        user_service.create_user(s, "admin", Role.admin, PASSWORD)
        add_accepted_samples(s, rt.media, videos=3)
    rt.close()
    conversion = convert(strip_module(fixture_state(load_fixture("default"))))
    save_checkpoint(registry.imported_path(settings.home, "rs"), conversion.network, conversion.config, step=0)
    narrow = load_preset("raft-stereo", LITE_WIDTHS)  # a RAFT-Stereo network as narrow as lite's stereo branch
    save_checkpoint(registry.imported_path(settings.home, "rs-lite"), FusionNetwork(narrow.model), narrow, step=0)
    with serving(settings.home, train_worker=True) as url:
        yield url


def test_a_run_started_from_an_imported_stereo_checkpoint_says_what_loaded(browser, server: str) -> None:  # type: ignore[no-untyped-def]
    page = browser.new_page()
    login(page, server, "admin", PASSWORD)
    page.goto(f"{server}/models")
    form = page.locator("#launch")
    assert "raft-stereo" in form.locator("[name=preset]").inner_text()
    form.locator("[name=init_stereo]").select_option("imported:rs")
    form.locator("[name=preset]").select_option("raft-stereo")
    form.locator("button[type=submit]").click()  # RAFT-Stereo's own network starts with init, not init_stereo
    error = form.locator("[data-error-for=init_stereo]")
    error.wait_for(state="visible")
    assert "start it with init" in error.inner_text()
    # The list says which presets each file's stereo branch fits, and a misfit is refused at launch.
    options = form.locator("[name=init_stereo] option")
    assert options.all_inner_texts()[1:] == ["imported:rs (fits paper)", "imported:rs-lite (fits lite)"]
    assert "checkpoints import --from raft-stereo" in page.locator("#imported-note").inner_text()
    form.locator("[name=preset]").select_option("lite")
    for name, value in (("steps", "2"), ("batch", "1"), ("crop", "32x64"), ("iters", "2")):
        form.locator(f"[name={name}]").fill(value)
    form.locator("[name=devices]").select_option("cpu")
    form.locator("button[type=submit]").click()
    page.wait_for_function("() => document.querySelector('[data-error-for=init_stereo]').textContent.includes('fits: paper')")
    assert "does not fit lite's stereo branch" in error.inner_text() and page.url == f"{server}/models"
    form.locator("[name=init_stereo]").select_option("imported:rs-lite")
    form.locator("button[type=submit]").click()
    page.wait_for_url(f"{server}/models/runs/*")
    assert "imported:rs-lite" in page.locator("#init-summary").inner_text()
    page.wait_for_selector("#init-details:not([hidden])", timeout=300_000)
    assert "tensors from the file" in page.locator("#init-counts").inner_text()
    page.click("#init-details summary")
    assert page.locator("#init-fresh li").count() > 0 and page.locator("#init-unused li").count() > 0
    page.close()
