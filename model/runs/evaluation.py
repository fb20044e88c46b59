"""The ``evaluate`` job: parameters, which samples (a dataset folder, or a training run's held-out
test split of the database), which methods, and the report folder it writes."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy.orm import Session

from core.formats import read_pfm
from dataset.contained import storage_root
from dataset.db import transaction
from dataset.readers import StereoSample, open_reader, resize_sample
from dataset.readers.version import VersionReader
from dataset.run_layout import CHECKPOINT_DIR, RUN_FILE
from dataset.services import evaluations, training
from dataset.services.dataset_roots import resolve_folder
from dataset.services.errors import InvalidInput, NotFound
from dataset.services.evaluations import checkpoint_label, dataset_label
from dataset.services.jobs import JobContext
from model.evaluate import DEFAULT_THRESHOLDS, RESOLUTIONS, EvalOptions, evaluate, iter_reader
from model.methods import BASELINE_METHODS, NETWORK_METHODS, Mono, NetworkRuns, SgbmParams, build_methods, relative_pfm
from model.runs import registry
from model.runs.report import PredictionWriter, ranked_samples, write_pictures, write_report
from model.runs.schema import EvaluationLaunch, FieldError, FolderRef, checkpoint_text

DEFAULT_METHODS = ("fusion", "stereo", "mono_gt_align", "sgbm")
PICTURED = 3  # worst and best samples shown with pictures


@dataclass(frozen=True)
class EvalShellOptions:
    """What only the command line may add to an evaluation (its user has a shell): server paths."""

    data_dir: Path | None = None
    data_format: str | None = None
    checkpoint: Path | None = None
    checkpoints: dict[str, Path] = field(default_factory=dict)  # a file per network method (report key)
    predictions: Path | None = None
    mono: Path | None = None
    out: Path | None = None
    reader_options: dict[str, Any] = field(default_factory=dict)
    thresholds: tuple[float, ...] = DEFAULT_THRESHOLDS


def evaluation_params(request: EvaluationLaunch, settings: Any, session: Session,
                      shell: EvalShellOptions | None = None) -> dict[str, Any]:
    """The ``evaluate`` job's parameters from a validated launch; FieldError naming the field.

    Names stay names (``{"run", "file", "step"}`` for a checkpoint, ``{"root", "path"}`` for a
    folder in a registered dataset root), resolved again when the job runs; only the command line
    puts paths (``{"dir"}``, ``{"path"}``) here. A checkpoint named ``best`` or ``last`` is pinned
    to the step it resolves to now, kept from rotation, so it cannot change or vanish while the job
    waits. Without a dataset folder the samples are the held-out test split of ``run`` (default:
    the checkpoint's run) — samples its training never read.
    """
    shell = shell or EvalShellOptions()
    for method, baseline in BASELINE_METHODS.items():
        if method in request.methods and method not in request.checkpoints | shell.checkpoints:
            raise FieldError("checkpoints", f"{baseline.architecture} needs its own checkpoint, e.g. {baseline.example}")
    source = _checkpoint_source(request, settings, session, shell)
    own = {m: _method_source(request, m, settings, session, shell) for m in request.methods
           if m in request.checkpoints or m in shell.checkpoints}
    data = _folder_param(request.data, shell.data_dir, settings, "data")
    run = request.run
    if data is None:
        run = run or source.get("run")
        if run is None:
            raise FieldError("run", "choose a run whose held-out test split to evaluate on, or a dataset folder")
        _test_split(settings, session, run)
    if "predictions" in request.methods and request.predictions is None and shell.predictions is None:
        raise FieldError("predictions", "the predictions method needs a predictions folder")
    resolution = request.resolution or ("quarter" if (request.data and request.data.format == "booster")
                                        or shell.data_format == "booster" else "full")
    params = {"data": data, "format": (request.data.format if request.data else shell.data_format) if data else "database",
              "methods": list(request.methods), "out": str(shell.out.resolve()) if shell.out else None, "run": run,
              "predictions": _folder_param(request.predictions, shell.predictions, settings, "predictions"),
              "mono": _folder_param(request.mono, shell.mono, settings, "mono"), "resolution": resolution,
              "align": request.align, "max_disparity": request.max_disparity, "kitti_png": request.kitti_png,
              "iters": request.iters, "thresholds": [float(t) for t in shell.thresholds],
              "reader_options": dict(shell.reader_options)}
    # Pinned last, once nothing else can refuse the launch: a refused one leaves no pin behind.
    return {**params, "checkpoint": _pinned(source, "checkpoint") or None,
            "checkpoints": {m: _pinned(ref, "checkpoints") for m, ref in own.items()}}


def _pinned(source: dict[str, Any], field_name: str) -> dict[str, Any]:
    """A checkpoint source with a run's file pinned (kept from rotation) and named by run, file and step."""
    found = source.get("file")
    if not isinstance(found, registry.CheckpointFile):
        return source
    try:
        pinned = registry.pin(found)
    except ValueError as exc:
        raise FieldError(field_name, str(exc)) from None
    return {"run": pinned.run, "file": pinned.name, "step": pinned.step}


def _method_source(request: EvaluationLaunch, method: str, settings: Any, session: Session,
                   shell: EvalShellOptions) -> dict[str, Any]:
    """The checkpoint of one network method that names its own (the command line's file, or a name)."""
    if method in shell.checkpoints:
        return _outside(shell.checkpoints[method], settings)
    return _named_source(request.checkpoints[method], settings, session, "checkpoints")


def _named_source(name: str, settings: Any, session: Session, field_name: str) -> dict[str, Any]:
    """A checkpoint a request names (:func:`model.runs.registry.resolve`): ``{"run", "file": CheckpointFile}``
    for a run's, ``{"name", "path"}`` for an imported one (its "path" is the name too: answers show
    it, and it is no server path)."""
    try:
        found = registry.resolve(settings, name)
        if found.run is None:
            return {"name": found.name, "path": found.name}
        run = training.get_run(session, found.run)
        file = registry.run_checkpoint(settings.runs_dir, run.id, name.split(":", 1)[1], best_step=run.best_step)
    except (NotFound, InvalidInput) as exc:
        raise FieldError(field_name, str(exc)) from None
    return {"run": file.run, "file": file}


def _checkpoint_source(request: EvaluationLaunch, settings: Any, session: Session,
                       shell: EvalShellOptions) -> dict[str, Any]:
    """Which checkpoint the network methods without their own use, not yet pinned: ``{"run", "file":
    CheckpointFile}`` for a run's, ``{"name", "path"}`` for an imported one, ``{"path"}`` (and its
    ``run`` when it lies in one) for the command line's or an outside current model; ``{}`` when no
    method needs one."""
    if not any(m in NETWORK_METHODS and m not in request.checkpoints and m not in shell.checkpoints
               for m in request.methods):
        return {}
    if shell.checkpoint is not None:
        return _outside(shell.checkpoint, settings)
    if request.checkpoint is not None:
        return _named_source(checkpoint_text(request.checkpoint), settings, session, "checkpoint")
    current = registry.current_reference(settings)
    if current is None:
        outside = registry.current_checkpoint(settings)
        if outside is None:
            raise FieldError("checkpoint", "fusion, stereo and mono-align need a checkpoint: name a run's, "
                                           "or promote a run to the current model")
        return _outside(outside, settings)
    run_id, which = current
    try:
        run = training.get_run(session, run_id)
        found = registry.run_checkpoint(settings.runs_dir, run.id, which, best_step=run.best_step)
    except NotFound as exc:
        raise FieldError("checkpoint", str(exc)) from None
    return {"run": found.run, "file": found}


def _outside(path: Path, settings: Any) -> dict[str, Any]:
    """A checkpoint file given by path; its run when it is one of a run's (``runs/<id>/checkpoints/``)."""
    path = Path(path).resolve()
    ref: dict[str, Any] = {"path": str(path)}
    run_dir = path.parent.parent
    if path.parent.name == CHECKPOINT_DIR and run_dir.parent == storage_root(settings.runs_dir) \
            and run_dir.name.isdigit():
        ref["run"] = int(run_dir.name)
    return ref


def _folder_param(ref: FolderRef | None, path: Path | None, settings: Any, field_name: str) -> dict[str, str] | None:
    if ref is not None:
        try:
            resolve_folder(settings.dataset_roots, ref.root, ref.path)
        except InvalidInput as exc:
            raise FieldError(field_name, str(exc)) from None
        return {"root": ref.root, "path": ref.path}
    return {"dir": str(path.resolve())} if path is not None else None


def _test_split(settings: Any, session: Session, run_id: int) -> None:
    """FieldError unless the run exists and holds a held-out test split to evaluate on."""
    try:
        training.get_run(session, run_id)
        training.test_split(settings.runs_dir, run_id)
    except (NotFound, InvalidInput) as exc:
        raise FieldError("run", str(exc)) from None


def folder_of(ref: dict[str, str] | None, settings: Any) -> Path | None:
    """A folder parameter's path on this machine (a registered root's folder is resolved again)."""
    if ref is None:
        return None
    if "dir" in ref:
        return Path(ref["dir"])
    return resolve_folder(settings.dataset_roots, ref["root"], ref.get("path", ""))


def checkpoint_of(ref: dict[str, Any] | None, settings: Any) -> Path | None:
    """A checkpoint parameter's file: a run's checkpoint by name (never a link), or the command line's path."""
    if ref is None:
        return None
    if "name" in ref:
        return registry.resolve(settings, ref["name"]).path
    if "path" in ref:
        return Path(ref["path"])
    return registry.run_checkpoint(settings.runs_dir, int(ref["run"]), ref["file"], best_step=ref.get("step")).path


def open_samples(params: dict[str, Any], settings: Any) -> Any:
    """The reader the parameters name: a dataset folder, or a run's test split of the database."""
    folder = folder_of(params["data"], settings)
    if folder is not None:
        return open_reader(params["format"], folder, **params["reader_options"])
    run = json.loads((training.run_dir(settings.runs_dir, int(params["run"])) / RUN_FILE).read_text())
    test_ids = training.test_split(settings.runs_dir, int(params["run"]))
    return VersionReader(run["dataset"], settings.media_root, sample_ids=test_ids)


def report_dir(params: dict[str, Any], settings: Any, job_id: int, *, writing: bool = False) -> Path:
    """Where an evaluate job writes its report: the command line's ``--out`` (its user's choice), else
    the workspace's ``evaluations/<job id>``, which refuses links (``writing``: anywhere inside it too)."""
    return Path(params["out"]) if params["out"] else evaluations.report_folder(settings.home, job_id, writing=writing)


def evaluate_job(ctx: JobContext) -> dict[str, Any]:
    """Job ``evaluate`` (params from :func:`evaluation_params`): writes the report folder, returns
    the headline table (per method and region: EPE, bad-2) and where the report is. The job's
    ``evaluations`` row gets that summary and, for database samples, per-sample results."""
    p, settings = ctx.params, ctx.settings
    out = report_dir(p, settings, ctx.job_id, writing=True)
    with transaction(ctx.sessions) as s:
        evaluation_id = evaluations.evaluation_for_job(s, ctx.job_id, p).id
    reader = open_samples(p, settings)
    label = dataset_label(p)
    ctx.log(f"{len(reader)} samples of {label} ({p['format']}), methods {', '.join(p['methods'])}, "
            f"{p['resolution']} resolution")
    mono_dir, checkpoint = folder_of(p["mono"], settings), checkpoint_of(p["checkpoint"], settings)
    own = p.get("checkpoints") or {}  # evaluations of earlier releases have one checkpoint for all
    paths = {m: checkpoint_of(ref, settings) for m, ref in own.items()}
    runs = (NetworkRuns(checkpoint, settings.device, Mono(mono_dir), p["iters"], label=checkpoint_label(p["checkpoint"]))
            if checkpoint and any(m in NETWORK_METHODS and m not in own for m in p["methods"]) else None)
    methods = build_methods(
        p["methods"], checkpoint=checkpoint, predictions=folder_of(p["predictions"], settings), mono_dir=mono_dir,
        align_rule=p["align"], sgbm=SgbmParams(max_disparity=p["max_disparity"]), device=settings.device,
        iters=p["iters"], runs=runs, checkpoints=paths,
        labels={str(paths[m]): checkpoint_label(ref) or m for m, ref in own.items()})
    writer = PredictionWriter(out, kitti_png=p["kitti_png"])
    seen = SeenSamples(writer, runs)
    report = evaluate(
        iter_reader(reader), methods,
        EvalOptions(resolution=p["resolution"], thresholds=tuple(p["thresholds"])),
        total=len(reader), dataset=label,
        on_progress=lambda i, n: ctx.progress(0.95 * i / n),
        on_prediction=seen, on_failure=lambda s, m, why: ctx.log(f"skipped {s} {m}: {why}"))
    report["params"] = {"format": p["format"], "checkpoint": checkpoint_label(p["checkpoint"]),
                        "checkpoints": {m: checkpoint_label(ref) for m, ref in own.items()}, "align": p["align"],
                        "max_disparity": p["max_disparity"], "iters": p["iters"], "run": p["run"]}
    if "sgbm" in p["methods"]:
        report["sgbm"] = SgbmParams(max_disparity=p["max_disparity"]).__dict__
    pictures = _pictures(out, reader, report, writer)
    write_report(out, report, pictures, writer.labels)
    shown = _shown_path(out, settings)
    result = {"out": shown, "evaluation": evaluation_id, "samples": report["samples"],
              "failed": len(report["failed"]), "pictures": pictures,
              "headline": {m: {r: {k: d["regions"][r].get(k) for k in ("epe", "bad2")} for r in d["regions"]}
                           for m, d in report["methods"].items()}}
    with transaction(ctx.sessions) as s:
        evaluation = evaluations.get_evaluation(s, evaluation_id)
        rows = evaluations.record_results(s, evaluation, report, result, out, seen.sample_ids, seen.predictions)
        evaluation.summary = {**result, "database_rows": rows}
    ctx.progress(1.0, f"report in {shown}/index.html; {len(report['failed'])} failures; {rows} database results")
    return result


def _shown_path(path: Path, settings: Any) -> str:
    """A path as answers show it: relative to the workspace, else the folder's name."""
    home = Path(settings.home).resolve()
    path = path.resolve()
    return str(path.relative_to(home)) if path.is_relative_to(home) else path.name


class SeenSamples:
    """The evaluation's prediction callback: writes each prediction (and, for ``fusion``, its
    confidence as ``predictions/confidence/…``) and remembers each sample's database id and
    prediction path for the per-sample results."""

    def __init__(self, writer: PredictionWriter, runs: NetworkRuns | None) -> None:
        self.writer, self.runs = writer, runs
        self.sample_ids: dict[str, int] = {}
        self.predictions: dict[str, str] = {}

    def __call__(self, method: str, sample: StereoSample, pred: np.ndarray) -> None:
        self.writer(method, sample, pred)
        if method == "fusion" and self.runs is not None:
            # The forward pass of this sample is cached: reading its confidence costs nothing.
            self.writer("confidence", sample, self.runs(sample).confidence)
        if "sample_id" in sample.meta:
            self.sample_ids[sample.name] = int(sample.meta["sample_id"])
        self.predictions[sample.name] = prediction_rel_path(sample)


def prediction_rel_path(sample: StereoSample) -> str:
    """Where :class:`PredictionWriter` puts a sample's prediction under ``predictions/<method>/``."""
    return str(relative_pfm(sample))


def _pictures(out: Path, reader: Any, report: dict[str, Any], writer: PredictionWriter) -> dict[str, list[str]]:
    """Pictures of the worst and best samples of the first method, beside every method's prediction."""
    methods = [m for m in report["methods"] if report["methods"][m]["per_sample"]]
    if not methods:
        return {}
    worst, best = ranked_samples(report, methods[0], count=PICTURED)
    index = {name: i for i, name in enumerate(reader.names)}
    pictures = {}
    for label, names in (("worst", worst), ("best", best)):
        for name in names:
            sample = reader[index[name]]
            factor = RESOLUTIONS[report["resolution"]]
            sample = sample if factor == 1.0 else resize_sample(sample, factor)
            rel = prediction_rel_path(sample)
            preds = {m: read_pfm(writer.out_dir / "predictions" / m / rel) for m in methods
                     if (writer.out_dir / "predictions" / m / rel).is_file()}
            pictures[f"{label}: {name}"] = write_pictures(out, sample, preds)
    return pictures
