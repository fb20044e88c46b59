"""Training runs API: curators look (list, show, live metrics, checkpoints); admins launch, cancel,
resume and promote."""

from __future__ import annotations

from typing import Any

from flask import g, request, send_file
from flask.typing import ResponseReturnValue
from flask_login import current_user

from dataset.models import Role, User
from dataset.services import training
from dataset.services.errors import InvalidInput, NotFound
from model import registry
from webapp.api.blueprint import api, int_arg, json_body
from webapp.auth import requires
from webapp.jobs import runs as run_control
from webapp.runtime import runtime


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
    ids = [int(v) for v in request.args.get("ids", "").split(",") if v.strip().isdigit()]
    return {"items": [training.run_json(r, rt.settings.runs_dir, current=current)
                      for r in training.list_runs(g.db, ids or None)], "current": current}


@api.post("/runs")
@requires(Role.admin)
def launch_run() -> ResponseReturnValue:
    body = json_body()
    selection = training.DataSelection(
        video_ids=tuple(_ints(body, "video_ids")), illusion_types=tuple(_strings(body, "illusion_types")),
        kinds=tuple(_strings(body, "kinds")), qa_ok=bool(body.get("qa_ok", False)),
        format=str(body.get("format") or training.DATABASE), root=body.get("data_root") or None)
    launch = training.Launch(
        nproc=_int(body, "nproc", 1), devices=str(body.get("devices") or "auto"),
        nnodes=_int(body, "nnodes", 1), rdzv_endpoint=body.get("rdzv_endpoint") or None,
        init_checkpoint=body.get("init_checkpoint") or None,
        split=training.parse_split(str(body.get("split") or training.DEFAULT_SPLIT)), seed=_int(body, "seed", 0))
    overrides = run_control.overrides_from(steps=_opt_int(body, "steps"), batch=_opt_int(body, "batch"),
                               lr=_opt_float(body, "lr"), crop=body.get("crop") or None, iters=_opt_int(body, "iters"))
    run = run_control.launch(runtime(), g.db, preset=str(body.get("preset") or "lite"), overrides=overrides,
                             selection=selection, launch=launch, user=_user())
    g.db.commit()
    return _run_json(run.id), 202


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
    """Body ``{"checkpoint": "best" | "last" | a file name from the run's checkpoints}``."""
    which = str((request.get_json(silent=True) or {}).get("checkpoint") or "best")
    if which not in run_control.CHECKPOINT_CHOICES:
        which = _checkpoint(run_id, which)["path"]
    return run_control.promote(runtime(), run_id, which, _user())


@api.get("/runs/<int:run_id>/checkpoints/<name>")
@requires(Role.curator)
def download_checkpoint(run_id: int, name: str) -> ResponseReturnValue:
    found = _checkpoint(run_id, name)
    return send_file(found["path"], as_attachment=True, download_name=f"run{run_id}_{name}", max_age=0)


def _checkpoint(run_id: int, name: str) -> dict[str, Any]:
    """One of the run's checkpoint files by name (never a path the caller makes up)."""
    training.get_run(g.db, run_id)
    files = training.checkpoint_files(training.run_dir(runtime().settings.runs_dir, run_id))
    found = next((f for f in files if f["name"] == name), None)
    if found is None:
        raise NotFound(f"run {run_id} has no checkpoint {name!r}")
    return found


def _int(body: dict[str, Any], key: str, default: int) -> int:
    value = _opt_int(body, key)
    return default if value is None else value


def _opt_int(body: dict[str, Any], key: str) -> int | None:
    value = body.get(key)
    if value in (None, ""):
        return None
    if isinstance(value, bool) or not isinstance(value, int | str) or not str(value).strip().lstrip("-").isdigit():
        raise InvalidInput(f"{key} must be an integer")
    return int(value)


def _opt_float(body: dict[str, Any], key: str) -> float | None:
    value = body.get(key)
    if value in (None, ""):
        return None
    try:
        return float(value)
    except (TypeError, ValueError):
        raise InvalidInput(f"{key} must be a number") from None


def _ints(body: dict[str, Any], key: str) -> list[int]:
    values = body.get(key) or []
    if not isinstance(values, list):
        raise InvalidInput(f"{key} must be a list of integers")
    return [v for v in (_opt_int({key: v}, key) for v in values) if v is not None]


def _strings(body: dict[str, Any], key: str) -> list[str]:
    values = body.get(key) or []
    if not isinstance(values, list) or not all(isinstance(v, str) for v in values):
        raise InvalidInput(f"{key} must be a list of strings")
    return values
