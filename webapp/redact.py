"""What the app shows from sources outside its own answers, and the folders it serves files from, set
up as the app starts.

Answers are not rewritten as a whole: what people type reaches others as they typed it, and a large
answer (a SAM2 mask) costs nothing extra. The sources that bring server paths in are rewritten where
they are shown (``dataset.redact``): services call :func:`dataset.redact.redacted` (job logs, errors,
parameters and results, a run's end reason and parameters), for which this module makes the
workspace's redactor the current one in every request; the views that serve a run's log or a
report's text files apply :func:`app_redactor` themselves.
"""

from __future__ import annotations

from flask import Flask, current_app, g

from dataset.contained import resolve_storage
from dataset.redact import Redactor, redactor_for, stop_using, use_redactor
from dataset.settings import Settings

EXTENSION = "illusion_studio_redact"


def app_redactor() -> Redactor:
    """This app's redactor, for a file a view serves (a run's log, a report's text): take it in the
    view, since a streamed answer runs after the request's context has gone."""
    return current_app.extensions[EXTENSION]


def init_redaction(app: Flask, settings: Settings) -> None:
    """Make the workspace's redactor current in every request, and resolve ``runs/`` and
    ``evaluations/`` now (an admin may have made them links to shared storage; see ``dataset.contained``)."""
    redactor = app.extensions[EXTENSION] = redactor_for(settings)
    resolve_storage(settings)

    @app.before_request
    def _use_redactor() -> None:
        g.redactor_token = use_redactor(redactor)

    @app.teardown_request
    def _stop_using(_exc: BaseException | None) -> None:
        token = g.pop("redactor_token", None)
        if token is not None:
            stop_using(token)
