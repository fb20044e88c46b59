"""`illusion-studio evaluate …`: the paper's tables for any methods on a dataset folder or on a
training run's held-out test split, as a job (queued, ``--wait`` or ``--here``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from dataset.readers import READER_FORMATS
from dataset.services.evaluations import dataset_label
from model.align import ALIGN_RULES
from model.evaluate import RESOLUTIONS
from model.methods import METHODS, method_key
from model.runs import registry
from model.runs.evaluation import DEFAULT_METHODS, EvalShellOptions, evaluation_params, report_dir
from model.runs.schema import EvaluationLaunch, validate
from webapp.cli.errors import service_errors
from webapp.cli.running import run_job, run_options
from webapp.cli.state import CliState, pass_state

METHOD_CHOICES = [m.replace("_", "-") for m in METHODS] + list(METHODS)


@click.command("evaluate")
@click.option("--data", type=click.Path(exists=True, file_okay=False, path_type=Path),
              help="A dataset folder; without it, the test split of --run (or of the checkpoint's run).")
@click.option("--format", "fmt", type=click.Choice(READER_FORMATS), help="The layout of --data.")
@click.option("--method", "methods", multiple=True, type=click.Choice(METHOD_CHOICES),
              help=f"Repeatable (default: {', '.join(m.replace('_', '-') for m in DEFAULT_METHODS)}).")
@click.option("--checkpoint", "checkpoints", multiple=True, metavar="[METHOD=]CHECKPOINT",
              help="RUN:NAME, imported:NAME or a file: the network methods' (default: the current model); "
                   "METHOD=… gives one method its own, e.g. raft-stereo=imported:raftstereo-sceneflow or "
                   "selective-raft=imported:sceneflow or selective-igev=imported:selective-igev-sceneflow or "
                   "mocha-stereo=imported:mocha-stereo. "
                   "Repeatable.")
@click.option("--run", "run_id", type=int, help="A training run whose test split to evaluate on.")
@click.option("--predictions", type=click.Path(exists=True, file_okay=False, path_type=Path),
              help="PFMs of another program: DIR/REL/x.pfm for left image REL/x.png (any resolution).")
@click.option("--mono", type=click.Path(exists=True, file_okay=False, path_type=Path),
              help="Monocular disparities as PFMs laid out like --predictions, for datasets that carry none.")
@click.option("--resolution", type=click.Choice(list(RESOLUTIONS)),
              help="Images and ground truth resized (disparity scaled); default full, quarter for booster.")
@click.option("--align", "align_rule", type=click.Choice(ALIGN_RULES), default="lsq", show_default=True,
              help="mono-gt-align: least squares, or the authors' median / mean-absolute-deviation.")
@click.option("--max-disparity", type=click.IntRange(min=1), help="sgbm's search range (default: a quarter of the width).")
@click.option("--iters", type=click.IntRange(min=1), help="GRU iterations (default: the checkpoint's test iterations).")
@click.option("--min-disparity", type=float, help="booster: ground truth below this is invalid (the authors' script: 1).")
@click.option("--kitti-png", is_flag=True, help="Also write predictions as KITTI uint16 PNGs (disparity × 256).")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path),
              help="Report folder (default: <data dir>/evaluations/<job id>; the web serves only those).")
@click.option("--json", "as_json", is_flag=True, help="Print the report as one JSON object (with --wait/--here).")
@run_options
@pass_state
def evaluate_cmd(state: CliState, data: Path | None, fmt: str | None, methods: tuple[str, ...],
                 checkpoints: tuple[str, ...], run_id: int | None, predictions: Path | None, mono: Path | None,
                 resolution: str | None, align_rule: str, max_disparity: int | None, iters: int | None,
                 min_disparity: float | None, kitti_png: bool, out: Path | None, as_json: bool,
                 wait: bool, here: bool) -> None:
    """Evaluate METHODs: EPE and bad-x (and depth metrics where a camera is known) per region."""
    if data is not None and fmt is None:
        raise click.UsageError("--data needs --format")
    rt = state.runtime
    body = {"methods": list(methods) or list(DEFAULT_METHODS), "run": run_id, "resolution": resolution,
            "align": align_rule, "max_disparity": max_disparity, "kitti_png": kitti_png, "iters": iters}
    named, files = _checkpoint_options(checkpoints)
    body.update(named)
    shell = EvalShellOptions(data_dir=data, data_format=fmt, checkpoint=files.pop("", None), checkpoints=files,
                             predictions=predictions,
                             mono=mono, out=out,
                             reader_options={"min_disparity": min_disparity} if min_disparity is not None else {})
    with service_errors(), rt.sessions() as s:
        request = validate(EvaluationLaunch, {k: v for k, v in body.items() if v is not None})
        params = evaluation_params(request, state.settings, s, shell)
        s.commit()
    job_id = run_job(state, "evaluate", params, f"evaluate {', '.join(params['methods'])} on {dataset_label(params)}",
                     wait=wait, here=here, quiet=as_json)
    if wait or here:
        out = report_dir(params, state.settings, job_id)
        if as_json:
            click.echo((out / "report.json").read_text())
        else:
            click.echo(f"report: {out / 'index.html'}")


def _checkpoint_options(values: tuple[str, ...]) -> tuple[dict[str, Any], dict[str, Path]]:
    """``--checkpoint`` values as the request's names (``checkpoint``, ``checkpoints``) and the
    command line's own files by method (``""``: the default one). UsageError for a method given twice
    or a path that is no file."""
    named: dict[str, Any] = {}
    files: dict[str, Path] = {}
    for value in values:
        method, _, text = value.rpartition("=") if "=" in value.split(":", 1)[0] else ("", "", value)
        try:
            key = method_key(method) if method else ""
        except ValueError as exc:
            raise click.UsageError(f"--checkpoint {value}: {exc}") from None
        if key in files or (key == "" and "checkpoint" in named) or key in named.get("checkpoints", {}):
            raise click.UsageError(f"--checkpoint gives {method or 'the default'} twice")
        if registry.is_name(text):
            if key:
                named.setdefault("checkpoints", {})[key] = text
            else:
                named["checkpoint"] = text
        elif Path(text).is_file():
            files[key] = Path(text)
        else:
            raise click.UsageError(f"--checkpoint {value}: {text} is no file, nor RUN:NAME or imported:NAME")
    return named, files
