"""`illusion-studio train …` and `illusion-studio runs …`: launch, follow and manage training runs."""

from __future__ import annotations

import json
import shlex
import time
from pathlib import Path
from typing import Any

import click

from dataset.db import transaction
from dataset.services import training
from dataset.tables import IllusionType
from model.presets import ALL_PRESETS, load_preset
from model.runs import registry
from model.runs.launcher import engine_options
from model.runs.schema import MIN_LR, RunLaunch, backbone_dirs, validate
from webapp.cli.errors import service_errors
from webapp.cli.state import CliState, pass_state
from webapp.jobs import runs as run_control

NO_WORKER_HINT_S = 15.0


class WholeNumber(click.ParamType):
    """A whole number of at least 1, also written like ``2e3``; its upper bound is the launch schema's,
    so ``--steps 1e12`` is told the schema's limit rather than that it is no integer."""

    name = "whole number"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> int:
        if isinstance(value, int):
            number = float(value)
        else:
            try:
                number = float(str(value).strip())
            except ValueError:
                self.fail(f"{value!r} is not a whole number", param, ctx)
        if not number.is_integer() or number < 1:
            self.fail(f"{value!r} is not a whole number of at least 1", param, ctx)
        return int(number)


WHOLE = WholeNumber()


@click.command()
@click.option("--preset", default="lite", show_default=True, type=click.Choice(ALL_PRESETS),
              help="A fusion preset, or raft-stereo: RAFT-Stereo's own network, the stereo-only baseline.")
@click.option("--steps", type=WHOLE, help="Training steps (preset's by default).")
@click.option("--batch", type=WHOLE, help="Global batch size.")
@click.option("--lr", type=click.FloatRange(min=MIN_LR), help="Peak learning rate (OneCycle).")
@click.option("--crop", help="Random crop HxW in pixels, e.g. 320x736.")
@click.option("--iters", type=WHOLE, help="GRU iterations in training.")
@click.option("--devices", default="auto", show_default=True, help="auto, cpu, cuda, or cuda:0,1 (GPUs to use).")
@click.option("--nproc", default=1, show_default=True, type=click.IntRange(1),
              help="Trainer processes on this machine (DDP: gloo on CPU, NCCL on CUDA).")
@click.option("--nnodes", default=1, show_default=True, type=click.IntRange(1, 1024),
              help="Machines in the run; the others join with torchrun (see docs/training.md).")
@click.option("--rdzv-endpoint", help="HOST:PORT of the c10d rendezvous, for --nnodes > 1.")
@click.option("--video", "video_ids", multiple=True, type=int, help="Only samples of this video id (repeatable).")
@click.option("--illusion-type", "illusion_types", multiple=True, type=click.Choice([t.value for t in IllusionType]),
              help="Only samples of videos showing this illusion type (repeatable).")
@click.option("--kind", "kinds", multiple=True, type=click.Choice(training.SAMPLE_KINDS),
              help="Synthesized (web, generated) or capture (real stereo + LiDAR) samples (repeatable).")
@click.option("--qa-ok", is_flag=True, help="Only samples without QA flags.")
@click.option("--data", "data_root", type=click.Path(file_okay=False, path_type=Path),
              help="Train on a dataset folder instead of the database (needs --format).")
@click.option("--format", "data_format", default=None, help="Folder format: native, authors, sceneflow, …")
@click.option("--split", default=training.DEFAULT_SPLIT, show_default=True,
              help="Fractions of videos in train/val/test; no video is in two splits.")
@click.option("--seed", default=0, show_default=True, type=click.IntRange(0), help="Split, init and data-order seed.")
@click.option("--init", "init_checkpoint", metavar="CHECKPOINT",
              help="Start from this checkpoint's weights (fine-tuning; not a resume): RUN:NAME, imported:NAME or a file.")
@click.option("--init-stereo", metavar="imported:NAME",
              help="Start a fusion preset's stereo branch from an imported RAFT-Stereo checkpoint (the tensors that fit).")
@click.option("--wait", is_flag=True, help="Wait for the run to end; exit non-zero unless it succeeds.")
@click.option("--json", "as_json", is_flag=True, help="Print the run as one JSON object.")
@pass_state
def train(state: CliState, preset: str, steps: int | None, batch: int | None, lr: float | None, crop: str | None,
          iters: int | None, devices: str, nproc: int, nnodes: int, rdzv_endpoint: str | None,
          video_ids: tuple[int, ...], illusion_types: tuple[str, ...], kinds: tuple[str, ...], qa_ok: bool,
          data_root: Path | None, data_format: str | None, split: str, seed: int, init_checkpoint: str | None,
          init_stereo: str | None, wait: bool, as_json: bool) -> None:
    """Train the fusion model on accepted samples (or a dataset folder) as a job on the train queue."""
    rt = state.runtime
    if data_root is not None and data_format is None:
        raise click.ClickException("--data needs --format (native, authors, sceneflow, …)")
    body = {"preset": preset, "steps": steps, "batch": batch, "lr": lr, "crop": crop, "iters": iters,
            "nproc": nproc, "devices": devices, "split": split, "seed": seed, "video_ids": list(video_ids),
            "illusion_types": list(illusion_types), "kinds": list(kinds), "qa_ok": qa_ok, "init_stereo": init_stereo}
    # A name goes through the schema as the web's does; a file's path only the command line may give.
    named = init_checkpoint is not None and registry.is_name(init_checkpoint)
    body["init"] = init_checkpoint if named else None
    init_path = Path(init_checkpoint) if init_checkpoint is not None and not named else None
    if init_path is not None and not init_path.is_file():
        raise click.BadParameter(f"{init_checkpoint} is no file (nor RUN:NAME or imported:NAME)", param_hint="--init")
    shell = run_control.ShellOptions(data_dir=data_root, data_format=data_format, init_path=init_path,
                                     nnodes=nnodes, rdzv_endpoint=rdzv_endpoint)
    with service_errors():
        request = validate(RunLaunch, {k: v for k, v in body.items() if v is not None}, state.settings)
        with transaction(rt.sessions) as s:
            run = run_control.launch_request(rt, s, request, None, shell)
            run_id, job_id = run.id, run.job_id
    click.echo(f"run {run_id}: job {job_id} on the train queue "
               f"(`illusion-studio --data-dir {state.settings.home} worker --queue train` runs it)", err=True)
    if nnodes > 1:
        click.echo("on each other node, once this one runs it:\n  " + other_node_command(
            training.run_dir(state.settings.runs_dir, run_id), nproc, nnodes, rdzv_endpoint or "",
            backbone_dirs(load_preset(preset), state.settings)), err=True)
    data = _wait(state, run_id) if wait else run_summary(state, run_id)
    print_run(data, as_json)
    if wait and data["state"] != "succeeded":
        raise click.ClickException(f"run {run_id} {data['state']}: {data['reason']}")


def other_node_command(directory: Path, nproc: int, nnodes: int, endpoint: str, backbones: dict[str, str]) -> str:
    """What the other machines of a multi-node run start (the run directory on shared storage;
    ``backbones``: the frozen backbones' directories, as this machine's settings name them)."""
    return shlex.join(["python", "-m", "torch.distributed.run", "--nnodes", str(nnodes), "--nproc-per-node", str(nproc),
                       "--rdzv-backend", "c10d", "--rdzv-endpoint", endpoint, "--rdzv-id", f"run-{directory.name}",
                       "-m", "model.train", str(directory), *engine_options(backbones)])


def run_summary(state: CliState, run_id: int, *, full: bool = False) -> dict[str, Any]:
    rt = state.runtime
    with service_errors(), rt.sessions() as s:
        return training.run_json(training.get_run(s, run_id), rt.settings.runs_dir,
                                 current=registry.current_model(rt.settings), full=full)


def _wait(state: CliState, run_id: int) -> dict[str, Any]:
    """Follow the run on stderr until it ends."""
    started, hinted, shown = time.monotonic(), False, None
    while True:
        data = run_summary(state, run_id)
        line = f"run {run_id}: {data['state']} step {data['step']}/{data['steps']}" + (
            f" loss {data['loss']:.4g}" if data["loss"] is not None else "")
        if line != shown:
            click.echo(line, err=True)
            shown = line
        if data["state"] not in ("queued", "running"):
            return data
        if not hinted and data["state"] == "queued" and time.monotonic() - started > NO_WORKER_HINT_S:
            click.echo(f"still queued after {NO_WORKER_HINT_S:.0f} s: is a train worker running? "
                       f"(`illusion-studio --data-dir {state.settings.home} worker --queue train`)", err=True)
            hinted = True
        time.sleep(0.5)


def print_run(data: dict[str, Any], as_json: bool) -> None:
    if as_json:
        click.echo(json.dumps(data, indent=2))
        return
    epe = f"{data['best_val_epe']:.3f}" if data["best_val_epe"] is not None else "—"
    click.echo(f"run {data['run']} {data['state']} step {data['step']}/{data['steps']} best val EPE {epe} "
               f"checkpoint {data['checkpoint'] or '—'}")
