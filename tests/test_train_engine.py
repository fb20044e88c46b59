"""The training engine end to end on a small native export: events, checkpoints, validation,
TensorBoard, keep.json, fine-tuning, divergence, bad input; DDP equals one process; a SIGKILLed
run resumes exactly; trainers stop when their worker dies."""

from __future__ import annotations

import json
import math
import signal
import subprocess
import time
from pathlib import Path

import pytest
import torch

from model.checkpoint import load_checkpoint
from model.train import EXIT_DIVERGED, EXIT_FAILED, EXIT_ORPHANED, EXIT_SUCCEEDED
from model.train.checkpoints import best_path, step_checkpoints, step_path
from model.train.events import read_events
from model.train.watch import alive
from tests.train_runs import (
    engine_env,
    events,
    make_run,
    max_difference,
    parameters,
    python_command,
    run_engine,
    split_names,
    torchrun_command,
    train_here,
)


@pytest.mark.slow
def test_a_run_writes_events_checkpoints_validation_and_tensorboard(native: Path, tmp_path: Path) -> None:
    run = make_run(tmp_path / "run", native, checkpoint_every=1, keep_last=1)
    n_train, n_val = (len(names) for names in split_names(native).values())
    (run / "keep.json").write_text(json.dumps({"paths": ["checkpoints/step_0000001.pt"]}))
    assert train_here(run) == EXIT_SUCCEEDED
    log = read_events(run)
    times = [e.pop("time") for e in log]
    assert times == sorted(times) and times[0] > 1.7e9
    assert log[0] == {"event": "start", "step": 0, "steps": 4, "world_size": 1, "resumed_from_step": None,
                      "device": "cpu", "dataset_version": None, "samples": {"train": n_train, "val": n_val}}
    assert log[-1] == {"event": "end", "state": "succeeded", "reason": None, "step": 4}
    steps = events(run, "step")
    assert steps[0]["step"] == 1 and steps[-1]["step"] == 4
    for event in steps:
        assert math.isfinite(event["loss"]) and event["lr"] > 0 and event["samples_per_s"] > 0 and event["eta_s"] >= 0
        assert event["parts"] and all(math.isfinite(v) for v in event["parts"].values())
    vals = events(run, "val")
    assert [v["step"] for v in vals] == [2, 4]
    for val in vals:
        assert set(val["metrics"]) == {"all", "illusion", "non_illusion"}
        assert all(set(m) == {"epe", "bad2", "bad3"} for m in val["metrics"].values())
        assert val["metrics"]["all"]["epe"] > 0 and 0 <= val["metrics"]["all"]["bad2"] <= 100
        assert len(val["images"]) == min(n_val, 4) and all((run / p).is_file() for p in val["images"])
        assert all(p.startswith(f"val/step_{val['step']:07d}/") and p.endswith(".png") for p in val["images"])
    saved = events(run, "checkpoint")
    assert [(c["step"], c["path"]) for c in saved if not c["best"]] == [
        (s, f"checkpoints/step_{s:07d}.pt") for s in (1, 2, 3, 4)]
    assert all(c["path"] == "checkpoints/best.pt" for c in saved if c["best"]) and saved[1]["best"] is False
    # keep_last 1: only the newest and what keep.json lists stay, and the best.
    assert [s for s, _ in step_checkpoints(run)] == [1, 4] and best_path(run).is_file()
    payload = load_checkpoint(step_path(run, 4))
    extra = payload["extra"]
    assert payload["step"] == 4 and extra["data"] == {"position": 8, "epoch": 8 // n_train, "offset": 8 % n_train,
                                                      "samples": n_train, "seed": 3, "batch_size": 2}
    assert {"optimizer", "scheduler", "scaler", "rng", "dataset_version", "best_epe"} <= set(extra)
    assert len(extra["rng"]) == 1 and extra["best_epe"] == min(v["metrics"]["all"]["epe"] for v in vals)
    assert any(p.name.startswith("events.out.tfevents") for p in (run / "tensorboard").iterdir())


@pytest.mark.slow
@pytest.mark.serial  # two gloo ranks beside another test process's load once aborted at teardown
def test_two_gloo_processes_equal_one_with_the_same_global_batch(native: Path, tmp_path: Path) -> None:
    one = make_run(tmp_path / "one", native, val=False, steps=3, checkpoint_every=3)
    two = make_run(tmp_path / "two", native, val=False, steps=3, checkpoint_every=3)
    # Both under torchrun, so both ranks' kernels run with the thread count it gives them: a
    # different count reorders float sums, and Adam amplifies such rounding in tiny gradients.
    assert run_engine(torchrun_command(one, 1)).returncode == EXIT_SUCCEEDED
    result = run_engine(torchrun_command(two, 2))
    assert result.returncode == EXIT_SUCCEEDED, result.stderr[-3000:]
    assert "find_unused_parameters" not in result.stderr  # every parameter gets a gradient: DDP need not search
    assert events(two, "start")[0]["world_size"] == 2
    assert max_difference(parameters(one, 3), parameters(two, 3)) < 1e-5
    # Step events are paced by time: compare the steps both logged (the first and last always are).
    losses = [{e["step"]: e["loss"] for e in events(run, "step")} for run in (one, two)]
    common = sorted(losses[0].keys() & losses[1].keys())
    assert common[0] == 1 and common[-1] == 3
    assert [losses[0][s] for s in common] == pytest.approx([losses[1][s] for s in common], rel=1e-5)


@pytest.mark.slow
def test_a_sigkilled_run_resumes_to_the_uninterrupted_parameters(native: Path, tmp_path: Path) -> None:
    kw = {"val": True, "steps": 6, "checkpoint_every": 2, "val_every": 3}
    reference = make_run(tmp_path / "reference", native, **kw)
    assert run_engine(python_command(reference)).returncode == EXIT_SUCCEEDED
    run = make_run(tmp_path / "run", native, **kw)
    proc = subprocess.Popen(python_command(run), env=engine_env(), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 180
        while not any(e["event"] == "checkpoint" for e in read_events(run)) and time.monotonic() < deadline:
            assert proc.poll() is None, proc.stderr.read().decode()[-3000:] if proc.stderr else ""
            time.sleep(0.05)
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.kill()
        proc.wait()
    killed_at = step_checkpoints(run)[-1][0]
    assert killed_at < 6
    result = run_engine(python_command(run))
    assert result.returncode == EXIT_SUCCEEDED, result.stderr[-3000:]
    assert events(run, "start")[-1]["resumed_from_step"] == killed_at
    done, expected = parameters(run, 6), parameters(reference, 6)
    assert all(torch.equal(done[k], expected[k]) for k in expected)  # bit for bit on CPU
    # The resumed run validated and logged as the uninterrupted one did from where it resumed
    # (but for how long validation took).
    assert [{**e, "seconds": 0} for e in events(run, "val") if e["step"] > killed_at] == [
        {**e, "seconds": 0} for e in events(reference, "val") if e["step"] > killed_at]


@pytest.mark.slow
def test_watched_worker_death_ends_every_rank(native: Path, tmp_path: Path) -> None:
    run = make_run(tmp_path / "run", native, val=False, steps=100000, checkpoint_every=100000)
    worker = subprocess.Popen(["sleep", "120"])
    trainer = subprocess.Popen(torchrun_command(run, 2, "--watch-pid", str(worker.pid)), env=engine_env(),
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while not events(run, "step") and time.monotonic() < deadline:
            assert trainer.poll() is None
            time.sleep(0.1)
        ranks = _children(trainer.pid)
        assert len(ranks) == 2 and all(alive(pid) for pid in ranks)
        worker.kill()
        worker.wait()
        started = time.monotonic()
        trainer.wait(timeout=30)
        assert time.monotonic() - started < 15
        assert not any(alive(pid) for pid in ranks)
    finally:
        worker.kill()
        worker.wait()
        if trainer.poll() is None:
            import os

            os.killpg(trainer.pid, signal.SIGKILL)
            trainer.wait()


def _children(pid: int) -> list[int]:
    """The direct children of ``pid`` (Linux /proc)."""
    found = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        found += [int(p) for p in (task / "children").read_text().split()]
    return found


def test_a_plain_process_exits_when_its_watched_process_is_gone(native: Path, tmp_path: Path) -> None:
    run = make_run(tmp_path / "run", native, val=False, steps=100000)
    worker = subprocess.Popen(["sleep", "120"])
    trainer = subprocess.Popen(python_command(run, "--watch-pid", str(worker.pid)), env=engine_env(),
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        time.sleep(1.0)
        worker.kill()
        worker.wait()
        assert trainer.wait(timeout=15) == EXIT_ORPHANED
    finally:
        for proc in (worker, trainer):
            proc.kill()
            proc.wait()


@pytest.mark.slow
def test_a_non_finite_loss_stops_as_diverged_and_keeps_the_good_checkpoint(native: Path, tmp_path: Path) -> None:
    # An absurd learning rate blows the weights up after the first step: the second loss is not finite.
    run = make_run(tmp_path / "run", native, val=False, steps=5, checkpoint_every=1, lr=1e30)
    assert train_here(run) == EXIT_DIVERGED
    end = read_events(run)[-1]
    assert end["event"] == "end" and end["state"] == "diverged" and end["step"] == 1
    assert end["reason"].startswith("non-finite loss") and "at step 2" in end["reason"]
    assert [s for s, _ in step_checkpoints(run)] == [1]
    assert load_checkpoint(step_path(run, 1))["step"] == 1


@pytest.mark.slow
def test_init_checkpoint_starts_from_its_weights_at_step_zero(native: Path, tmp_path: Path) -> None:
    base = make_run(tmp_path / "base", native, val=False, steps=2, checkpoint_every=2)
    assert train_here(base) == EXIT_SUCCEEDED
    # A learning rate so small that one step leaves the weights where they started.
    tuned = make_run(tmp_path / "tuned", native, val=False, steps=1, lr=1e-20, init=step_path(base, 2))
    fresh = make_run(tmp_path / "fresh", native, val=False, steps=1, lr=1e-20)
    assert train_here(tuned) == EXIT_SUCCEEDED and train_here(fresh) == EXIT_SUCCEEDED
    assert events(tuned, "start")[0]["resumed_from_step"] is None
    assert max_difference(parameters(tuned, 1), parameters(base, 2)) < 1e-6
    assert max_difference(parameters(fresh, 1), parameters(base, 2)) > 1e-4


def test_bad_run_directories_fail_with_a_reason(native: Path, tmp_path: Path) -> None:
    assert train_here(tmp_path / "missing") == EXIT_FAILED
    empty = tmp_path / "empty"
    empty.mkdir()
    assert train_here(empty) == EXIT_FAILED
    assert read_events(empty)[-1]["reason"].endswith("no run.json in the run directory")
    run = make_run(tmp_path / "run", native)
    spec = json.loads((run / "run.json").read_text())
    spec["splits"]["train"] = []
    (run / "run.json").write_text(json.dumps(spec))
    assert train_here(run) == EXIT_FAILED
    assert "splits.train is empty" in read_events(run)[-1]["reason"]
    spec["splits"]["train"] = ["no/such_sample"]
    (run / "run.json").write_text(json.dumps(spec))
    assert train_here(run) == EXIT_FAILED
    assert read_events(run)[-1]["reason"] == "ValueError: 1 sample(s) not in the data folder: no/such_sample"
