"""Evaluations API: curators and admins list, inspect and launch evaluations, and read their reports."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from flask import g, send_file
from flask.typing import ResponseReturnValue
from flask_login import current_user

from dataset.models import Role, User
from dataset.services import evaluations, training
from dataset.services.errors import InvalidInput
from model.evaluation import evaluation_params
from model.methods import NETWORK_METHODS, method_key
from model.registry import current_checkpoint
from webapp.api.blueprint import api, json_body
from webapp.auth import requires
from webapp.runtime import runtime


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
    """Queue an evaluate job; the body names a dataset folder and format, or a run whose test split to use."""
    rt = runtime()
    params = launch_params(json_body(), rt.settings)
    user = g.db.get(User, current_user.id)
    job = rt.submit(g.db, "evaluate", params, user)
    evaluation = evaluations.evaluation_for_job(g.db, job.id, params, user)
    g.db.commit()
    return evaluations.evaluation_json(evaluation), 202


def launch_params(body: dict[str, Any], settings: Any) -> dict[str, Any]:
    """The job's parameters from a launch body, validated; the checkpoint defaults to the current model."""
    methods = body.get("methods") or []
    if not isinstance(methods, list) or not all(isinstance(m, str) for m in methods):
        raise InvalidInput("methods must be a list of method names")
    try:
        keys = [method_key(m) for m in methods]
    except ValueError as exc:
        raise InvalidInput(str(exc)) from None
    checkpoint = body.get("checkpoint") or None
    if checkpoint is None and any(k in NETWORK_METHODS for k in keys or ["fusion"]):
        checkpoint = current_checkpoint(settings)
    run = body.get("run")
    if run not in (None, "") and not str(run).isdigit():
        raise InvalidInput("run must be a run id")
    run_dir = training.run_dir(settings.runs_dir, int(run)) if run not in (None, "") else None
    try:
        return evaluation_params(
            data=body.get("data") or None, format=body.get("format") or None, methods=keys,
            checkpoint=checkpoint, predictions=body.get("predictions") or None, mono=body.get("mono") or None,
            resolution=body.get("resolution") or None, align=str(body.get("align") or "lsq"),
            max_disparity=_opt_int(body, "max_disparity"), kitti_png=bool(body.get("kitti_png")),
            iters=_opt_int(body, "iters"), run_dir=run_dir)
    except ValueError as exc:
        raise InvalidInput(str(exc)) from None


def _opt_int(body: dict[str, Any], key: str) -> int | None:
    value = body.get(key)
    if value in (None, ""):
        return None
    if isinstance(value, bool) or not str(value).strip().isdigit():
        raise InvalidInput(f"{key} must be a positive integer")
    return int(value)


@api.get("/evaluations/<int:evaluation_id>/files/<path:name>")
@requires(Role.curator)
def evaluation_file(evaluation_id: int, name: str) -> ResponseReturnValue:
    """A file of the report folder (report.json, per_sample.csv, pictures, predictions) by relative path."""
    path: Path = evaluations.report_file(evaluations.get_evaluation(g.db, evaluation_id), name)
    return send_file(path, max_age=0, conditional=True)
