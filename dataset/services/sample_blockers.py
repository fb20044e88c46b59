"""Whether a video's frames can become samples, said before anyone works on them.

A sample needs a monocular disparity (:func:`dataset.services.generate.mono_disparity`): a
configured depth model, or a disparity that came with the frame (imported beside a video,
rendered from a reconstruction, or a synthetic scene's own). Without one the generate job can
only fail after the annotation is done, so every place that leads to that work (the upload's
answer, Review, Annotate, submit, the Dashboard) asks :func:`sample_blocker` first. Generate jobs
that failed anyway are found by :func:`failed_generate`, so a frame shows why it has no sample.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from sqlalchemy import Select, func, select
from sqlalchemy.orm import Session

from dataset.imported import depth_model_dir
from dataset.redact import redacted
from dataset.services.errors import ServiceError
from dataset.settings import Settings
from dataset.tables import Annotation, Frame, FrameState, Job, JobState, Video

GENERATE_JOB = "generate"


def sample_blocker(settings: Settings, video: Video | None, frame: Frame | None = None) -> str | None:
    """The reason ``video``'s frames (``frame``, when given) cannot become samples, or None when they can.

    ``video`` None stands for a plain video not ingested yet (an upload): it has no depth of its own.
    A video's own depth is judged on ``frame``'s assets when given, else on what the video recorded at
    ingest (a synthetic scene, or maps imported with ``--mono``).
    """
    if frame is not None and "reconstruction_disparity" in frame.assets:
        return None  # generation reads it before any backend
    if settings.depth_backend == "depth-anything-v2":
        if settings.depth_model_path is None:
            return ("depth_backend is depth-anything-v2 but depth_model_path is not set: set it to a local "
                    "Depth Anything V2 checkpoint directory or imported:NAME")
        try:
            depth_model_dir(settings)  # an imported:NAME that names nothing blocks every frame
        except ServiceError as exc:
            return str(exc)
        return None
    if _own_depth(video, frame):
        return None
    return ("this workspace cannot make samples from this video: it has no monocular depth of its own and no "
            "depth model is configured. Set depth_backend = 'depth-anything-v2' with depth_model_path, or "
            "ingest the video with its per-frame disparity maps (illusion-studio ingest --mono DIR)")


def _own_depth(video: Video | None, frame: Frame | None) -> bool:
    if video is None:
        return False
    if frame is not None:
        assets = frame.assets or {}
        return "precomputed_disparity" in assets or ("mono_disparity" in assets and bool(video.meta.get("synthetic")))
    return bool(video.meta.get("synthetic") or video.meta.get("mono"))


def frame_blocker(session: Session, settings: Settings, frame: Frame) -> str | None:
    """:func:`sample_blocker` for one stored frame."""
    return sample_blocker(settings, session.get(Video, frame.video_id), frame)


def failed_generate(session: Session, frame: Frame) -> dict[str, Any] | None:
    """The frame's last generate job when it failed and the frame is still waiting for its sample
    (``{"job_id", "error", "finished_at"}``), else None: a later success or a new job supersedes it."""
    if frame.state != FrameState.annotated:
        return None
    job = session.scalar(select(Job).where(Job.kind == GENERATE_JOB, Job.params["frame_id"].as_integer() == frame.id)
                         .order_by(Job.id.desc()).limit(1))
    if job is None or job.state not in (JobState.failed, JobState.interrupted):
        return None
    return _failure_json(job)


def _failure_json(job: Job) -> dict[str, Any]:
    # A job's error comes from outside the app's own answers (tracebacks, paths): shown as job answers show it.
    return {"job_id": job.id, "error": redacted(job.error),
            "finished_at": job.finished_at.isoformat() + "Z" if job.finished_at else None}


def _failed_last_jobs() -> Select[Any]:
    """(frame id, job) of the annotated frames whose last generate job failed, newest job first."""
    frame_id = Job.params["frame_id"].as_integer()
    last = (select(frame_id.label("frame_id"), func.max(Job.id).label("job_id"))
            .where(Job.kind == GENERATE_JOB).group_by(frame_id).subquery())
    return (select(last.c.frame_id, Job).join(Job, Job.id == last.c.job_id).join(Frame, Frame.id == last.c.frame_id)
            .where(Job.state.in_((JobState.failed, JobState.interrupted)), Frame.state == FrameState.annotated)
            .order_by(Job.id.desc()))


def failed_generate_count(session: Session) -> int:
    """How many annotated frames have a failed last generate job (the Dashboard's count)."""
    return session.scalar(select(func.count()).select_from(_failed_last_jobs().subquery())) or 0


def failed_generates_of(session: Session, user_id: int, *, other_than: int | None = None,
                        limit: int = 5) -> list[dict[str, Any]]:
    """The frames ``user_id`` submitted whose sample could not be made (``{"frame_id", "job_id",
    "error"}``, newest first, at most ``limit``): the annotator's next page names them."""
    query = _failed_last_jobs().join(Annotation, Annotation.frame_id == Frame.id).where(Annotation.user_id == user_id)
    if other_than is not None:
        query = query.where(Frame.id != other_than)
    return [{"frame_id": fid, "job_id": job.id, "error": redacted(job.error)}
            for fid, job in session.execute(query.limit(limit)).all()]


def frame_sample_status(session: Session, settings: Settings, frame: Frame, user_id: int) -> dict[str, Any]:
    """What a frame's JSON says of its way to a sample: ``sample_blocker`` (why it cannot get one, or
    None), ``generate_failed`` (its failed generate job, see :func:`failed_generate`, or None) and
    ``failed_elsewhere`` (the caller's other frames whose sample could not be made)."""
    return {"sample_blocker": frame_blocker(session, settings, frame),
            "generate_failed": failed_generate(session, frame),
            "failed_elsewhere": failed_generates_of(session, user_id, other_than=frame.id)}


def with_blockers(session: Session, settings: Settings, items: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """``items`` (frame JSON with ``id``) with their ``sample_blocker``: the review grid marks the frames
    an approval would send to annotators for nothing."""
    for item in items:
        frame = session.get(Frame, item["id"])
        item["sample_blocker"] = frame_blocker(session, settings, frame) if frame is not None else None
    return items


def blocked_videos(session: Session, settings: Settings) -> int:
    """How many ingested videos cannot make samples as the workspace is configured (judged on what
    each video recorded at ingest; frames given a reconstruction later are not seen here)."""
    if sample_blocker(settings, None) is None:
        return 0  # a depth model serves every video
    return sum(1 for meta in session.scalars(select(Video.meta))
               if sample_blocker(settings, Video(meta=meta or {})) is not None)


def with_failures(session: Session, items: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """``items`` (frame JSON with ``id`` and ``state``) with ``generate_failed`` (see :func:`failed_generate`):
    the frames browser marks the annotated frames whose sample could not be made."""
    ids = [item["id"] for item in items if item.get("state") == FrameState.annotated.value]
    failed = ({fid: _failure_json(job) for fid, job in session.execute(_failed_last_jobs().where(Frame.id.in_(ids))).all()}
              if ids else {})
    for item in items:
        item["generate_failed"] = failed.get(item["id"])
    return items


def retry_failed_generates(session: Session, settings: Settings,
                           retry: Callable[[Session, int], Any]) -> dict[str, Any]:
    """Queue again, through ``retry`` (the job queue's), every failed last generate job whose frame can
    become a sample now (its cause fixed: a depth model configured, its depth imported); the others stay,
    grouped by the reason (``{"retried": [job ids], "still_blocked": [{"reason", "frame_ids"}]}``)."""
    retried: list[int] = []
    blocked: dict[str, list[int]] = {}
    for frame_id, job in session.execute(_failed_last_jobs()).all():
        reason = frame_blocker(session, settings, session.get(Frame, frame_id))
        if reason is not None:
            blocked.setdefault(reason, []).append(frame_id)
            continue
        retry(session, job.id)
        retried.append(job.id)
    return {"retried": retried,
            "still_blocked": [{"reason": reason, "frame_ids": ids} for reason, ids in blocked.items()]}
