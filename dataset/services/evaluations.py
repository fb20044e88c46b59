"""Evaluations in the database: one row per evaluate job, and per database sample and method its
figures, so the Samples pages can sort and filter by an evaluation's error.

The job computes the report (``model.runs.evaluation``) into the workspace's ``evaluations/<job id>``
(or, from the command line, a folder of its choice); this module stores it and reads it back, from the
workspace's folder only.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, BinaryIO

from sqlalchemy import delete, func, select
from sqlalchemy.orm import Session

from core.wording import quoted
from dataset.contained import REPORTS, contained_file, open_contained, owned_folder
from dataset.redact import redacted
from dataset.services.dataset_roots import folder_label
from dataset.services.errors import InvalidInput, NotFound
from dataset.services.sample_review import sample_json
from dataset.tables import Evaluation, EvaluationResult, Frame, Sample, User, Video

SORT_REGIONS = ("all", "illusion")  # the regions with indexed columns
SORT_METRICS = ("epe", "bad2")


def evaluation_for_job(session: Session, job_id: int, params: dict[str, Any], user: User | None = None) -> Evaluation:
    """The job's evaluation row, created on first call (a retried job keeps its row)."""
    row = session.scalar(select(Evaluation).where(Evaluation.job_id == job_id))
    if row is None:
        row = Evaluation(job_id=job_id, params=params, dataset=dataset_label(params),
                         created_by_id=user.id if user else None)
        session.add(row)
        session.flush()
    return row


def dataset_label(params: dict[str, Any]) -> str:
    """How answers name what an evaluation scores (``model.runs.evaluation``'s parameters): a folder in a
    registered root (``root:path``), a command-line folder by its name, or a run's test split."""
    data = params.get("data")
    if data is None:
        return f"test split of run {params.get('run') or Path(str(params.get('run_dir'))).name}"
    if isinstance(data, str):  # an evaluation of an earlier release: a path
        return Path(data).name
    return folder_label(data["root"], data.get("path", "")) if "root" in data else Path(data["dir"]).name


def _checkpoint_step(ref: Any) -> int | None:
    return ref.get("step") if isinstance(ref, dict) else None


def checkpoint_label(ref: dict[str, Any] | None) -> str | None:
    """How answers name an evaluation's checkpoint: run, file and step, never a path."""
    if ref is None:
        return None
    if isinstance(ref, str):  # an evaluation of an earlier release: a path
        return Path(ref).name
    if "path" in ref:
        return Path(ref["path"]).name
    step = f", step {ref['step']}" if ref.get("step") is not None else ""
    return f"run {ref['run']} · {ref['file']}{step}"


def _finite(value: Any) -> float | None:
    return float(value) if isinstance(value, int | float) and math.isfinite(value) else None


def record_results(session: Session, evaluation: Evaluation, report: dict[str, Any], summary: dict[str, Any],
                   report_dir: Path, sample_ids: dict[str, int], predictions: dict[str, str]) -> int:
    """Store the summary and, for each (method, database sample), its figures; replaces an earlier
    attempt's rows. ``sample_ids``: sample name → database id (folder samples have none and are
    skipped); ``predictions``: sample name → the prediction's path under ``predictions/<method>/``.
    Returns how many result rows were written."""
    evaluation.summary, evaluation.report_dir = summary, str(report_dir)
    session.execute(delete(EvaluationResult).where(EvaluationResult.evaluation_id == evaluation.id))
    rows = []
    for method, data in report["methods"].items():
        for row in data["per_sample"]:
            sample_id = sample_ids.get(row["sample"])
            if sample_id is None:
                continue
            regions = row["regions"]
            rows.append(EvaluationResult(
                evaluation_id=evaluation.id, sample_id=sample_id, method=method, regions=_clean(regions),
                prediction=predictions.get(row["sample"]),
                epe_all=_finite(regions.get("all", {}).get("epe")), bad2_all=_finite(regions.get("all", {}).get("bad2")),
                epe_illusion=_finite(regions.get("illusion", {}).get("epe")),
                bad2_illusion=_finite(regions.get("illusion", {}).get("bad2"))))
    session.add_all(rows)
    session.flush()
    return len(rows)


def _clean(regions: dict[str, dict[str, Any]]) -> dict[str, dict[str, float | None]]:
    """JSON columns hold no NaN: an empty region's figures become null."""
    return {r: {k: _finite(v) for k, v in figures.items()} for r, figures in regions.items()}


def evaluation_json(evaluation: Evaluation) -> dict[str, Any]:
    job = evaluation.job
    return {"id": evaluation.id, "job": evaluation.job_id, "state": job.state.value if job else "unknown",
            "progress": job.progress if job else None, "error": redacted(job.error) if job else None,
            "created_by": evaluation.created_by.name if evaluation.created_by else None,
            "created_at": evaluation.created_at.isoformat() + "Z", "dataset": evaluation.dataset,
            "format": evaluation.params.get("format"), "methods": evaluation.params.get("methods", []),
            "resolution": evaluation.params.get("resolution"),
            "checkpoint": checkpoint_label(evaluation.params.get("checkpoint")),
            "run": evaluation.params.get("run"), "step": _checkpoint_step(evaluation.params.get("checkpoint")),
            "summary": evaluation.summary,
            "has_results": evaluation.summary.get("database_rows", 0) > 0}


def list_evaluations(session: Session, limit: int = 100) -> list[dict[str, Any]]:
    """The newest evaluations first, with their job's state and progress."""
    rows = session.scalars(select(Evaluation).order_by(Evaluation.id.desc()).limit(limit))
    return [evaluation_json(e) for e in rows]


def get_evaluation(session: Session, evaluation_id: int) -> Evaluation:
    row = session.get(Evaluation, evaluation_id)
    if row is None:
        raise NotFound(f"no evaluation {evaluation_id}")
    return row


def reports_dir(home: Path) -> Path:
    """The workspace's ``evaluations/`` (it may be an admin's link to shared storage)."""
    return Path(home) / REPORTS


def report_folder(home: Path, job_id: int, *, writing: bool = False) -> Path:
    """The workspace's report folder of evaluate job ``job_id``, ``evaluations/<job id>``: LinkedFolder
    when it is a symbolic link or, ``writing``, when anything inside it is (see ``dataset.contained``)."""
    return owned_folder(reports_dir(home), str(job_id), whole=writing)


def report_file(evaluation: Evaluation, name: str, home: Path) -> Path:
    """A file of the evaluation's report folder by its relative path; never a path outside it, never a
    link, and only from the workspace's ``evaluations/`` (a command line's ``--out`` is not served)."""
    if not evaluation.report_dir or evaluation.job_id is None:
        raise NotFound(f"evaluation {evaluation.id} has no report yet")
    folder = report_folder(home, evaluation.job_id)
    # Stored as written: under the resolved evaluations/ (or, by earlier releases, the workspace's path).
    if Path(evaluation.report_dir) not in (folder, reports_dir(home) / str(evaluation.job_id)):
        raise NotFound(f"evaluation {evaluation.id} wrote its report outside the workspace (evaluate --out); "
                       f"the web serves reports under {REPORTS}/ only")
    path = contained_file(folder, name)
    if path is None:
        raise NotFound(f"evaluation {evaluation.id} has no report file {quoted(name)}")
    return path


def open_report_file(evaluation: Evaluation, name: str, home: Path) -> BinaryIO:
    """A file of the evaluation's report folder, opened without following any link (what to serve
    or read, never its path again); NotFound as :func:`report_file` says."""
    if evaluation.job_id is None:
        raise NotFound(f"evaluation {evaluation.id} has no report yet")
    report_file(evaluation, name, home)  # the report's own checks, and their reasons
    file = open_contained(report_folder(home, evaluation.job_id), name)
    if file is None:  # swapped for something else since the check
        raise NotFound(f"evaluation {evaluation.id} has no report file {quoted(name)}")
    return file


def _sort_column(region: str, metric: str) -> Any:
    if region not in SORT_REGIONS or metric not in SORT_METRICS:
        raise InvalidInput(f"sort by {'/'.join(SORT_METRICS)} on {' or '.join(SORT_REGIONS)} only, "
                           f"got {metric} on {region}")
    return getattr(EvaluationResult, f"{metric}_{region}")


def default_method(evaluation: Evaluation) -> str:
    methods = evaluation.params.get("methods") or []
    if not methods:
        raise InvalidInput(f"evaluation {evaluation.id} has no methods")
    return str(methods[0])


def samples_by_error(session: Session, evaluation_id: int, *, method: str | None = None, region: str = "all",
                     metric: str = "epe", min_error: float | None = None, limit: int = 60,
                     offset: int = 0) -> tuple[list[dict[str, Any]], int]:
    """The evaluation's samples, worst first by ``metric`` (EPE px, bad-2 %) on ``region`` for
    ``method`` (default: the evaluation's first), optionally only those at or above ``min_error``;
    each sample's JSON carries ``evaluation`` (the method's figures). Returns (page, total).

    Offset paging is enough here: an evaluation holds one row per test sample (thousands, not the
    millions of frames the keyset pages serve), and the order is an index of its own.
    """
    if not 1 <= limit <= 500 or offset < 0:
        raise InvalidInput("limit must be 1..500 and offset ≥ 0")
    evaluation = get_evaluation(session, evaluation_id)
    method = method or default_method(evaluation)
    column = _sort_column(region, metric)
    where = [EvaluationResult.evaluation_id == evaluation_id, EvaluationResult.method == method]
    if min_error is not None:
        where.append(column >= min_error)
    query = (select(EvaluationResult, Sample, Frame, Video).join(Sample, Sample.id == EvaluationResult.sample_id)
             .join(Frame, Frame.id == Sample.frame_id).join(Video, Video.id == Frame.video_id).where(*where)
             .order_by(column.desc().nulls_last(), EvaluationResult.sample_id).limit(limit).offset(offset))
    total = int(session.scalar(select(func.count()).select_from(EvaluationResult).where(*where)) or 0)
    items = []
    for result, sample, frame, video in session.execute(query):
        item = sample_json(sample, frame, video)
        item["evaluation"] = {"id": evaluation_id, "method": method, "region": region, "metric": metric,
                              "value": getattr(result, f"{metric}_{region}"), "regions": result.regions}
        items.append(item)
    return items, total


def sample_result(session: Session, evaluation_id: int, sample_id: int, method: str) -> EvaluationResult:
    row = session.scalar(select(EvaluationResult).where(
        EvaluationResult.evaluation_id == evaluation_id, EvaluationResult.sample_id == sample_id,
        EvaluationResult.method == method))
    if row is None:
        raise NotFound(f"evaluation {evaluation_id} has no {quoted(method)} result for sample {sample_id}")
    return row


def sample_evaluations(session: Session, sample_id: int) -> list[dict[str, Any]]:
    """Every evaluation with results for this sample: id, method, figures (newest first)."""
    rows = session.execute(select(EvaluationResult, Evaluation.created_at)
                           .join(Evaluation, Evaluation.id == EvaluationResult.evaluation_id)
                           .where(EvaluationResult.sample_id == sample_id)
                           .order_by(EvaluationResult.evaluation_id.desc(), EvaluationResult.method))
    return [{"evaluation": r.evaluation_id, "method": r.method, "epe_all": r.epe_all, "bad2_all": r.bad2_all,
             "epe_illusion": r.epe_illusion, "created_at": created.isoformat() + "Z",
             "has_prediction": bool(r.prediction)} for r, created in rows]

