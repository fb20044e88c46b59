"""The Evaluation pages (curators and admins): the launch form and the list, one report (the
paper-style table, sortable per-sample metrics, the worst and best samples), and one evaluated
database sample — the method's prediction, error map and confidence beside its ground truth.

Launching goes through the API (``POST /api/v1/evaluations``); report files are served by the
API's file route, confined to the report folder.
"""

from __future__ import annotations

import json
from io import BytesIO

import numpy as np
from flask import Blueprint, abort, g, render_template, request, send_file
from flask.typing import ResponseReturnValue

from core.formats import decode_pfm
from core.wording import quoted
from dataset.preview.evaluation_maps import EVALUATION_IMAGES, evaluation_image
from dataset.preview.images import encode_png
from dataset.readers import READER_FORMATS
from dataset.readers.base import resize_disparity
from dataset.samples import load_output
from dataset.services import evaluations, sample_review, training
from dataset.services.errors import NotFound
from dataset.tables import Evaluation, Role, Sample
from model.align import ALIGN_RULES
from model.evaluate import RESOLUTIONS
from model.methods import BASELINE_METHODS, METHODS
from model.runs import registry
from model.runs.evaluation import DEFAULT_METHODS
from model.runs.report import DEPTH_METRICS, TABLE_METRICS
from webapp.auth import requires
from webapp.redact import app_redactor
from webapp.runtime import runtime

bp = Blueprint("evaluations", __name__)


@bp.get("/evaluations")
@requires(Role.curator)
def index() -> ResponseReturnValue:
    """The launch form and every evaluation with its state and progress (live, from the API)."""
    settings = runtime().settings
    runs = [run_id for run_id, _ in training.recent_runs(g.db, 200)]
    return render_template("evaluations.html", formats=READER_FORMATS, methods=METHODS, default_methods=DEFAULT_METHODS,
                           baselines=BASELINE_METHODS, resolutions=list(RESOLUTIONS), align_rules=ALIGN_RULES, runs=runs,
                           current=registry.current_model(settings), roots=sorted(settings.dataset_roots),
                           checkpoints=registry.named_checkpoints(g.db, settings.runs_dir),
                           imported=[f"{registry.IMPORTED}:{n}" for n in registry.imported_names(settings.home)])


@bp.get("/evaluations/<int:evaluation_id>")
@requires(Role.curator)
def report(evaluation_id: int) -> ResponseReturnValue:
    """The report, from its ``report.json``."""
    evaluation = evaluations.get_evaluation(g.db, evaluation_id)
    try:  # written by the job, which may quote server paths (a sample's failure)
        data = app_redactor().value(json.loads(_report_bytes(evaluation, "report.json")))
    except NotFound:
        data = None
    regions: list[str] = []
    has_depth = False
    for method in (data or {}).get("methods", {}).values():
        regions += [r for r in method["regions"] if r not in regions]
        has_depth = has_depth or any("abs_rel" in f for f in method["regions"].values())
    return render_template("evaluation.html", evaluation=evaluations.evaluation_json(evaluation), report=data,
                           regions=regions, metrics=TABLE_METRICS + (DEPTH_METRICS if has_depth else ()),
                           pictures=evaluation.summary.get("pictures", {}))


@bp.get("/evaluations/<int:evaluation_id>/samples/<int:sample_id>")
@requires(Role.curator)
def sample(evaluation_id: int, sample_id: int) -> ResponseReturnValue:
    """One database sample of the evaluation: ground truth, prediction, error and confidence."""
    evaluation = evaluations.get_evaluation(g.db, evaluation_id)
    method = request.args.get("method") or evaluations.default_method(evaluation)
    result = evaluations.sample_result(g.db, evaluation_id, sample_id, method)
    return render_template("evaluation_sample.html", evaluation=evaluations.evaluation_json(evaluation),
                           sample=sample_review.get_sample(g.db, sample_id), method=method, result=result,
                           has_confidence=_has_confidence(evaluation, result.prediction))


@bp.get("/evaluations/<int:evaluation_id>/samples/<int:sample_id>/<method>/<image>.png")
@requires(Role.curator)
def sample_image(evaluation_id: int, sample_id: int, method: str, image: str) -> ResponseReturnValue:
    """``image`` in gt, prediction, error, confidence, coloured at the evaluation's resolution."""
    if image not in EVALUATION_IMAGES:
        abort(404, f"no {quoted(image)} picture; choose from {', '.join(EVALUATION_IMAGES)}")
    evaluation = evaluations.get_evaluation(g.db, evaluation_id)
    result = evaluations.sample_result(g.db, evaluation_id, sample_id, method)
    if not result.prediction:
        abort(404, f"evaluation {evaluation_id} kept no {method} prediction of sample {sample_id}")
    name = f"predictions/{method}/{result.prediction}"
    prediction = decode_pfm(_report_bytes(evaluation, name), name)
    confidence = _confidence(evaluation, result.prediction) if image == "confidence" else None
    row = g.db.get(Sample, sample_id)
    gt = load_output(runtime().media, row.files["disparity"], "disparity")
    if "valid" in row.files:
        gt = np.where(load_output(runtime().media, row.files["valid"], "valid"), gt, np.nan).astype(np.float32)
    gt = gt if gt.shape == prediction.shape else resize_disparity(gt, prediction.shape)
    try:
        rgb = evaluation_image(image, gt, prediction, confidence)
    except KeyError:
        abort(404, f"evaluation {evaluation_id} has no {image} of sample {sample_id}")
    return send_file(BytesIO(encode_png(rgb)), mimetype="image/png", max_age=0)


def _report_bytes(evaluation: Evaluation, name: str) -> bytes:
    """A report file's bytes, read from the file the checks opened (never its path again)."""
    with evaluations.open_report_file(evaluation, name, runtime().settings.home) as file:
        return file.read()


def _confidence(evaluation: Evaluation, prediction: str) -> np.ndarray | None:
    """The confidence map kept beside ``prediction``, or None when the method kept none."""
    name = f"predictions/confidence/{prediction}"
    try:
        return decode_pfm(_report_bytes(evaluation, name), name)
    except NotFound:
        return None


def _has_confidence(evaluation: Evaluation, prediction: str | None) -> bool:
    if not prediction:
        return False
    try:
        evaluations.open_report_file(evaluation, f"predictions/confidence/{prediction}", runtime().settings.home).close()
    except NotFound:
        return False
    return True
