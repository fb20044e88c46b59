"""The Models pages: training runs (list, launch form), one run live, and runs compared.

Curators look; the launch form and the run controls appear for admins only, and go through the
API (``/api/v1/runs…``), which enforces the same roles.
"""

from __future__ import annotations

from flask import Blueprint, abort, g, render_template, request, send_file
from flask.typing import ResponseReturnValue
from flask_login import current_user

from dataset.models import IllusionType, Role, Video
from dataset.services import training
from model import registry
from webapp.auth import requires
from webapp.runtime import runtime

bp = Blueprint("models", __name__)


@bp.get("/models")
@requires(Role.curator)
def runs() -> ResponseReturnValue:
    """Every run with its state and progress; admins also get the launch form."""
    videos = g.db.query(Video.id, Video.name).order_by(Video.id).all()
    return render_template("models.html", can_admin=current_user.allows(Role.admin), videos=videos,
                           illusion_types=list(IllusionType), kinds=training.SAMPLE_KINDS,
                           default_split=training.DEFAULT_SPLIT)


@bp.get("/models/runs/<int:run_id>")
@requires(Role.curator)
def run(run_id: int) -> ResponseReturnValue:
    """One run: live curves, validation images, config, dataset version, checkpoints."""
    rt = runtime()
    data = training.run_json(training.get_run(g.db, run_id), rt.settings.runs_dir,
                             current=registry.current_model(rt.settings), full=True)
    return render_template("run.html", run=data, can_admin=current_user.allows(Role.admin))


@bp.get("/models/compare")
@requires(Role.curator)
def compare() -> ResponseReturnValue:
    """Two or more runs (``?ids=1,2``): curves on one chart, last validation metrics side by side."""
    ids = [int(v) for v in request.args.get("ids", "").split(",") if v.strip().isdigit()]
    return render_template("compare.html", ids=ids)


@bp.get("/models/runs/<int:run_id>/files/<path:name>")
@requires(Role.curator)
def val_image(run_id: int, name: str) -> ResponseReturnValue:
    """A validation image the engine wrote, by its path in the run directory (``val/step_…/x.png``)."""
    training.get_run(g.db, run_id)
    directory = training.run_dir(runtime().settings.runs_dir, run_id)
    root = (directory / "val").resolve()
    path = (directory / name).resolve()
    if not path.is_relative_to(root) or path.suffix != ".png" or not path.is_file():
        abort(404, f"run {run_id} has no validation image {name!r}")
    return send_file(path, mimetype="image/png", max_age=3600, conditional=True)
