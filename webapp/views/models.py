"""The Models pages: training runs (list, launch form), one run live, and runs compared.

Curators look; the launch form and the run controls appear for admins only, and go through the
API (``/api/v1/runs…``), which enforces the same roles.
"""

from __future__ import annotations

from pathlib import PurePosixPath
from typing import Any

from flask import Blueprint, Response, abort, g, render_template
from flask.typing import ResponseReturnValue
from flask_login import current_user

from dataset.contained import open_contained
from dataset.readers import READER_FORMATS
from dataset.services import run_logs, training
from dataset.tables import IllusionType, Role, Video
from model.presets import ALL_PRESETS, load_preset
from model.runs import registry, run_length
from model.runs.capacity import suggest_crop
from webapp.api.blueprint import id_list_arg, int_arg
from webapp.auth import requires
from webapp.redact import app_redactor
from webapp.runtime import runtime
from webapp.served import send_opened

bp = Blueprint("models", __name__)


@bp.get("/models")
@requires(Role.curator)
def runs() -> ResponseReturnValue:
    """Every run with its state and progress; admins also get the launch form."""
    videos = g.db.query(Video.id, Video.name).order_by(Video.id).all()
    settings = runtime().settings
    return render_template("models.html", can_admin=current_user.allows(Role.admin), videos=videos,
                           illusion_types=list(IllusionType), kinds=training.SAMPLE_KINDS,
                           default_split=training.DEFAULT_SPLIT, formats=READER_FORMATS,
                           roots=sorted(settings.dataset_roots), max_nproc=settings.train_max_nproc,
                           gpu=settings.train_devices == "cuda",
                           checkpoints=registry.named_checkpoints(g.db, settings.runs_dir),
                           imported=registry.imported_fits(settings.home),
                           preset_names=ALL_PRESETS,
                           suggested_crop=suggest_crop(load_preset("lite"), training.smallest_accepted_image(g.db)),
                           presets=_preset_values(), start=run_length.latest_finished_size(g.db))


def _preset_values() -> dict[str, dict[str, Any]]:
    """What each preset trains with when a launch leaves a field empty: the form's placeholders."""
    values = {}
    for name in ALL_PRESETS:
        train = load_preset(name).train
        values[name] = {"steps": train.steps, "batch": train.batch_size, "lr": train.lr,
                        "crop": "x".join(map(str, train.crop)), "iters": train.train_iters}
    return values


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
    ids = id_list_arg("ids")
    return render_template("compare.html", ids=ids)


@bp.get("/models/runs/<int:run_id>/files/<path:name>")
@requires(Role.curator)
def val_image(run_id: int, name: str) -> ResponseReturnValue:
    """A validation image the engine wrote, by its path in the run directory (``val/step_…/x.png``)."""
    training.get_run(g.db, run_id)
    directory = training.run_dir(runtime().settings.runs_dir, run_id)
    parts = PurePosixPath(name)
    file = open_contained(directory, name) if parts.suffix == ".png" and parts.parts[:1] == ("val",) else None
    if file is None:
        abort(404, f"run {run_id} has no validation image {name!r}")
    return send_opened(file, parts.name, mimetype="image/png", max_age=3600)


@bp.get("/models/runs/<int:run_id>/log")
@requires(Role.curator)
def run_log(run_id: int) -> ResponseReturnValue:
    """The tail of rank 0's log (``?lines=200``, at most 2000), its server folders rewritten out
    (``dataset/redact.py``)."""
    training.get_run(g.db, run_id)
    count = int_arg("lines", 200, minimum=1, maximum=2000)
    tail = run_logs.tail(training.run_dir(runtime().settings.runs_dir, run_id), count)
    redact = app_redactor()
    return {"run": run_id, **tail, "lines": [redact(line) for line in tail["lines"]]}


@bp.get("/models/runs/<int:run_id>/log.txt")
@requires(Role.curator)
def run_log_file(run_id: int) -> ResponseReturnValue:
    """The whole of rank 0's log as a text file to download (every launch of the run, oldest first),
    streamed, so its server folders are rewritten here, line by line."""
    training.get_run(g.db, run_id)
    settings = runtime().settings
    directory = training.run_dir(settings.runs_dir, run_id)
    if not run_logs.rank0_files(directory):
        abort(404, f"run {run_id} has no log yet: its trainers have not started")
    redact = app_redactor()
    lines = (redact(line).encode() for line in run_logs.log_lines(directory))
    return Response(lines, mimetype="text/plain",
                    headers={"Content-Disposition": f'attachment; filename="run{run_id}_rank0.log"',
                             "Cache-Control": "no-store"})
