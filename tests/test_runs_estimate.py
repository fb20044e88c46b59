"""The run-length estimate: the nearest finished run of the preset, its median step time scaled by
batch × crop pixels × iterations, said in words; a launch field it cannot read is that field's 400;
the launch form starts at the newest finished run's batch, crop and iterations."""

from __future__ import annotations

import pytest

from dataset.db import transaction
from dataset.states import RunState
from dataset.tables import TrainingMetric, TrainingRun
from model.presets import load_preset
from model.runs.run_length import Measured, Size, estimate
from model.runs.schema import MAX_STEPS
from tests.runs_data import add_accepted_samples
from tests.test_runs import _queued_run, bearer


@pytest.fixture(autouse=True)
def _samples(runtime) -> None:  # type: ignore[no-untyped-def]
    with transaction(runtime.sessions) as s:
        add_accepted_samples(s, runtime.media, videos=3)


def _finished(runtime, *, batch: int, crop: tuple[int, int], iters: int, step_s: float,  # type: ignore[no-untyped-def]
              state: RunState = RunState.succeeded) -> int:
    """A finished lite run of that size whose curve says each step took ``step_s`` seconds."""
    run_id = _queued_run(runtime)
    config = load_preset("lite", {"train.batch_size": batch, "train.crop": crop, "train.train_iters": iters}).to_dict()
    with transaction(runtime.sessions) as s:
        run = s.get(TrainingRun, run_id)
        run.config, run.state, run.step = config, state, 4
        run.job.state = "succeeded" if state == RunState.succeeded else run.job.state
        for step, rate in enumerate((batch / step_s, batch / step_s, batch / (10 * step_s)), start=1):
            s.add(TrainingMetric(run_id=run_id, kind="step", step=step, values={"samples_per_s": rate}))
    return run_id


def _estimate(client, tokens, **body):  # type: ignore[no-untyped-def]
    return client.post("/api/v1/runs/estimate", json=body, headers=bearer(tokens, "admin"))


def test_the_estimate_scales_with_batch_crop_and_iterations(client, tokens, runtime) -> None:  # type: ignore[no-untyped-def]
    run_id = _finished(runtime, batch=2, crop=(96, 192), iters=16, step_s=24.1)
    same = _estimate(client, tokens, steps=4, batch=2, crop="96x192", iters=16).json
    assert same["seconds"] == pytest.approx(4 * 24.1) and same["run"] == run_id
    assert same["text"] == f"about 1 min 36 s (4 steps × 24.1 s measured on run {run_id} at batch 2, 96×192, 16 iterations)"
    bigger = _estimate(client, tokens, steps=4, batch=4, crop="96x192", iters=24).json
    assert bigger["seconds"] == pytest.approx(4 * 24.1 * 3) and bigger["scale"] == pytest.approx(3)
    assert bigger["text"].endswith("16 iterations, scaled ×3 for batch, crop and iterations)")
    assert _estimate(client, tokens, steps=4, batch=2, crop="192x192", iters=16).json["seconds"] == pytest.approx(8 * 24.1)
    # The nearest measured run is taken: a second run at batch 8 serves a batch-8 launch unscaled.
    near = _finished(runtime, batch=8, crop=(96, 192), iters=16, step_s=50.0)
    assert _estimate(client, tokens, steps=2, batch=8, crop="96x192", iters=16).json["run"] == near


def test_the_estimate_says_when_no_run_measured_one(client, tokens, runtime) -> None:  # type: ignore[no-untyped-def]
    _finished(runtime, batch=2, crop=(96, 192), iters=16, step_s=24.1, state=RunState.running)  # live: not measured
    answer = _estimate(client, tokens, steps=4).json
    assert answer["seconds"] is None and answer["text"] == "unknown: no finished lite run has recorded its step times yet"
    assert estimate("lite", 10, Size(2, (96, 192), 16), [Measured(1, Size(2, (96, 192), 16), 1.0)])["seconds"] == 10


@pytest.mark.parametrize(("body", "field", "words"), [
    ({"crop": "abc"}, "crop", "expected HxW in pixels, e.g. 192x320"),
    ({"steps": 99999999999}, "steps", f"must be at most {MAX_STEPS}"),
    ({"batch": 257}, "batch", "must be at most 256"),
])
def test_a_field_the_estimate_cannot_read_is_that_field_s_error(client, tokens, runtime, body, field, words) -> None:  # type: ignore[no-untyped-def]
    answer = _estimate(client, tokens, **body)
    assert answer.status_code == 400 and answer.json["field"] == field and words in answer.json["error"], answer.json


def test_the_launch_form_starts_at_the_newest_finished_run(client, tokens, runtime) -> None:  # type: ignore[no-untyped-def]
    page = client.get("/models", headers=bearer(tokens, "admin")).get_data(as_text=True)
    assert 'id="launch-start"' not in page and 'name="crop" placeholder' in page
    run_id = _finished(runtime, batch=2, crop=(96, 192), iters=16, step_s=1.0)
    page = client.get("/models", headers=bearer(tokens, "admin")).get_data(as_text=True)
    assert f"start at run {run_id}'s" in page and 'value="96x192"' in page
    assert 'name="batch" min="1" max="256" placeholder="preset\'s" value="2"' in page
    assert 'name="iters" min="1" max="64" placeholder="preset\'s" value="16"' in page
    assert 'value="lite" selected' in page
