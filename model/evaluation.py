"""The ``evaluate`` job: parameters, which samples (a dataset folder, or a training run's held-out
test split of the database), which methods, and the report folder it writes."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from dataset.db import transaction
from dataset.formats import read_pfm
from dataset.readers import READER_FORMATS, StereoSample, open_reader, resize_sample
from dataset.readers.version import VersionReader
from dataset.services import evaluations
from dataset.services.jobs import JobContext
from model.align import ALIGN_RULES
from model.evaluate import DEFAULT_THRESHOLDS, RESOLUTIONS, EvalOptions, evaluate, iter_reader
from model.methods import NETWORK_METHODS, Mono, NetworkRuns, SgbmParams, build_methods, method_key
from model.report import PredictionWriter, ranked_samples, write_pictures, write_report

DEFAULT_METHODS = ("fusion", "stereo", "mono_gt_align", "sgbm")
PICTURED = 3  # worst and best samples shown with pictures


def run_of_checkpoint(checkpoint: Path) -> Path | None:
    """The training run folder a checkpoint belongs to (``RUN_DIR/checkpoints/x.pt``), if any."""
    run_dir = checkpoint.resolve().parent.parent
    return run_dir if (run_dir / "run.json").is_file() else None


def evaluation_params(*, data: str | Path | None, format: str | None, methods: list[str],
                      out: str | Path | None = None,
                      checkpoint: str | Path | None = None, predictions: str | Path | None = None,
                      mono: str | Path | None = None, resolution: str | None = None, align: str = "lsq",
                      max_disparity: int | None = None, kitti_png: bool = False, iters: int | None = None,
                      thresholds: tuple[float, ...] = DEFAULT_THRESHOLDS, run_dir: str | Path | None = None,
                      reader_options: dict[str, Any] | None = None) -> dict[str, Any]:
    """Validated parameters of an ``evaluate`` job; ValueError with a one-line reason.

    Without ``data`` the samples are the held-out test split of the training run ``run_dir`` (or of
    the run ``checkpoint`` belongs to) — samples its training never read. Without ``out`` the
    report goes to ``<data dir>/evaluations/<job id>``.
    """
    keys = [method_key(m) for m in methods] or list(DEFAULT_METHODS)
    if len(set(keys)) != len(keys):
        raise ValueError("a method is named twice")
    if any(k in NETWORK_METHODS for k in keys) and checkpoint is None:
        raise ValueError("fusion, stereo and mono-align need --checkpoint (or a promoted current model)")
    if checkpoint is not None and not Path(checkpoint).is_file():
        raise ValueError(f"checkpoint {checkpoint} does not exist")
    if "predictions" in keys and (predictions is None or not Path(predictions).is_dir()):
        raise ValueError("the predictions method needs --predictions DIR (an existing folder)")
    if mono is not None and not Path(mono).is_dir():
        raise ValueError(f"--mono {mono} is not a folder")
    if align not in ALIGN_RULES:
        raise ValueError(f"--align must be one of {', '.join(ALIGN_RULES)}")
    if data is not None:
        if format not in READER_FORMATS:
            raise ValueError(f"--format must be one of {', '.join(READER_FORMATS)}")
        if not Path(data).is_dir():
            raise ValueError(f"--data {data} is not a folder")
    else:
        run_dir = Path(run_dir) if run_dir else (run_of_checkpoint(Path(checkpoint)) if checkpoint else None)
        if run_dir is None or not (Path(run_dir) / "run.json").is_file():
            raise ValueError("without --data, evaluation uses a training run's test split: pass --run RUN, "
                             "a checkpoint of a run, or promote a run")
    resolution = resolution or ("quarter" if format == "booster" else "full")
    if resolution not in RESOLUTIONS:
        raise ValueError(f"--resolution must be one of {', '.join(RESOLUTIONS)}")
    if max_disparity is not None and max_disparity <= 0:
        raise ValueError("--max-disparity must be positive")
    absolute = lambda p: str(Path(p).absolute()) if p is not None else None
    return {"data": absolute(data), "format": format if data is not None else "database",
            "methods": keys, "out": absolute(out), "checkpoint": absolute(checkpoint),
            "predictions": absolute(predictions), "mono": absolute(mono), "resolution": resolution,
            "align": align, "max_disparity": max_disparity, "kitti_png": bool(kitti_png), "iters": iters,
            "thresholds": [float(t) for t in thresholds], "run_dir": absolute(run_dir),
            "reader_options": dict(reader_options or {})}


def open_samples(params: dict[str, Any], media_root: Path) -> Any:
    """The reader the parameters name: a dataset folder, or a run's test split of the database."""
    if params["data"] is not None:
        return open_reader(params["format"], Path(params["data"]), **params["reader_options"])
    run = json.loads((Path(params["run_dir"]) / "run.json").read_text())
    test_ids = run["splits"].get("test", [])
    if not test_ids:
        raise ValueError(f"run {params['run_dir']} has an empty test split")
    return VersionReader(run["dataset"], media_root, sample_ids=test_ids)


def evaluate_job(ctx: JobContext) -> dict[str, Any]:
    """Job ``evaluate`` (params from :func:`evaluation_params`): writes the report folder, returns
    the headline table (per method and region: EPE, bad-2) and where the report is. The job's
    ``evaluations`` row gets that summary and, for database samples, per-sample results."""
    p = ctx.params
    out = Path(p["out"]) if p["out"] else Path(ctx.settings.home) / "evaluations" / str(ctx.job_id)
    with transaction(ctx.sessions) as s:
        evaluation_id = evaluations.evaluation_for_job(s, ctx.job_id, p).id
    reader = open_samples(p, ctx.settings.media_root)
    ctx.log(f"{len(reader)} samples ({p['format']}), methods {', '.join(p['methods'])}, {p['resolution']} resolution")
    mono_dir = Path(p["mono"]) if p["mono"] else None
    runs = (NetworkRuns(Path(p["checkpoint"]), ctx.settings.device, Mono(mono_dir), p["iters"])
            if p["checkpoint"] and any(m in NETWORK_METHODS for m in p["methods"]) else None)
    methods = build_methods(
        p["methods"], checkpoint=Path(p["checkpoint"]) if p["checkpoint"] else None,
        predictions=Path(p["predictions"]) if p["predictions"] else None, mono_dir=mono_dir, align_rule=p["align"],
        sgbm=SgbmParams(max_disparity=p["max_disparity"]), device=ctx.settings.device, iters=p["iters"], runs=runs)
    writer = PredictionWriter(out, kitti_png=p["kitti_png"])
    seen = SeenSamples(writer, runs)
    report = evaluate(
        iter_reader(reader), methods,
        EvalOptions(resolution=p["resolution"], thresholds=tuple(p["thresholds"])),
        total=len(reader), dataset=p["data"] or f"test split of {p['run_dir']}",
        on_progress=lambda i, n: ctx.progress(0.95 * i / n),
        on_prediction=seen, on_failure=lambda s, m, why: ctx.log(f"skipped {s} {m}: {why}"))
    report["params"] = {k: p[k] for k in ("format", "checkpoint", "align", "max_disparity", "iters", "run_dir")}
    if "sgbm" in p["methods"]:
        report["sgbm"] = SgbmParams(max_disparity=p["max_disparity"]).__dict__
    pictures = _pictures(out, reader, report, writer)
    write_report(out, report, pictures)
    result = {"out": str(out), "evaluation": evaluation_id, "samples": report["samples"],
              "failed": len(report["failed"]), "pictures": pictures,
              "headline": {m: {r: {k: d["regions"][r].get(k) for k in ("epe", "bad2")} for r in d["regions"]}
                           for m, d in report["methods"].items()}}
    with transaction(ctx.sessions) as s:
        evaluation = evaluations.get_evaluation(s, evaluation_id)
        rows = evaluations.record_results(s, evaluation, report, result, out, seen.sample_ids, seen.predictions)
        evaluation.summary = {**result, "database_rows": rows}
    ctx.progress(1.0, f"report in {out}/index.html; {len(report['failed'])} failures; {rows} database results")
    return result


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
    return str(Path(str(sample.meta.get("left") or sample.name)).with_suffix(".pfm"))


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
