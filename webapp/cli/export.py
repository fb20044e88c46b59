"""`illusion-studio export …` and `illusion-studio import …`: dataset folders in and out, as jobs
(queued, ``--wait`` or ``--here``: see :mod:`webapp.cli.running`)."""

from __future__ import annotations

from pathlib import Path

import click

from dataset.export import FORMATS, LayoutError, export_params, import_params
from dataset.export.authors_layout import MASK_FORMATS
from dataset.export.selection import DEFAULT_STATES
from dataset.export.splits import DEFAULT_SPLIT
from dataset.export.staging import check_target
from dataset.services.errors import FieldError
from dataset.services.exports import check_selection
from dataset.tables import SampleState
from webapp.cli.errors import service_errors
from webapp.cli.running import run_job, run_options
from webapp.cli.state import CliState, pass_state


@click.command("export")
@click.argument("out", type=click.Path(file_okay=False, path_type=Path))
@click.option("--format", "fmt", type=click.Choice(FORMATS), required=True,
              help="native: PNG/PFM + manifest + COCO (NATIVE_FORMAT.md); authors: the paper's released layout.")
@click.option("--split", default=DEFAULT_SPLIT, show_default=True,
              help="native: NAME=FRACTION,… e.g. train=0.8,test=0.2; whole videos go to one split.")
@click.option("--seed", default=0, show_default=True, type=int, help="Seed of the split by video.")
@click.option("--state", "states", multiple=True, type=click.Choice([s.value for s in SampleState]),
              help=f"Sample states to export (repeatable; default: {', '.join(DEFAULT_STATES)}).")
@click.option("--video", "video_ids", multiple=True, type=int, help="Only these video ids (repeatable).")
@click.option("--masks", "mask_format", type=click.Choice(MASK_FORMATS), default="png", show_default=True,
              help="authors: mask files as lossless PNG, or JPEG as the authors' tools wrote them.")
@click.option("--overwrite", is_flag=True, help="Replace OUT if it is a non-empty folder (swapped in at the end).")
@run_options
@pass_state
def export_cmd(state: CliState, out: Path, fmt: str, split: str, seed: int, states: tuple[str, ...],
               video_ids: tuple[int, ...], mask_format: str, overwrite: bool, wait: bool, here: bool) -> None:
    """Export samples into the new folder OUT (written aside and renamed into place when complete)."""
    with service_errors():
        try:
            check_target(out.absolute(), overwrite=overwrite)
        except LayoutError as exc:
            # The check's words serve the web too; on the command line the way out has a flag's name.
            raise LayoutError(str(exc) if overwrite else f"{exc} (--overwrite)") from None
        params = export_params(out, format=fmt, split=split, seed=seed, states=states or DEFAULT_STATES,
                               video_ids=video_ids, overwrite=overwrite, mask_format=mask_format)
        # Refused here rather than as a failed job: videos that do not exist, a selection of no sample.
        with state.runtime.sessions() as session:
            try:
                check_selection(session, params["states"], params["video_ids"])
            except FieldError as exc:  # its field is the form's; here the option's
                raise click.ClickException(f"--video: {exc.reason}" if exc.field else exc.reason) from None
    run_job(state, "export", params, f"export {fmt} → {params['out']}", wait=wait, here=here)


@click.command("import")
@click.argument("path", type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option("--format", "fmt", type=click.Choice(FORMATS), required=True,
              help="native: a folder made by `export --format native`; authors: the paper's released layout.")
@run_options
@pass_state
def import_cmd(state: CliState, path: Path, fmt: str, wait: bool, here: bool) -> None:
    """Import the dataset folder PATH: checked completely first, then whatever is missing is added
    (importing again adds nothing)."""
    with service_errors():
        params = import_params(path, format=fmt)
    run_job(state, "import", params, f"import {fmt} ← {params['path']}", wait=wait, here=here)
