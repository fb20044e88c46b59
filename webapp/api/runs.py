"""Training runs API: curators look (list, show, live metrics, checkpoints); admins launch, cancel,
resume and promote."""

from __future__ import annotations

from typing import Any

from flask import g, request
from flask.typing import ResponseReturnValue
from flask_login import current_user

from dataset.services import training
from dataset.tables import Role, User
from model.runs import registry, run_length
from model.runs.schema import FieldError, RunLaunch, validate
from webapp.api.blueprint import api, id_list_arg, int_arg, json_body
from webapp.auth import requires
from webapp.jobs import runs as run_control
from webapp.runtime import runtime
from webapp.served import send_opened


def _run_json(run_id: int) -> dict[str, Any]:
    rt = runtime()
    return training.run_json(training.get_run(g.db, run_id), rt.settings.runs_dir,
                             current=registry.current_model(rt.settings), full=True)


def _user() -> User | None:
    return g.db.get(User, current_user.id)


@api.get("/runs")
@requires(Role.curator)
def list_runs() -> ResponseReturnValue:
    rt = runtime()
    current = registry.current_model(rt.settings)
    # ?ids= picks runs (the compare page); ids that name no run pick none, never all.
    rows = training.list_runs(g.db, id_list_arg("ids")) if "ids" in request.args else training.list_runs(g.db)
    return {"items": [training.run_json(r, rt.settings.runs_dir, current=current) for r in rows], "current": current}


@api.post("/runs")
@requires(Role.admin)
def launch_run() -> ResponseReturnValue:
    """Body: :class:`model.runs.schema.RunLaunch` (published in the OpenAPI document)."""
    request_ = validate(RunLaunch, json_body(), runtime().settings)
    run = run_control.launch_request(runtime(), g.db, request_, _user())
    g.db.commit()
    return _run_json(run.id), 202


@api.post("/runs/estimate")
@requires(Role.admin)
def estimate_run() -> ResponseReturnValue:
    """Body: :class:`model.runs.schema.RunLaunch`, validated as a launch is (a wrong field is its 400)."""
    return run_length.launch_estimate(g.db, validate(RunLaunch, json_body(), runtime().settings))


@api.get("/runs/<int:run_id>")
@requires(Role.curator)
def get_run(run_id: int) -> ResponseReturnValue:
    return _run_json(run_id)


@api.get("/runs/<int:run_id>/metrics")
@requires(Role.curator)
def run_metrics(run_id: int) -> ResponseReturnValue:
    """Curve points after step ``after`` (validations after ``after_val``): what a live chart lacks."""
    after, after_val = int_arg("after", -1), int_arg("after_val", -1)
    return {"run": run_id, **training.metrics_since(g.db, run_id, -1 if after is None else after,
                                                     -1 if after_val is None else after_val)}


@api.post("/runs/<int:run_id>/cancel")
@requires(Role.admin)
def cancel_run(run_id: int) -> ResponseReturnValue:
    run_control.cancel(runtime(), run_id, _user())
    return _run_json(run_id), 202


@api.post("/runs/<int:run_id>/resume")
@requires(Role.admin)
def resume_run(run_id: int) -> ResponseReturnValue:
    run_control.resume(runtime(), run_id, _user())
    return _run_json(run_id), 202


@api.post("/runs/<int:run_id>/promote")
@requires(Role.admin)
def promote_run(run_id: int) -> ResponseReturnValue:
    """Body ``{"checkpoint": "best" | "last" | a file name from the run's checkpoints}`` (default best)."""
    body = (request.get_data() and json_body()) or {}
    if unknown := sorted(set(body) - {"checkpoint"}):
        raise FieldError(unknown[0], "not a field of a promote; send {\"checkpoint\": …} only")
    which = body.get("checkpoint", "best")
    if not isinstance(which, str):
        raise FieldError("checkpoint", "expected best, last or a file name of the run's checkpoints")
    return run_control.promote(runtime(), run_id, which, _user())


@api.get("/runs/<int:run_id>/checkpoints/<name>")
@requires(Role.curator)
def download_checkpoint(run_id: int, name: str) -> ResponseReturnValue:
    """One of the run's checkpoint files by name (never a path the caller makes up, never a link)."""
    run = training.get_run(g.db, run_id)
    found, file = registry.open_run_checkpoint(runtime().settings.runs_dir, run.id, name, best_step=run.best_step)
    return send_opened(file, f"run{run_id}_{found.name}", mimetype="application/octet-stream", as_attachment=True)
