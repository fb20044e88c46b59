"""The ``illusion-studio`` command line: one click group, a module per topic."""

from __future__ import annotations

from importlib import import_module
from pathlib import Path

import click

from dataset.settings import HOME_ENV

# name: (module, attribute, summary). Subcommands load on first use, so that `--help` and a command's
# own start import only what that command needs (torch, the database layer and the benchmarks are
# seconds). The summaries are the commands' own first sentences, checked by tests/test_cli.py.
COMMANDS: dict[str, tuple[str, str, str]] = {
    "init": ("webapp.cli.workspace", "init", "Create (or upgrade) the workspace: directories, database schema, secret key."),
    "serve": ("webapp.cli.workspace", "serve", "Run the web app with cheroot."),
    "worker": ("webapp.cli.jobs", "worker", "Run jobs from the queue until interrupted (Ctrl-C)."),
    "demo": ("webapp.cli.demo", "demo", "A ready-to-click workspace (default ./var/demo): synthetic videos, one user per "
                                        "role, workers and server."),
    "synth": ("webapp.cli.workspace", "synth", "Render synthetic illusion videos (picture + mirror, with exact ground "
                                               "truth) into OUT_DIR."),
    "ingest": ("webapp.cli.ingest", "ingest", "Queue video files, folders of videos, or synthetic scenes for ingest (a "
                                              "worker decodes them)."),
    "prefilter": ("webapp.cli.ingest", "prefilter", "Ask the VLM the paper's 12 questions about every ingested frame; "
                                                    "survivors go to curators."),
    "frames": ("webapp.cli.ingest", "frames", "Query frames."),
    "users": ("webapp.cli.users", "users", "Manage users and API tokens."),
    "jobs": ("webapp.cli.jobs", "jobs", "Inspect and retry jobs."),
    "geometry": ("webapp.cli.geometry", "geometry", "Plane rectification, right-view synthesis and depth reprojection on "
                                                    "files."),
    "bench": ("webapp.cli.bench", "bench", "Speed benchmarks, each on scratch workspaces of its own."),
    "selftest": ("webapp.cli.selftest", "selftest", "Rectify fooled disparities, synthesize right views and check them "
                                                    "against the exact truth."),
    "import-capture": ("webapp.cli.capture", "import_capture", "Import a stereo + depth-sensor capture FOLDER (left/, "
                       "right/, depth/, optional mask/ with files matched by stem) as a real-capture video whose frames "
                       "come with ground-truth disparity."),
    "import-reconstruction": ("webapp.cli.capture", "import_reconstruction", "Attach an external reconstruction in FOLDER "
                              "(disparity/*.pfm|npy in pixels, right/*.png rendered right views) to the frames of video "
                              "VIDEO_ID."),
    "export": ("webapp.cli.export", "export_cmd", "Export samples into the new folder OUT (written aside and renamed into "
                                                  "place when complete)."),
    "import": ("webapp.cli.export", "import_cmd", "Import the dataset folder PATH: checked completely first, then whatever "
                                                  "is missing is added (importing again adds nothing)."),
    "train": ("webapp.cli.train", "train", "Train the fusion model on accepted samples (or a dataset folder) as a job on the "
                                           "train queue."),
    "runs": ("webapp.cli.runs", "runs", "List, inspect, cancel, resume and promote training runs."),
    "checkpoints": ("webapp.cli.runs", "checkpoints", "Fusion-model checkpoint files."),
    "predict": ("webapp.cli.model", "predict", "Disparity of the LEFT/RIGHT rectified pair (fused, or a stereo-only "
                "network's such as an imported RAFT-Stereo); extra outputs go beside --out as <stem>_<output>.pfm."),
    "depth": ("webapp.cli.depth", "depth", "Relative disparity (inverse depth, up to scale and shift) of IMAGE from a "
                                           "Depth Anything V2 model; an imported original file runs as the original "
                                           "code's infer_image(image, 518)."),
    "evaluate": ("webapp.cli.evaluate", "evaluate_cmd", "Evaluate METHODs: EPE and bad-x (and depth metrics where a camera "
                                                        "is known) per region."),
    "table": ("webapp.cli.table", "table", "The paper's Table 1 (EPE, bad-x, depth metrics per region) for every method "
                                           "this workspace has, on a dataset folder."),
    "example-data": ("webapp.cli.examples", "example_data", "Write a small real dataset folder that needs no "
                     "download: motorcycle (Middlebury 2014's Motorcycle as scikit-image ships it, 741×500, with ground "
                     "truth and calibration; read it with --format middlebury)."),
    "media": ("webapp.cli.media", "media", "Media store housekeeping."),
}


class LazyGroup(click.Group):
    """A click group whose subcommands load on first use (click's documented pattern), listed in
    ``--help`` from :data:`COMMANDS`' summaries."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(COMMANDS)

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        if name not in COMMANDS:
            return None
        module, attribute, _ = COMMANDS[name]
        command: click.Command = getattr(import_module(module), attribute)
        if name == "checkpoints" and "import" not in getattr(command, "commands", {}):
            from webapp.cli.checkpoints import import_checkpoint  # the group lives with the runs commands

            command.add_command(import_checkpoint)  # type: ignore[attr-defined]
        return command

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        width = formatter.width - 6 - max(map(len, COMMANDS))
        rows = [(name, click.utils.make_default_short_help(COMMANDS[name][2], width)) for name in self.list_commands(ctx)]
        with formatter.section("Commands"):
            formatter.write_dl(rows)


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
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
    from webapp.cli.state import CliState

    ctx.obj = CliState(data_dir)
