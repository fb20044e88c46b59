"""The ``illusion-studio`` command line: one click group, a module per topic."""

from __future__ import annotations

from pathlib import Path

import click

from dataset.settings import HOME_ENV
from webapp.cli.bench import bench
from webapp.cli.capture import import_capture, import_reconstruction
from webapp.cli.checkpoints import import_checkpoint
from webapp.cli.demo import demo
from webapp.cli.evaluate import evaluate_cmd
from webapp.cli.export import export_cmd, import_cmd
from webapp.cli.geometry import geometry
from webapp.cli.ingest import frames, ingest, prefilter
from webapp.cli.jobs import jobs, worker
from webapp.cli.media import media
from webapp.cli.model import predict
from webapp.cli.selftest import selftest
from webapp.cli.state import CliState
from webapp.cli.train import checkpoints, runs, train
from webapp.cli.users import users
from webapp.cli.workspace import init, serve, synth


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.option(
    "--data-dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    # The same for every command: an unset --data-dir is $ILLUSION_STUDIO_HOME, here, once.
    envvar=HOME_ENV,
    help=f"Workspace directory (default: ${HOME_ENV}).",
)
@click.pass_context
def main(ctx: click.Context, data_dir: Path | None) -> None:
    """Illusion Studio: build stereo depth datasets of 3D visual illusions."""
    ctx.obj = CliState(data_dir)


for command in (init, serve, worker, demo, synth, ingest, prefilter, frames, users, jobs, geometry, bench, selftest,
                import_capture, import_reconstruction, export_cmd, import_cmd, train, runs, checkpoints, predict,
                evaluate_cmd, media):
    main.add_command(command)
checkpoints.add_command(import_checkpoint)  # the group lives with the runs commands
