"""`init`, `serve`, `synth` and `demo`: set up a workspace and run the app."""

from __future__ import annotations

import importlib.util
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import click
from sqlalchemy import select

from dataset.db import migrate, transaction
from dataset.models import JobState, Role, User, Video
from dataset.services import jobs as job_service
from dataset.services import users as user_service
from dataset.services.ingest import ingest_params
from dataset.settings import HOME_ENV, Settings, SettingsError, load_settings
from dataset.wording import plural
from webapp.cli.state import CliState, pass_state
from webapp.runtime import Runtime

DEMO_DIR = Path("var/demo")
DEMO_PASSWORD = "{role}-demo"
# The demo's run: short enough for a minute of CPU, long enough for curves, a validation and checkpoints.
DEMO_TRAIN = {"train.steps": 40, "train.batch_size": 2, "train.crop": (96, 192), "train.val_every": 20,
              "train.checkpoint_every": 20}


def init_workspace(data_dir: Path | None) -> Settings:
    """Create the data dir (if needed) and bring its database to the newest schema."""
    try:
        if data_dir is None:
            settings = load_settings(None, must_exist=False)
        else:
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
    """Run the web app with waitress."""
    _serve(state, host, port, threads)


def _serve(state: CliState, host: str | None, port: int | None, threads: int) -> None:
    import waitress

    from webapp.app import create_app

    app = create_app(state.settings, state.runtime)
    host = host or state.settings.host
    port = port or state.settings.port
    click.echo(f"Illusion Studio at http://{host}:{port}/  (Ctrl-C to stop)", err=True)
    waitress.serve(app, host=host, port=port, threads=threads, ident="illusion-studio")


@click.command()
@click.argument("out_dir", type=click.Path(file_okay=False, path_type=Path))
@click.option("--videos", default=3, show_default=True, type=click.IntRange(1, 1000))
@click.option("--seed", default=0, show_default=True, type=int)
@click.option("--frames", "n_frames", default=12, show_default=True, type=click.IntRange(1, 10_000))
@click.option("--size", default="640x360", show_default=True, help="WIDTHxHEIGHT in pixels.")
def synth(out_dir: Path, videos: int, seed: int, n_frames: int, size: str) -> None:
    """Render synthetic illusion videos (picture + mirror, with exact ground truth) into OUT_DIR."""
    from dataset.synthetic import write_synthetic_dataset

    width, height = _parse_size(size)
    with click.progressbar(length=videos, label="rendering", file=sys.stderr) as bar:
        paths = []
        for k in range(videos):
            paths += write_synthetic_dataset(out_dir, videos=1, seed=seed + k, n_frames=n_frames,
                                             width=width, height=height)
            bar.update(1)
    for path in paths:
        click.echo(str(path))


def _parse_size(size: str) -> tuple[int, int]:
    try:
        width, height = (int(v) for v in size.lower().split("x"))
    except ValueError:
        raise click.ClickException(f"--size: {size!r} is not WIDTHxHEIGHT") from None
    if not (16 <= width <= 8192 and 16 <= height <= 8192):
        raise click.ClickException("--size: width and height must be 16..8192")
    return width, height


@click.command()
@click.option("--no-serve", is_flag=True, help="Set everything up, run the import jobs, then exit.")
@click.option("--videos", default=3, show_default=True, type=click.IntRange(1, 50))
@click.option("--host", default=None, help="Bind address (default 127.0.0.1).")
@click.option("--port", default=None, type=int, help="Port (default 5000).")
@pass_state
def demo(state: CliState, no_serve: bool, videos: int, host: str | None, port: int | None) -> None:
    """A ready-to-click workspace in ./var/demo: synthetic videos, one user per role, worker and server."""
    from dataset.synthetic import write_synthetic_dataset

    if state.data_dir is None:
        state.data_dir = DEMO_DIR.resolve()
    settings = init_workspace(state.data_dir)
    rt = state.runtime
    synth_dir = settings.home / "synthetic"
    video_dirs = sorted(p for p in synth_dir.glob("synthetic-*") if (p / "scene.json").is_file())
    if len(video_dirs) < videos:
        click.echo(f"rendering {videos} synthetic videos into {synth_dir} …", err=True)
        video_dirs = write_synthetic_dataset(synth_dir, videos=videos, seed=0, defects=True)

    logins = []
    with transaction(rt.sessions) as s:
        for role in Role:
            password = DEMO_PASSWORD.format(role=role.value)
            if s.scalar(select(User.id).where(User.name == role.value)) is None:
                user_service.create_user(s, role.value, role, password)
            logins.append((role.value, password))
        admin = s.scalar(select(User).where(User.name == Role.admin.value))
        imported = set(s.scalars(select(Video.original_path)))
        # Synthetic scenes pan slowly but every frame is distinct, so no de-duplication here.
        jobs = [rt.queue.submit(s, "ingest", ingest_params(str(p), user_id=admin.id, dedup_hamming=None,
                                                           prefilter=True), admin)
                for p in video_dirs if str(p) not in imported]

    if jobs:
        _prepare_demo(rt)
    click.echo("\nDemo users (name / password):")
    for name, password in logins:
        click.echo(f"  {name:<10} {password}")
    if no_serve:
        click.echo(f"\nworkspace ready at {settings.home}; run `illusion-studio --data-dir {settings.home} serve`")
        return

    env = {**os.environ, HOME_ENV: str(settings.home)}
    workers = [subprocess.Popen([sys.executable, "-m", "webapp.cli", "worker", "--queue", queue], env=env)
               for queue in ("default", "train")]
    click.echo(f"workers started (pids {', '.join(str(w.pid) for w in workers)}: default and train queues)", err=True)
    # Python skips `finally` on SIGTERM; turn it into an exit so the workers are stopped with us.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    try:
        _serve(state, host, port, threads=8)
    finally:
        for worker in workers:
            worker.terminate()
        for worker in workers:
            worker.wait(timeout=30)


def _prepare_demo(rt: Runtime) -> None:
    """Ingest and prefilter the videos, review and annotate some frames, generate their samples.

    Runs the jobs in this process (the same code a worker runs), so that every page has content
    the moment the server starts.
    """
    from dataset.services.demo import seed_reviews_and_annotations
    from webapp.jobs.handlers import HANDLERS

    with click.progressbar(length=3, label="preparing the demo", file=sys.stderr) as bar:
        _report_jobs(job_service.run_queued_jobs(HANDLERS, rt))
        bar.update(1)
        with transaction(rt.sessions) as s:
            curator = s.scalar(select(User).where(User.name == Role.curator.value))
            annotator = s.scalar(select(User).where(User.name == Role.annotator.value))
            for frame_id in seed_reviews_and_annotations(s, rt.media, curator, annotator):
                rt.submit(s, "generate", {"frame_id": frame_id}, annotator)
        bar.update(1)
        _report_jobs(job_service.run_queued_jobs(HANDLERS, rt))
        bar.update(1)
    _train_demo_model(rt)
    # Every job row has run here, so the queues hold only their now-stale messages: drop them
    # rather than have the workers wake up for each.
    for huey in rt.queue.hueys.values():
        huey.flush()


def _train_demo_model(rt: Runtime) -> None:
    """Accept the generated samples and train a short `lite` run on them, marked as the current model
    (with too few videos for its splits, neither)."""
    from dataset.services import training
    from dataset.services.demo import accept_generated_samples
    from dataset.services.errors import InvalidInput
    from webapp.jobs import runs as run_control
    from webapp.jobs.handlers import HANDLERS

    if importlib.util.find_spec("torch") is None:
        click.echo("no demo training run: torch is not installed (pip install -e '.[models]')", err=True)
        return
    try:
        # One transaction: samples are accepted only for a run that can start, so a demo too small
        # to train on leaves them for a curator to review.
        with transaction(rt.sessions) as s:
            curator = s.scalar(select(User).where(User.name == Role.curator.value))
            admin = s.scalar(select(User).where(User.name == Role.admin.value))
            accepted = accept_generated_samples(s, curator)
            run = run_control.launch(rt, s, preset="lite", overrides=DEMO_TRAIN, selection=training.DataSelection(),
                                     launch=training.Launch(split=training.parse_split(training.DEFAULT_SPLIT)),
                                     user=s.get(User, admin.id))
            run_id = run.id
        click.echo(f"{accepted} generated samples accepted", err=True)
    except InvalidInput as exc:
        click.echo(f"no demo training run: {exc}", err=True)
        return
    click.echo(f"training demo run {run_id} ({DEMO_TRAIN['train.steps']} steps of lite) …", err=True)
    started = time.monotonic()
    results = job_service.run_queued_jobs(HANDLERS, rt)
    _report_jobs(results)
    if any(job_state != JobState.succeeded for _, job_state in results):
        click.echo(f"the demo run did not succeed; see `illusion-studio runs show {run_id}`", err=True)
        return
    try:
        doc = run_control.promote(rt, run_id, "best", admin)
    except InvalidInput:  # no finite validation EPE, so no best checkpoint: the last one will do
        doc = run_control.promote(rt, run_id, "last", admin)
    click.echo(f"demo run {run_id} trained in {time.monotonic() - started:.0f} s; current model: step {doc['step']}",
               err=True)


def _report_jobs(results: list[tuple[int, JobState]]) -> None:
    for job_id, job_state in results:
        if job_state != JobState.succeeded:
            click.echo(f"job {job_id}: {job_state.value} (see `illusion-studio jobs show {job_id}`)", err=True)
    click.echo(f"{sum(s == JobState.succeeded for _, s in results)} of {plural(len(results), 'job')} succeeded")
