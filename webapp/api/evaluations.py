"""Evaluations API: curators and admins list, inspect and launch evaluations, and read their reports."""

from __future__ import annotations

from pathlib import PurePosixPath

from flask import Response, g
from flask.typing import ResponseReturnValue
from flask_login import current_user

from dataset.services import evaluations
from dataset.tables import Role, User
from model.runs.evaluation import evaluation_params
from model.runs.schema import EvaluationLaunch, validate
from webapp.api.blueprint import api, json_body
from webapp.auth import requires
from webapp.redact import app_redactor
from webapp.runtime import runtime
from webapp.served import send_opened


@api.get("/evaluations")
@requires(Role.curator)
def list_evaluations() -> ResponseReturnValue:
    return {"items": evaluations.list_evaluations(g.db)}


@api.get("/evaluations/<int:evaluation_id>")
@requires(Role.curator)
def get_evaluation(evaluation_id: int) -> ResponseReturnValue:
    return evaluations.evaluation_json(evaluations.get_evaluation(g.db, evaluation_id))


@api.post("/evaluations")
@requires(Role.curator)
def launch_evaluation() -> ResponseReturnValue:
    """Queue an evaluate job. Body: :class:`model.runs.schema.EvaluationLaunch` (in the OpenAPI document)."""
    rt = runtime()
    params = evaluation_params(validate(EvaluationLaunch, json_body(), rt.settings), rt.settings, g.db)
    user = g.db.get(User, current_user.id)
    job = rt.submit(g.db, "evaluate", params, user)
    evaluation = evaluations.evaluation_for_job(g.db, job.id, params, user)
    g.db.commit()
    return evaluations.evaluation_json(evaluation), 202


@api.get("/evaluations/<int:evaluation_id>/files/<path:name>")
@requires(Role.curator)
def evaluation_file(evaluation_id: int, name: str) -> ResponseReturnValue:
    """A file of the report folder (report.json, per_sample.csv, pictures, predictions) by relative path."""
    evaluation = evaluations.get_evaluation(g.db, evaluation_id)
    file = evaluations.open_report_file(evaluation, name, runtime().settings.home)
    suffix = PurePosixPath(name).suffix
    if suffix in _TEXT:  # written by a job, which may quote server paths (a sample's failure)
        with file:
            text = file.read().decode("utf-8", errors="replace")
        return Response(app_redactor()(text), mimetype=_TEXT[suffix])
    return send_opened(file, PurePosixPath(name).name)


_TEXT = {".json": "application/json", ".html": "text/html", ".csv": "text/csv", ".txt": "text/plain"}
