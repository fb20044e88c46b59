"""`init`, `serve` and `synth`: set up a workspace and run the app (`demo` is in :mod:`webapp.cli.demo`)."""

from __future__ import annotations

import logging
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import click

from core.wording import plural
from dataset.db import migrate
from dataset.settings import Settings, SettingsError, load_settings
from webapp.cli.state import CliState, pass_state
from webapp.runtime import Runtime

if TYPE_CHECKING:
    from webapp.server import Server


def init_workspace(data_dir: Path | None) -> Settings:
    """Create the data dir (if needed) and bring its database to the newest schema."""
    try:
        settings = load_settings(data_dir, must_exist=False)
    except SettingsError as exc:
        raise click.ClickException(str(exc)) from None
    for path in (settings.home, settings.media_root, settings.cache_dir):
        path.mkdir(parents=True, exist_ok=True)
    migrate(settings.database_url)
    return settings


@click.command()
@pass_state
def init(state: CliState) -> None:
    """Create (or upgrade) the workspace: directories, database schema, secret key."""
    settings = init_workspace(state.data_dir)
    click.echo(f"workspace ready at {settings.home} (database {_redact(settings.database_url)})")


def _redact(url: str) -> str:
    from sqlalchemy.engine import make_url

    return make_url(url).render_as_string(hide_password=True)


@click.command()
@click.option("--host", default=None, help="Bind address (default from settings: 127.0.0.1).")
@click.option("--port", default=None, type=int, help="Port (default from settings: 5000).")
@click.option("--threads", default=8, show_default=True, type=click.IntRange(1, 128))
@pass_state
def serve(state: CliState, host: str | None, port: int | None, threads: int) -> None:
    """Run the web app with cheroot."""
    _serve(state, host, port, threads)


def _serve(state: CliState, host: str | None, port: int | None, threads: int) -> None:
    server = make_server(state.settings, state.runtime, host, port, threads)
    click.echo(f"Illusion Studio at {server_url(server)}  (Ctrl-C to stop)", err=True)
    server.run()


def make_server(settings: Settings, rt: Runtime, host: str | None, port: int | None, threads: int) -> Server:
    """The app's server, listening on ``host:port`` (default: the settings'; port 0: any free one);
    connections wait in the backlog until ``run()``; ``close()`` stops it."""
    from webapp.admission import make_admission
    from webapp.app import create_app
    from webapp.server import Server

    logging.basicConfig()  # the app's modules report through logging
    app = create_app(settings, rt, threads=threads)  # slowed logins may hold at most half of these threads
    return Server(app, host or settings.host, settings.port if port is None else port, threads,
                  admit=make_admission(app, settings, rt))


def server_url(server: Server) -> str:
    host = server.effective_host
    return f"http://[{host}]:{server.effective_port}/" if ":" in host else f"http://{host}:{server.effective_port}/"


@click.command()
@click.argument("out_dir", type=click.Path(file_okay=False, path_type=Path))
@click.option("--videos", default=3, show_default=True, type=click.IntRange(1, 1000))
@click.option("--seed", default=0, show_default=True, type=int)
@click.option("--frames", "n_frames", default=12, show_default=True, type=click.IntRange(1, 10_000))
@click.option("--size", default="640x360", show_default=True, help="WIDTHxHEIGHT in pixels.")
@click.option("--families", is_flag=True, help="The scene families of the fusion benchmark: frames of one distribution "
                                                "for every kind, large and wall-sized mirrors, weak walls, mixed estimators.")
@click.option("--baseline-m", type=click.FloatRange(0.01, 5.0), default=None,
              help="Stereo baseline in metres (default 0.1; the fusion benchmark's held-out scenes: 0.63).")
def synth(out_dir: Path, videos: int, seed: int, n_frames: int, size: str, families: bool, baseline_m: float | None) -> None:
    """Render synthetic illusion videos (picture + mirror, with exact ground truth) into OUT_DIR."""
    from dataset.synthetic import write_synthetic_dataset

    width, height = _parse_size(size)
    with click.progressbar(length=videos, label="rendering", file=sys.stderr) as bar:
        paths = []
        for k in range(videos):
            paths += write_synthetic_dataset(out_dir, videos=1, seed=seed + k, n_frames=n_frames, width=width,
                                             height=height, families=families,
                                             **({"baseline_m": baseline_m} if baseline_m is not None else {}))
            bar.update(1)
    for path in paths:
        click.echo(str(path))
    # stdout lists the folders, one a line, for scripts; the summary is for the person
    seeds = f"seed {seed}" if videos == 1 else f"seeds {seed}–{seed + videos - 1}"
    click.echo(f"made {plural(videos, 'video')}, {plural(videos * n_frames, 'frame')}, {width}×{height}, {seeds} "
               f"in {out_dir}", err=True)


def _parse_size(size: str) -> tuple[int, int]:
    try:
        width, height = (int(v) for v in size.lower().split("x"))
    except ValueError:
        raise click.ClickException(f"--size: {size!r} is not WIDTHxHEIGHT") from None
    if not (16 <= width <= 8192 and 16 <= height <= 8192):
        raise click.ClickException("--size: width and height must be 16..8192")
    return width, height
