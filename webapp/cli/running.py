"""Running one job from the command line: queued for a worker (default), queued and waited for
(``--wait``), or run in this process at once (``--here``: no worker needed, what a one-machine
user wants for a folder on this machine — a queued job runs on whichever machine's worker takes it)."""

from __future__ import annotations

import threading
from typing import Any

import click

from dataset.db import transaction
from dataset.services import jobs as job_service
from webapp.cli.ingest import wait_for_jobs
from webapp.cli.state import CliState
from webapp.jobs.handlers import HANDLERS


def run_options(command: Any) -> Any:
    """``--wait`` and ``--here``, for every command that runs one job."""
    command = click.option("--here", is_flag=True,
                           help="Run the job in this process now (no worker needed), showing progress.")(command)
    return click.option("--wait", is_flag=True, help="Queue the job for a worker and wait for it, showing progress.")(command)


def run_job(state: CliState, kind: str, params: dict[str, Any], what: str, *, wait: bool, here: bool,
            quiet: bool = False) -> int:
    """Create the job, then queue, wait for or run it as the flags say; returns its id. A job that
    does not succeed exits non-zero (when waited for). ``quiet`` keeps stdout for ``--json``."""
    rt = state.runtime
    with transaction(rt.sessions) as s:
        # --here skips the queue: the row alone records the job, and this process runs it.
        job_id = (job_service.create_job(s, kind, params, None) if here else rt.submit(s, kind, params, None)).id
    click.echo(f"job {job_id}: {what}", err=quiet)
    if here:
        runner = threading.Thread(target=job_service.execute_job, args=(job_id, {kind: HANDLERS[kind]}, rt),
                                  name=f"{kind}-job-{job_id}", daemon=True)
        runner.start()
        wait_for_jobs(state, [job_id], quiet=quiet)
        runner.join()  # the row is final already; Ctrl-C leaves it running, and the reaper marks it interrupted
    elif wait:
        wait_for_jobs(state, [job_id], quiet=quiet)
    else:
        click.echo("queued for a worker (`illusion-studio worker`); --here runs it in this process", err=True)
    return job_id
