"""`illusion-studio media …`: housekeeping of the media store."""

from __future__ import annotations

import json
from datetime import timedelta

import click

from dataset.services.media_gc import clean_incoming, collect
from webapp.cli.state import CliState, pass_state


@click.group()
def media() -> None:
    """Media store housekeeping."""


@media.command("gc")
@click.option("--dry-run", is_flag=True, help="List what would go; delete nothing.")
@pass_state
def gc(state: CliState, dry_run: bool) -> None:
    """Delete stored files nothing in the database references (and dead uploads' leftovers).

    Files younger than media_gc_grace_hours, or than the oldest running or queued job, stay.
    Prints a JSON summary; with --dry-run, the keys that would go too.
    """
    rt = state.runtime
    grace = timedelta(hours=rt.settings.media_gc_grace_hours)
    with rt.sessions() as s:
        report = collect(s, rt.media, grace=grace, dry_run=dry_run)
    summary = {**report.json(), "dry_run": dry_run,
               "incoming_removed": 0 if dry_run else clean_incoming(rt.media, older_than_s=grace.total_seconds())}
    if dry_run:
        summary["would_remove"] = report.removed
    click.echo(json.dumps(summary, indent=2))
