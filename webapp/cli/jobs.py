"""`illusion-studio worker` and `illusion-studio jobs …`."""

from __future__ import annotations

import json
import logging

import click
from sqlalchemy import select

from dataset.db import transaction
from dataset.services import jobs as job_service
from dataset.services import training
from dataset.tables import Job
from webapp.cli.errors import service_errors
from webapp.cli.state import CliState, pass_state
from webapp.jobs import runs as run_control


@click.command()
@click.option("--concurrency", default=1, show_default=True, type=click.IntRange(1, 64),
              help="Jobs run at once by this worker (threads). Run more workers for more processes.")
@click.option("--burst", is_flag=True,
              help="Run the queued jobs (and those they queue) in this process, --concurrency at once, then exit.")
@click.option("--queue", "queue_name", type=click.Choice(["default", "train"]), default="default", show_default=True,
              help="Which queue to take jobs from: train runs only training jobs, default everything else.")
@pass_state
def worker(state: CliState, concurrency: int, burst: bool, queue_name: str) -> None:
    """Run jobs from the queue until interrupted (Ctrl-C). Start as many as you like.

    Training jobs have a queue of their own: run `worker --queue train` as well (one per machine
    whose CPUs or GPUs should train), so that other jobs never wait behind a run that takes hours.
    """
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    if burst:
        from webapp.jobs.handlers import HANDLERS

        results = job_service.run_queued_jobs(HANDLERS, state.runtime, workers=concurrency)
        for job_id, job_state in results:
            click.echo(f"job {job_id}: {job_state.value}")
        if any(s.value != "succeeded" for _, s in results):
            raise click.ClickException("some jobs did not succeed; see `illusion-studio jobs list`")
        return
    queue = state.runtime.queue
    click.echo(f"worker {job_service.worker_id()} ({queue_name} queue) on "
               f"{state.settings.queue_url or state.settings.queue_path}", err=True)
    queue.run_worker(concurrency, queue_name)


@click.group()
def jobs() -> None:
    """Inspect and retry jobs."""


@jobs.command("list")
@click.option("--state", "state_filter", default=None, help="Only jobs in this state.")
@click.option("--json", "as_json", is_flag=True, help="Print a JSON array.")
@pass_state
def list_jobs(state: CliState, state_filter: str | None, as_json: bool) -> None:
    with state.runtime.sessions() as s:
        query = select(Job).order_by(Job.id)
        if state_filter:
            query = query.where(Job.state == state_filter)
        rows = [job_service.job_json(j) for j in s.scalars(query)]
    if as_json:
        click.echo(json.dumps(rows, indent=2))
        return
    for j in rows:
        click.echo(f"{j['id']:>5} {j['kind']:<20} {j['state']:<12} {j['progress'] * 100:5.1f}%  {j['error'] or ''}")


@jobs.command("retry")
@click.argument("job_id", type=int)
@pass_state
def retry(state: CliState, job_id: int) -> None:
    """Queue a failed or interrupted job again (a training job: resume its run)."""
    with service_errors():
        with state.runtime.sessions() as s:
            run_id = training.run_of_job(s, job_id)
        if run_id is not None:
            run_control.resume(state.runtime, run_id, None)
        else:
            with transaction(state.runtime.sessions) as s:
                state.runtime.queue.retry(s, job_id)
    click.echo(f"job {job_id} queued again" + (f" (run {run_id} resumes)" if run_id is not None else ""))


@jobs.command("retry-generates")
@pass_state
def retry_generates(state: CliState) -> None:
    """Queue again the failed generate jobs whose frames can become samples now (their cause fixed: a depth
    model configured, the video's depth imported); say why the others still cannot."""
    from core.wording import plural
    from dataset.services.sample_blockers import retry_failed_generates

    rt = state.runtime
    with service_errors(), transaction(rt.sessions) as s:
        result = retry_failed_generates(s, rt.settings, rt.queue.retry)
    click.echo(f"queued {plural(len(result['retried']), 'generate job')} again"
               + (f": {', '.join(map(str, result['retried']))}" if result["retried"] else ""))
    for blocked in result["still_blocked"]:
        click.echo(f"{plural(len(blocked['frame_ids']), 'frame')} still cannot ({', '.join(map(str, blocked['frame_ids'][:10]))}"
                   f"{' …' if len(blocked['frame_ids']) > 10 else ''}): {blocked['reason']}", err=True)


@jobs.command("show")
@click.argument("job_id", type=int)
@pass_state
def show(state: CliState, job_id: int) -> None:
    """Print one job with its log as JSON."""
    with service_errors(), transaction(state.runtime.sessions) as s:
        click.echo(json.dumps(job_service.job_json(job_service.get_job(s, job_id), with_log=True), indent=2))
