"""What a newcomer reads on the demo's pages: its training run says it is a short toy run."""

from __future__ import annotations

import pytest

from dataset.db import transaction
from tests.conftest import login
from tests.runs_data import add_accepted_samples
from webapp.cli.demo import DEMO_RUN_NOTE, DEMO_TRAIN, _launch_demo_run
from webapp.runtime import Runtime

pytest.importorskip("torch")


def test_the_demo_run_page_says_it_is_a_toy_run(client, runtime: Runtime, monkeypatch: pytest.MonkeyPatch) -> None:  # type: ignore[no-untyped-def]
    monkeypatch.setitem(DEMO_TRAIN, "train.crop", (64, 96))  # the test's samples are smaller than the demo's
    with transaction(runtime.sessions) as s:
        add_accepted_samples(s, runtime.media, videos=3)
    run_id = _launch_demo_run(runtime)
    assert run_id is not None
    login(client, "curator")
    page = client.get(f"/models/runs/{run_id}").get_data(as_text=True)
    assert 'id="run-note"' in page and "toy run: 40 steps of the lite preset" in page
    assert "expect a validation bad-2" in DEMO_RUN_NOTE
    assert client.get(f"/api/v1/runs/{run_id}").json["launch"]["note"] == DEMO_RUN_NOTE
