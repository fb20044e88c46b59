"""`illusion-studio table --data DIR --format FMT`: the paper's Table 1 for every method this workspace
has — SGBM, the GT-aligned mono, the current model's three outputs and each imported stereo network —
each scored by an ``evaluate`` job run here, the table printed from their reports (model/runs/table.py)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click

from dataset.readers import READER_FORMATS
from model.evaluate import RESOLUTIONS
from model.methods import BASELINE_METHODS
from model.runs import registry
from model.runs.evaluation import EvalShellOptions, evaluation_params, report_dir
from model.runs.schema import EvaluationLaunch, validate
from model.runs.start_fit import imported_model
from model.runs.table import CURRENT, Round, format_table, plan_rounds, table_regions, table_rows
from webapp.cli.errors import service_errors
from webapp.cli.running import run_job
from webapp.cli.state import CliState, pass_state


@click.command("table")
@click.option("--data", required=True, type=click.Path(exists=True, file_okay=False, path_type=Path),
              help="A dataset folder, in any layout `evaluate` reads.")
@click.option("--format", "fmt", required=True, type=click.Choice(READER_FORMATS), help="The layout of --data.")
@click.option("--region", "regions", multiple=True,
              help="Regions to print, repeatable (default: every region of the data, `all` first).")
@click.option("--mono", type=click.Path(exists=True, file_okay=False, path_type=Path),
              help="Monocular disparities as PFMs (DIR/REL/x.pfm), for data that carries none.")
@click.option("--resolution", type=click.Choice(list(RESOLUTIONS)),
              help="Images and ground truth resized (disparity scaled); default full, quarter for booster.")
@click.option("--min-disparity", type=float, help="booster: ground truth below this is invalid (the authors' script: 1).")
@click.option("--markdown", is_flag=True, help="Markdown tables instead of aligned text.")
@click.option("--json", "as_json", is_flag=True, help="Print the rows as one JSON object.")
@pass_state
def table(state: CliState, data: Path, fmt: str, regions: tuple[str, ...], mono: Path | None,
          resolution: str | None, min_disparity: float | None, markdown: bool, as_json: bool) -> None:
    """The paper's Table 1 (EPE, bad-x, depth metrics per region) for every method this workspace has, on a
    dataset folder."""
    settings = state.settings
    home = Path(settings.home)
    imported = []
    for name in registry.imported_names(home):
        model = imported_model(registry.imported_path(home, name))
        key = model.architecture.replace("-", "_") if model is not None else None
        if key in BASELINE_METHODS:
            imported.append((f"{registry.IMPORTED}:{name}", key))
    with service_errors():
        current = registry.current_reference(settings)
    current_name = registry.checkpoint_name(*current) if current else ""
    evaluations = []
    for plan in plan_rounds(current is not None, imported):
        job_id, params = _evaluate(state, plan, data, fmt, mono, resolution, min_disparity)
        report = json.loads((report_dir(params, settings, job_id) / "report.json").read_text())
        evaluations.append((plan, report, current_name))
    rows = table_rows(evaluations)
    shown = table_regions(rows, regions)
    if as_json:
        click.echo(json.dumps({"regions": shown, "rows": [{"method": r.method, "title": r.title, "checkpoint": r.checkpoint,
                                                           "samples": r.samples, "missing": r.missing,
                                                           "regions": {k: r.regions[k] for k in shown if k in r.regions}}
                                                          for r in rows]}))
        return
    click.echo(format_table(rows, shown, markdown=markdown))
    if not current:
        click.echo("\n(no current model: promote a run's checkpoint to add ours; `checkpoints import` adds "
                   "published stereo networks)", err=True)


def _evaluate(state: CliState, plan: Round, data: Path, fmt: str, mono: Path | None, resolution: str | None,
              min_disparity: float | None) -> tuple[int, dict[str, Any]]:
    """Run one round's evaluation here, its progress on stderr (stdout is the table's); (job id, params)."""
    body: dict[str, Any] = {"methods": list(plan.methods),
                            "checkpoints": {m: name for m, name in plan.checkpoints.items() if name != CURRENT}}
    if resolution is not None:
        body["resolution"] = resolution
    shell = EvalShellOptions(data_dir=data, data_format=fmt, mono=mono,
                             reader_options={"min_disparity": min_disparity} if min_disparity is not None else {})
    with service_errors(), state.runtime.sessions() as s:
        params = evaluation_params(validate(EvaluationLaunch, body), state.settings, s, shell)
        s.commit()
    what = f"table: {', '.join(m.replace('_', '-') for m in plan.methods)} on {data.name}"
    return run_job(state, "evaluate", params, what, wait=False, here=True, quiet=True), params
