"""``illusion-studio runs`` and ``checkpoints``: training runs and their checkpoint files, after launch.

The services load inside each command, so that ``runs --help`` imports no database layer or torch.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import click

from dataset.run_layout import CHECKPOINT_DIR
from webapp.cli.errors import service_errors
from webapp.cli.state import CliState, pass_state


@click.group()
def runs() -> None:
    """List, inspect, cancel, resume and promote training runs."""


@runs.command("list")
@click.option("--json", "as_json", is_flag=True, help="Print a JSON array.")
@pass_state
def list_runs(state: CliState, as_json: bool) -> None:
    """Every run: state, step, best validation EPE, dataset; the current model's marked."""
    from dataset.services import training
    from model.runs import registry

    rt = state.runtime
    current = registry.current_model(rt.settings)
    with rt.sessions() as s:
        rows = [registry.with_checkpoint_names(training.run_json(r, rt.settings.runs_dir, current=current))
                for r in training.list_runs(s)]
    if as_json:
        click.echo(json.dumps(rows, indent=2))
        return
    for r in rows:
        epe = f"{r['best_val_epe']:.3f}" if r["best_val_epe"] is not None else "—"
        click.echo(f"{r['run']:>5} {r['preset']:<6} {r['state']:<12} {r['step']:>7}/{r['steps']:<7} "
                   f"val EPE {epe:<8} data {r['dataset']['id'][:12]}{'  (current)' if r['current'] else ''}")


@runs.command("show")
@click.argument("run_id", type=int)
@click.option("--json", "as_json", is_flag=True, help="Print JSON (with config, dataset version and checkpoints).")
@pass_state
def show(state: CliState, run_id: int, as_json: bool) -> None:
    """One run: its state, progress, checkpoint, dataset version and why it ended."""
    from webapp.cli.train import print_run, run_summary

    data = run_summary(state, run_id, full=as_json)
    if as_json:
        click.echo(json.dumps(data, indent=2))
        return
    print_run(data, False)
    click.echo(f"  dataset {data['dataset']['id']}: {data['dataset']['kinds']}, splits {data['dataset']['splits']}")
    if data["reason"]:
        click.echo(f"  {data['reason']}")


@runs.command("cancel")
@click.argument("run_id", type=int)
@pass_state
def cancel(state: CliState, run_id: int) -> None:
    """Stop a queued or running run (its trainers' whole process group)."""
    from webapp.jobs import runs as run_control

    with service_errors():
        run_control.cancel(state.runtime, run_id, None)
    click.echo(f"run {run_id}: cancel requested")


@runs.command("resume")
@click.argument("run_id", type=int)
@pass_state
def resume(state: CliState, run_id: int) -> None:
    """Continue an interrupted, failed or cancelled run from its newest checkpoint."""
    from webapp.jobs import runs as run_control

    with service_errors():
        run_control.resume(state.runtime, run_id, None)
    click.echo(f"run {run_id}: queued again; it resumes from its newest checkpoint")


@runs.command("promote")
@click.argument("run_id", type=int)
@click.option("--checkpoint", "which", default="best", show_default=True,
              help="best, last, a file name of the run's checkpoints, or a checkpoint file's path (with a /).")
@pass_state
def promote(state: CliState, run_id: int, which: str) -> None:
    """Make a run's checkpoint the current model (what `predict` and evaluation use by default)."""
    from webapp.jobs import runs as run_control

    path = Path(which).expanduser() if "/" in which else None
    with service_errors():
        doc = run_control.promote(state.runtime, run_id, which, None, path=path)
    click.echo(json.dumps(doc), file=sys.stdout)


@click.group()
def checkpoints() -> None:
    """Fusion-model checkpoint files."""


@checkpoints.command("upgrade")
@click.argument("paths", nargs=-1, type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--all", "every", is_flag=True, help="Every checkpoint under <data dir>/runs.")
@pass_state
def upgrade(state: CliState, paths: tuple[Path, ...], every: bool) -> None:
    """Rewrite checkpoints of an earlier release (their trainer state held numpy objects) so that
    they load with weights-only loading, the only loading there is. Reading them allows numpy's
    arrays and nothing else: a file that needs more is reported and left alone."""
    from model.checkpoint import upgrade_checkpoint

    if every:
        paths = (*paths, *_run_checkpoint_files(state.settings.runs_dir))
    if not paths:
        raise click.UsageError("name checkpoint files, or --all for every run's")
    failed = 0
    for path in paths:
        if path.is_symlink():
            click.echo(f"{path}: a symbolic link, skipped")
            continue
        try:
            click.echo(f"{path}: {'upgraded' if upgrade_checkpoint(path) else 'already loads safely'}")
        except (ValueError, OSError) as exc:
            failed += 1
            click.echo(f"{path}: left alone: {exc}", err=True)
    if failed:
        raise click.ClickException(f"{failed} of {len(paths)} checkpoint(s) could not be upgraded (see above)")


def _run_checkpoint_files(runs_dir: Path) -> list[Path]:
    """``runs/<id>/checkpoints/*.pt``, never through a linked run or checkpoint folder."""
    runs = [run for run in runs_dir.iterdir() if not run.is_symlink()] if runs_dir.is_dir() else []
    return sorted(path for run in runs if not (run / CHECKPOINT_DIR).is_symlink()
                  for path in (run / CHECKPOINT_DIR).glob("*.pt"))
