"""Runs end honestly: trainer checkpoints load with ``weights_only=True`` and resume bit
for bit from them; non-finite weights end a run ``diverged``; absurd values are refused before any
work; a cancelled run checkpoints the step it stopped at and resumes from it; a rank killed by a
signal is named; DDP logs no ``find_unused_parameters`` warning."""

from __future__ import annotations

import json
import math
import os
import signal
from pathlib import Path
from typing import Any

import pytest
import torch

from dataset.db import transaction
from dataset.services import training
from dataset.tables import JobState, RunState, TrainingRun
from model.losses import fusion_loss
from model.network import TRUNK_PREFIXES, FusionNetwork
from model.presets import load_preset
from model.runs.launcher import TRAINERS_FILE, death_reason, group_members
from model.train import CANCEL_FILE, EXIT_DIVERGED, EXIT_FAILED, EXIT_SUCCEEDED
from model.train.checkpoints import step_checkpoints, step_path
from model.train.events import read_events
from tests.runs_data import add_accepted_samples
from tests.test_runs import _queued_run
from tests.train_runs import events, make_run, parameters, split_names, train_here
from tests.waiting import until
from tests.workers import wait_for
from webapp.jobs import runs as run_control

TINY = {"train.steps": 4, "train.batch_size": 2, "train.crop": (32, 64), "train.train_iters": 2,
        "train.test_iters": 2, "train.val_every": 100_000, "train.checkpoint_every": 100_000, "train.amp": False}


@pytest.fixture
def weights_only(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every ``torch.load`` of this test with ``weights_only=True``, whatever its caller asks."""
    load = torch.load
    monkeypatch.setattr(torch, "load", lambda *a, **kw: load(*a, **{**kw, "weights_only": True}))


# --- the engine --------------------------------------------------------------------------------

def test_a_frozen_trunk_stays_where_it_started_while_the_heads_learn(native: Path, tmp_path: Path) -> None:
    """train.freeze_trunk: between two steps not one tensor of the mono context encoder or the stereo branch
    moves (nor a batch-norm statistic), while the VLM, confidence and fusion heads do; a stereo-only network,
    all trunk, is refused."""
    run = make_run(tmp_path / "run", native, val=False, steps=2, checkpoint_every=1, keep_last=5, freeze_trunk=True)
    assert train_here(run) == EXIT_SUCCEEDED
    first, second = parameters(run, 1), parameters(run, 2)
    trunk = [name for name in first if name.startswith(TRUNK_PREFIXES)]
    moved = {name for name in first if not torch.equal(first[name], second[name])}
    assert trunk and not moved & set(trunk)
    assert {name.split(".")[0] for name in moved} == {"vlm", "confidence", "fusion"}
    with pytest.raises(ValueError, match="freeze_trunk"):
        load_preset("lite", {"freeze_trunk": True, "use_vlm": False, "use_mono": False})


@pytest.mark.slow
def test_a_trainer_checkpoint_loads_weights_only_and_resumes_bit_for_bit(native: Path, tmp_path: Path,
                                                                          weights_only: None) -> None:
    run = make_run(tmp_path / "run", native, val=False, steps=3, checkpoint_every=1, keep_last=5)
    assert train_here(run) == EXIT_SUCCEEDED
    payload = torch.load(step_path(run, 2), map_location="cpu")  # weights_only=True (the fixture)
    extra = payload["extra"]
    assert {"optimizer", "scheduler", "scaler", "rng"} <= set(extra) and len(extra["rng"]) == 1
    assert isinstance(extra["rng"][0]["numpy"][1], torch.Tensor)
    expected = parameters(run, 3)
    step_path(run, 3).unlink()  # resume from step 2, and redo the last step
    assert train_here(run) == EXIT_SUCCEEDED
    assert events(run, "start")[-1]["resumed_from_step"] == 2
    done = parameters(run, 3)
    assert all(torch.equal(done[k], expected[k]) for k in expected)  # bit for bit on CPU


@pytest.mark.slow
def test_non_finite_weights_after_a_finite_loss_end_the_run_diverged(native: Path, tmp_path: Path,
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    # A backward pass that yields a NaN gradient while its loss is finite (Adam cannot overflow a
    # weight with a learning rate float32 can hold): the update makes that weight NaN.
    clip = torch.nn.utils.clip_grad_norm_

    def nan_gradient(params, *args, **kwargs):  # type: ignore[no-untyped-def]
        params = list(params)
        params[0].grad.fill_(math.nan)
        return clip(params, *args, **kwargs)

    monkeypatch.setattr(torch.nn.utils, "clip_grad_norm_", nan_gradient)
    run = make_run(tmp_path / "run", native, val=False, steps=1)
    assert train_here(run) == EXIT_DIVERGED
    end = read_events(run)[-1]
    assert end == {**end, "event": "end", "state": "diverged", "step": 0, "reason": "non-finite weights after step 1"}
    assert step_checkpoints(run) == []  # nothing non-finite is kept


@pytest.mark.slow
def test_a_run_whose_predictions_are_not_finite_ends_diverged_not_succeeded(native: Path, tmp_path: Path) -> None:
    # lr 1e9: one step leaves huge but finite weights whose every prediction is NaN.
    run = make_run(tmp_path / "run", native, steps=1, lr=1e9)
    n_val = len(split_names(native)["val"])
    assert train_here(run) == EXIT_DIVERGED
    end = read_events(run)[-1]
    assert end["event"] == "end" and end["state"] == "diverged" and end["step"] == 1
    assert end["reason"] == f"non-finite predictions on {n_val} validation sample(s) after step 1"
    assert step_checkpoints(run) == []  # nothing non-finite is kept


@pytest.mark.parametrize(("override", "field"), [({"steps": 10**20}, "train.steps"),
                                                  ({"checkpoint_every": 2**40}, "train.checkpoint_every"),
                                                  ({"lr": float("nan")}, "train.lr"),
                                                  ({"lr": -1.0}, "train.lr"),
                                                  ({"seed": 10**30}, "train.seed")])
def test_absurd_values_are_refused_before_any_work(native: Path, tmp_path: Path, override: dict[str, Any],
                                                   field: str) -> None:
    run = make_run(tmp_path / "run", native, val=False)
    spec = json.loads((run / "run.json").read_text())
    spec["config"]["train"].update(override)
    (run / "run.json").write_text(json.dumps(spec))
    assert train_here(run) == EXIT_FAILED
    log = read_events(run)
    assert [e["event"] for e in log] == ["end"] and field in log[0]["reason"]


@pytest.mark.slow
def test_the_cancel_flag_stops_at_a_step_with_its_checkpoint(native: Path, tmp_path: Path) -> None:
    run = make_run(tmp_path / "run", native, val=False, steps=50, checkpoint_every=1000)
    (run / CANCEL_FILE).write_text("cancel\n")
    assert train_here(run) == EXIT_SUCCEEDED  # torchrun takes any other status for a crash
    assert read_events(run)[-1] | {"time": 0} == {"event": "end", "state": "cancelled", "time": 0,
                                                 "reason": "cancelled at step 1", "step": 1}
    assert [s for s, _ in step_checkpoints(run)] == [1]


def _backbones(root: Path) -> dict[str, Any]:
    """The paper preset's tiny real backbones (as tests/test_model_paper.py builds them)."""
    pytest.importorskip("transformers")
    pytest.importorskip("peft")
    from tests.test_depth_backends import _save_tiny
    from tests.test_model_paper import TINY as PAPER_TINY
    from tests.test_vlm_transformers import save_tiny_qwen2_vl

    return {**PAPER_TINY, "mono_model_path": str(_save_tiny(root / "da")),
            "vlm_model_path": str(save_tiny_qwen2_vl(root / "qwen"))}


@pytest.mark.slow
@pytest.mark.parametrize(("preset", "overrides"), [("lite", {}), ("lite", {"use_vlm": False}), ("paper", {}),
                                                   ("paper", {"use_vlm": False}),
                                                   ("lite", {"use_vlm": False, "use_mono": False})])
def test_every_trainable_parameter_gets_a_gradient(tmp_path: Path, preset: str, overrides: dict[str, Any]) -> None:
    # What DDP's find_unused_parameters=False relies on (model/train/loop.py).
    backbones = _backbones(tmp_path) if preset == "paper" else {}
    config = load_preset(preset, {**backbones, **overrides, "crop": [64, 96]})
    torch.manual_seed(0)
    network = FusionNetwork(config.model).train()
    left = torch.rand(1, 3, 64, 96) * 255
    mono = None if preset == "paper" else torch.rand(1, 1, 64, 96)  # paper computes its own
    out = network(left, torch.roll(left, -2, dims=3), mono, iters=2, noise=torch.Generator().manual_seed(0))
    gt = torch.full((1, 1, 64, 96), 2.0)
    loss, _ = fusion_loss(out, gt, torch.ones_like(gt, dtype=torch.bool), config.train)
    loss.backward()
    trainable = [name for name, p in network.named_parameters() if p.requires_grad]
    assert trainable and [name for name, p in network.named_parameters() if p.requires_grad and p.grad is None] == []


SUMMARY = """torch.distributed.elastic.multiprocessing.errors.ChildFailedError:
=======================================================
model.train FAILED
-------------------------------------------------------
Failures:
[1]:
  time      : 2026-12-02_07:08:31
  host      : localhost
  rank      : 0 (local_rank: 0)
  exitcode  : -15 (pid: 13698)  (SIGTERM)
  error_file: <N/A>
  traceback : Signal 15 (SIGTERM) received by PID 13698
-------------------------------------------------------
Root Cause (first observed failure):
[0]:
  time      : 2026-12-02_07:08:31
  host      : localhost
  rank      : {rank} (local_rank: 1)
  exitcode  : {code} (pid: 13699)  (SIGKILL)
  error_file: <N/A>
  traceback : Signal 9 (SIGKILL) received by PID 13699
======================================================="""


def test_death_reason_reads_torchrun_s_failure_summary() -> None:
    # torchrun's own summary: the root cause first; the SIGTERM it sent the other ranks is no cause.
    assert death_reason(1, SUMMARY.format(rank=1, code=-9).splitlines()) == \
        "rank 1 was killed by SIGKILL — out of memory?"
    assert death_reason(1, SUMMARY.format(rank=1, code=1).splitlines()) is None
    assert death_reason(1, SUMMARY.format(rank=3, code=-11).splitlines()) == "rank 3 was killed by SIGSEGV"
    assert death_reason(-9, []) == "torchrun was killed by SIGKILL — out of memory?"
    assert death_reason(0, ["step 4/4"]) is None


@pytest.mark.parametrize(("end", "code", "killed", "state", "reason"), [
    (None, 1, "rank 0 was killed by SIGKILL — out of memory?", RunState.failed,
     "rank 0 was killed by SIGKILL — out of memory?"),
    ({"event": "end", "state": "failed", "reason": "ValueError: bad data", "step": 2}, 1, "rank 1 was killed by SIGSEGV",
     RunState.failed, "ValueError: bad data"),  # the engine's own reason comes first
    ({"event": "end", "state": "cancelled", "reason": "cancelled at step 3", "step": 3}, 0, None, RunState.cancelled,
     "cancelled at step 3"),
])
def test_finish_run_names_the_signal_and_the_cancel_step(runtime, samples, end, code, killed, state, reason) -> None:  # type: ignore[no-untyped-def]
    run_id = _queued_run(runtime)
    with transaction(runtime.sessions) as s:
        run = s.get(TrainingRun, run_id)
        assert training.finish_run(run, end, code, killed) == state and run.reason == reason


# --- through the train job -----------------------------------------------------------------------

def _launch(rt, nproc: int = 1, **overrides: Any) -> tuple[int, int, Path]:  # type: ignore[no-untyped-def]
    with transaction(rt.sessions) as s:
        add_accepted_samples(s, rt.media, videos=3)
        run = run_control.launch(rt, s, preset="lite", overrides={**TINY, **overrides},
                                 selection=training.DataSelection(),
                                 launch=training.Launch(split=training.parse_split(training.DEFAULT_SPLIT),
                                                        devices="cpu", nproc=nproc), user=None)
        return run.id, run.job_id, training.run_dir(rt.settings.runs_dir, run.id)


def _run(rt, run_id: int) -> dict[str, Any]:  # type: ignore[no-untyped-def]
    with rt.sessions() as s:
        return training.run_json(s.get(TrainingRun, run_id), rt.settings.runs_dir)


def _ranks(directory: Path) -> tuple[int, list[int]]:
    """The recorded process group and its ranks (the members but torchrun, the group's leader)."""
    pgid = json.loads((directory / TRAINERS_FILE).read_text())["pgid"]
    return pgid, [pid for pid in group_members(pgid) if pid != pgid]


@pytest.mark.slow
@pytest.mark.parametrize("queue_settings", ["sqlite"], indirect=True)
def test_cancel_checkpoints_the_step_it_stopped_at_and_resume_goes_on_from_there(rt, start_worker) -> None:  # type: ignore[no-untyped-def]
    start_worker("--queue", "train")
    # Two ranks, no checkpoint before step 100000: only the cancel's checkpoint can exist.
    run_id, job_id, directory = _launch(rt, nproc=2, **{"train.steps": 100_000})
    until(lambda: events(directory, "step"), 120, "the first step")
    pgid, _ = _ranks(directory)
    run_control.cancel(rt, run_id, None)
    job = wait_for(rt, job_id, lambda j: j.state.finished, 60)
    data = _run(rt, run_id)
    end = events(directory, "end")[-1]
    stopped = end["step"]
    assert data["state"] == "cancelled" and end["state"] == "cancelled" and stopped >= 1
    assert data["reason"] == f"cancelled by the command line at step {stopped}"
    assert [s for s, _ in step_checkpoints(directory)] == [stopped]
    assert data["checkpoint"] is not None and data["checkpoint"].endswith(f"step_{stopped:07d}.pt")
    assert group_members(pgid) == [] and not (directory / TRAINERS_FILE).exists()
    # The trainers stopped by themselves: no signal, no torch traceback in the log, no DDP warning.
    assert "ChildFailedError" not in job.log and "SIGTERM" not in job.log
    assert "find_unused_parameters" not in job.log
    rank_logs = [p.read_text() for p in (directory / "logs").rglob("*.log")]
    assert rank_logs and not any("Traceback" in log or "find_unused_parameters" in log for log in rank_logs)

    run_control.resume(rt, run_id, None)
    until(lambda: len(events(directory, "start")) == 2, 120, "the resumed start")
    assert events(directory, "start")[-1]["resumed_from_step"] == stopped
    until(lambda: _run(rt, run_id)["resumed_from_step"] == stopped, 30, "the mirrored resume")
    run_control.cancel(rt, run_id, None)
    wait_for(rt, job_id, lambda j: j.state.finished and j.attempts == 2, 60)
    assert _run(rt, run_id)["state"] == "cancelled"
    assert events(directory, "end")[-1]["step"] > stopped


@pytest.mark.slow
@pytest.mark.parametrize("queue_settings", ["sqlite"], indirect=True)
def test_a_rank_killed_by_sigkill_is_named_in_the_reason(rt, start_worker) -> None:  # type: ignore[no-untyped-def]
    start_worker("--queue", "train")
    run_id, job_id, directory = _launch(rt, **{"train.steps": 100_000})
    until(lambda: events(directory, "step"), 120, "the first step")
    pgid, ranks = _ranks(directory)
    assert len(ranks) == 1, (group_members(pgid), pgid, wait_for(rt, job_id, lambda j: True).log[-3000:])
    os.kill(ranks[0], signal.SIGKILL)  # what the kernel's OOM killer does
    job = wait_for(rt, job_id, lambda j: j.state.finished, 60)
    assert job.state == JobState.failed
    data = _run(rt, run_id)
    assert data["state"] == "failed" and data["reason"] == "rank 0 was killed by SIGKILL — out of memory?"
    assert "killed by SIGKILL" in job.error
    assert group_members(pgid) == []
