"""`demo`: a ready-to-click workspace (synthetic videos, one user per role), its workers and the server.

The data a newcomer clicks through is prepared in this process before the server starts; the demo's
training run is a queued job the train worker runs while the newcomer watches it on the Models page.
A thread of this process follows the run and, when it ends, makes its best checkpoint the current
model and queues the demo's evaluation. With ``--no-serve`` all of it runs here, then the command exits.
"""

from __future__ import annotations

import importlib.util
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import click
from sqlalchemy import inspect, select
from sqlalchemy.engine import make_url

from core.wording import plural
from dataset.db import make_engine, transaction
from dataset.services import jobs as job_service
from dataset.services import users as user_service
from dataset.services.errors import ServiceError
from dataset.services.ingest import ingest_params
from dataset.settings import HOME_ENV, SettingsError, load_settings
from dataset.tables import Frame, FrameState, JobState, Role, RunState, TrainingRun, User, Video
from webapp.cli.state import CliState, pass_state
from webapp.cli.workspace import init_workspace, make_server, server_url
from webapp.runtime import Runtime

DEMO_DIR = Path("var/demo")
# Written into a workspace the demo creates; the demo adds users with published passwords to no other.
DEMO_MARKER = ".illusion-studio-demo"
DEMO_PASSWORD = "{role}-demo"
# The demo's run: short enough for a minute of CPU, long enough for curves, a validation and checkpoints.
DEMO_TRAIN = {"train.steps": 40, "train.batch_size": 2, "train.crop": (96, 192), "train.val_every": 20,
              "train.checkpoint_every": 20}
POLL_S = 2.0
# Shown on the run's page: what the demo's run is for, how long it takes, and that its model is no use.
DEMO_RUN_NOTE = (f"The demo's toy run: {DEMO_TRAIN['train.steps']} steps of the lite preset on the demo's few samples, "
                 "so that the Models and Evaluation pages have something to show. It takes under a minute on a quiet "
                 "2-core machine and a quarter of an hour on a busy one; its model is a toy (expect a validation bad-2 "
                 "near 100 %). For a model worth using, accept more samples and launch a longer run.")


@click.command()
@click.option("--no-serve", is_flag=True, help="Set everything up, run every job here (training too), then exit.")
@click.option("--videos", default=3, show_default=True, type=click.IntRange(1, 50))
@click.option("--host", default=None, help="Bind address (default 127.0.0.1).")
@click.option("--port", default=None, type=int, help="Port (default 5000).")
@pass_state
def demo(state: CliState, no_serve: bool, videos: int, host: str | None, port: int | None) -> None:
    """A ready-to-click workspace (default ./var/demo): synthetic videos, one user per role, workers and server."""
    from dataset.synthetic import write_synthetic_dataset

    home = (state.data_dir or DEMO_DIR).expanduser().resolve()
    claim_demo_workspace(home)
    state.data_dir = home
    settings = init_workspace(home)
    rt = state.runtime
    synth_dir = settings.home / "synthetic"
    video_dirs = sorted(p for p in synth_dir.glob("synthetic-*") if (p / "scene.json").is_file())
    if len(video_dirs) < videos:
        click.echo(f"rendering {videos} synthetic videos into {synth_dir} …", err=True)
        video_dirs = write_synthetic_dataset(synth_dir, videos=videos, seed=0, defects=True)

    logins, new_videos = _users_and_videos(rt, video_dirs)
    if new_videos:
        _prepare_demo(rt)
        run_id = _launch_demo_run(rt)
    else:
        run_id = _unfinished_demo_run(rt)
    if no_serve:
        if run_id is not None:
            _run_here(rt)
            if _finish_demo_run(rt, run_id) is not None:
                _run_here(rt)
        click.echo(frame_logins(logins, f"workspace ready at {settings.home}",
                                f"run `illusion-studio --data-dir {settings.home} serve`"))
        return

    workers = _start_workers(settings.home)
    if run_id is not None:
        threading.Thread(target=_watch_demo_run, args=(rt, run_id), name="demo-run", daemon=True).start()
    # Python skips `finally` on SIGTERM; turn it into an exit so the workers are stopped with us.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    try:
        server = make_server(settings, rt, host, port, threads=8)
        # Listening now: a browser's first request waits in the backlog for run() below, at most moments.
        training_note = f"run {run_id} trains meanwhile: watch it on the Models page; " if run_id is not None else ""
        click.echo(frame_logins(logins, f"Illusion Studio demo at {server_url(server)}",
                                f"{training_note}Ctrl-C stops it"))
        server.run()
    finally:
        for worker in workers:
            worker.terminate()
        for worker in workers:
            worker.wait(timeout=30)


def _users_and_videos(rt: Runtime, video_dirs: list[Path]) -> tuple[list[tuple[str, str]], bool]:
    """One user per role (name = role, published password) and an ingest job per video not yet imported;
    the logins, and whether any video was new."""
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
    return logins, bool(jobs)


def claim_demo_workspace(home: Path) -> None:
    """Refuse ``home`` unless the demo created it (or it is new or empty, and then mark it as the demo's):
    the demo writes users with published passwords. Nothing is written when refused."""
    marker = home / DEMO_MARKER
    if marker.is_file():
        return
    if home.is_dir() and any(home.iterdir()):
        raise click.ClickException(
            f"{home} holds a workspace the demo did not create; the demo adds users with published passwords "
            f"(admin / admin-demo), so it fills only a new or empty folder: pass another --data-dir (or remove "
            f"{home} if an older demo made it)")
    if home.exists() and not home.is_dir():
        raise click.ClickException(f"{home} is not a directory")
    try:
        settings = load_settings(home, must_exist=False)
    except SettingsError as exc:
        raise click.ClickException(str(exc)) from None
    if _has_users(settings.database_url):
        raise click.ClickException(
            "the configured database already has users (ILLUSION_STUDIO_DATABASE_URL?); the demo adds users "
            "with published passwords, so it only fills a database of its own")
    home.mkdir(parents=True, exist_ok=True)
    marker.write_text("This workspace was created by `illusion-studio demo`; its users have published passwords.\n",
                      encoding="utf-8")


def _has_users(url: str) -> bool:
    """Whether the database at ``url`` has a users table with rows (without creating a SQLite file)."""
    parsed = make_url(url)
    if parsed.get_backend_name() == "sqlite" and not Path(parsed.database or "").is_file():
        return False
    engine = make_engine(url)
    try:
        if not inspect(engine).has_table(User.__tablename__):
            return False
        with engine.connect() as connection:
            return connection.scalar(select(User.id).limit(1)) is not None
    finally:
        engine.dispose()


def frame_logins(logins: list[tuple[str, str]], head: str, foot: str) -> str:
    """The demo's logins in a box, so they stand out of the log lines around them."""
    lines = [head, "", "Demo users (name / password):", *(f"  {name:<10} {password}" for name, password in logins),
             "", foot]
    width = max(len(line) for line in lines)
    rule = "─" * (width + 2)
    return "\n".join([f"┌{rule}┐", *(f"│ {line:<{width}} │" for line in lines), f"└{rule}┘"])


def _start_workers(home: Path) -> list[subprocess.Popen[bytes]]:
    """A default and a train worker on ``home``, logging to ``home/logs`` (the terminal keeps the logins)."""
    logs = home / "logs"
    logs.mkdir(exist_ok=True)
    env = {**os.environ, HOME_ENV: str(home)}
    workers = []
    for queue in ("default", "train"):
        with open(logs / f"worker-{queue}.log", "ab") as log:
            workers.append(subprocess.Popen([sys.executable, "-m", "webapp.cli", "worker", "--queue", queue],
                                            env=env, stdout=log, stderr=subprocess.STDOUT))
    click.echo(f"workers started (default and train queues; their logs: {logs}/worker-*.log)", err=True)
    return workers


def _prepare_demo(rt: Runtime) -> None:
    """Ingest and prefilter the videos, review and annotate some frames, generate their samples.

    Runs the jobs in this process (the same code a worker runs), so that every page has content
    the moment the server starts.
    """
    from dataset.services import pipeline
    from dataset.services.demo import seed_reviews_and_annotations

    with click.progressbar(length=2, label="preparing the demo", file=sys.stderr) as bar:
        _run_here(rt)
        bar.update(1)
        with transaction(rt.sessions) as s:
            curator = s.scalar(select(User).where(User.name == Role.curator.value))
            annotator = s.scalar(select(User).where(User.name == Role.annotator.value))
            for frame_id in seed_reviews_and_annotations(s, rt.media, curator, annotator):
                pipeline.submitted(s, rt.submit, pipeline.GenerateParams(frame_id), annotator)
            # The approved frames left to annotate get their proposals now, as a curator's approval queues them.
            waiting = s.scalars(select(Frame.id).where(Frame.state == FrameState.approved).order_by(Frame.id)).all()
            pipeline.approved(s, rt.submit, rt.settings, waiting, curator)
        _run_here(rt)
        bar.update(1)


def _run_here(rt: Runtime) -> None:
    """Run every queued job in this process and report those that failed."""
    from webapp.jobs.handlers import HANDLERS

    results = job_service.run_queued_jobs(HANDLERS, rt)
    # Every job row has run, so the queues hold only their now-stale messages: drop them rather
    # than have the workers wake up for each.
    for huey in rt.queue.hueys.values():
        huey.flush()
    for job_id, job_state in results:
        if job_state != JobState.succeeded:
            click.echo(f"job {job_id}: {job_state.value} (see `illusion-studio jobs show {job_id}`)", err=True)
    click.echo(f"{sum(s == JobState.succeeded for _, s in results)} of {plural(len(results), 'job')} succeeded")


def _launch_demo_run(rt: Runtime) -> int | None:
    """Accept the generated samples and queue a short `lite` run on them; the run's id, or None (with
    the reason) when torch is missing or the demo has too few videos for a run's splits."""
    from dataset.services import training
    from dataset.services.demo import accept_generated_samples
    from webapp.jobs import runs as run_control

    if importlib.util.find_spec("torch") is None:
        click.echo("no demo training run: torch is not installed (pip install -e '.[models]')", err=True)
        return None
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
            run.launch = {**run.launch, "note": DEMO_RUN_NOTE}
            run_id = run.id
    except ServiceError as exc:
        click.echo(f"no demo training run: {exc}", err=True)
        return None
    click.echo(f"{accepted} generated samples accepted; demo run {run_id} queued "
               f"({DEMO_TRAIN['train.steps']} steps of lite)", err=True)
    return run_id


def _unfinished_demo_run(rt: Runtime) -> int | None:
    """On a later start, the demo's run if it never became the current model (the demo stopped first)."""
    from model.runs.registry import current_checkpoint

    if current_checkpoint(rt.settings) is not None:
        return None
    with rt.sessions() as s:
        return s.scalar(select(TrainingRun.id).order_by(TrainingRun.id.desc()).limit(1))


def _watch_demo_run(rt: Runtime, run_id: int) -> None:
    """Thread: wait for the demo's run to end, then finish it (promote, evaluate)."""
    try:
        _finish_demo_run(rt, run_id, wait=True)
    except Exception as exc:  # a thread's exception would vanish unseen; the server keeps serving
        click.echo(f"the demo could not finish run {run_id}: {exc}", err=True)


def _finish_demo_run(rt: Runtime, run_id: int, *, wait: bool = False) -> int | None:
    """When the run has succeeded: its best checkpoint (else its last) becomes the current model and the
    demo's evaluation is queued; returns the evaluation's id (None when the run did not succeed)."""
    from dataset.services import training
    from webapp.jobs import runs as run_control

    while True:
        with rt.sessions() as s:
            run = training.get_run(s, run_id)
            state, steps = training.effective_state(run), run.steps
        if state.finished or not wait:
            break
        time.sleep(POLL_S)
    if state != RunState.succeeded:
        click.echo(f"demo run {run_id} is {state.value}, not succeeded; see `illusion-studio runs show {run_id}`", err=True)
        return None
    with rt.sessions() as s:
        admin_id = s.scalar(select(User.id).where(User.name == Role.admin.value))
        admin = s.get(User, admin_id)
    try:
        which, doc = "best", run_control.promote(rt, run_id, "best", admin)
    except ServiceError:  # no finite validation EPE, so no best checkpoint: the last one will do
        which, doc = "last", run_control.promote(rt, run_id, "last", admin)
    evaluation_id = _launch_demo_evaluation(rt, run_id, admin_id)
    click.echo(f"demo run {run_id} done; current model: run {run_id}, {which} checkpoint (step {doc['step']} of "
               f"{steps}); evaluation {evaluation_id} queued (the Evaluation page)", err=True)
    return evaluation_id


def _launch_demo_evaluation(rt: Runtime, run_id: int, user_id: int) -> int:
    """Queue the default methods, with the current model, on the run's held-out test split; the evaluation's id."""
    from dataset.services import evaluations
    from model.runs.evaluation import DEFAULT_METHODS, evaluation_params
    from model.runs.schema import EvaluationLaunch

    with transaction(rt.sessions) as s:
        params = evaluation_params(EvaluationLaunch(methods=list(DEFAULT_METHODS), run=run_id), rt.settings, s)
        user = s.get(User, user_id)
        job = rt.submit(s, "evaluate", params, user)
        return evaluations.evaluation_for_job(s, job.id, params, user).id
