"""The VLM prefilter as jobs: claim ingested frames in chunks, ask the VLM, record verdicts, move frames on.

Frames are claimed by exactly one job (``frames.prefilter_job_id``), so any number of workers share
one backlog without asking about a frame twice; a chunk job skips frames that already have a
verdict from the same backend, model and prompt version, so a retry after a crash costs nothing.
Sparse mode (the authors') asks about every ``step``-th frame of a video and lets a rejected
sample take its ±step/2 neighbours with it.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from sqlalchemy import or_, select, tuple_, update
from sqlalchemy.orm import Session

from annotation.vlm import KeepRule, PrefilterBackend, Verdict, make_backend, sparse_expand, sparse_samples, sparse_step
from core.wording import plural
from dataset.db import transaction
from dataset.services.errors import Conflict, InvalidInput
from dataset.services.frames import update_frame
from dataset.services.jobs import JobContext
from dataset.settings import Settings
from dataset.tables import Frame, FrameState, Job, JobState, PrefilterResult, User, Video

Submit = Callable[[Session, str, dict[str, Any], User | None], Job]
CHUNK = 32  # frames per job: small enough to spread over workers, large enough to batch the VLM
BATCH = 8  # images per VLM call
CLAIM_PAGE = 5000  # frame ids read per query while claiming the backlog


def launch_prefilter(session: Session, submit: Submit, user: User | None, *, video_id: int | None = None,
                     backend: str | None = None, base_url: str | None = None, model: str | None = None,
                     sparse: bool = False, chunk: int = CHUNK) -> list[Job]:
    """Queue prefilter jobs for the unclaimed ingested frames (of one video, or all)."""
    if video_id is not None and session.get(Video, video_id) is None:
        raise InvalidInput(f"no video {video_id}")
    if not 1 <= chunk <= 1000:
        raise InvalidInput("chunk must be 1..1000 frames")
    owner = select(Job.id).where(Job.id == Frame.prefilter_job_id,
                                 Job.state.in_([JobState.queued, JobState.running])).exists()
    query = (select(Frame.id, Frame.video_id, Frame.index)
             .where(Frame.state == FrameState.ingested, or_(Frame.prefilter_job_id.is_(None), ~owner))
             .order_by(Frame.video_id, Frame.index).limit(CLAIM_PAGE).with_for_update(skip_locked=True, of=Frame))
    if video_id is not None:
        query = query.where(Frame.video_id == video_id)
    options = {"backend": backend, "base_url": base_url, "model": model, "sparse": sparse}
    jobs: list[Job] = []

    def claim(frame_ids: list[int]) -> None:
        job = submit(session, "prefilter", {**options, "frame_ids": frame_ids}, user)
        session.execute(update(Frame).where(Frame.id.in_(frame_ids)).values(prefilter_job_id=job.id)
                        .execution_options(synchronize_session=False))
        jobs.append(job)

    # The backlog is read in keyed pages of ids, never loaded whole: a 1.4M-frame ingest stays flat in memory.
    pending: list[int] = []
    pending_video, last = None, None
    while True:
        rows = session.execute(query if last is None else query.where(tuple_(Frame.video_id, Frame.index) > last)).all()
        for frame_id, frame_video, index in rows:
            # Sparse decisions span a whole video, so one job per video; otherwise chunks of ``chunk``.
            if pending and (len(pending) == chunk if not sparse else frame_video != pending_video):
                claim(pending)
                pending = []
            pending.append(frame_id)
            pending_video, last = frame_video, (frame_video, index)
        if len(rows) < CLAIM_PAGE:
            break
    if pending:
        claim(pending)
    session.flush()
    return jobs


@lru_cache(maxsize=4)
def _backend(name: str, base_url: str, model: str, api_key: str, model_path: str | None, device: str,
             rule: KeepRule) -> PrefilterBackend:
    # One instance per configuration and process: a transformers model loads once per worker.
    return make_backend(name, base_url=base_url, model=model, api_key=api_key,
                        model_path=Path(model_path) if model_path else None, device=device, rule=rule)


def backend_for(settings: Settings, params: dict[str, Any]) -> PrefilterBackend:
    try:
        rule = KeepRule(any_of=tuple(settings.vlm_keep_any_of), none_of=tuple(settings.vlm_keep_none_of),
                        veto_pair=tuple(settings.vlm_keep_veto) if settings.vlm_keep_veto else None)
        return _backend(params.get("backend") or settings.vlm_backend, params.get("base_url") or settings.vlm_base_url,
                        params.get("model") or settings.vlm_model, settings.vlm_api_key,
                        str(settings.vlm_model_path) if settings.vlm_model_path else None, settings.device, rule)
    except ValueError as exc:
        raise InvalidInput(str(exc)) from None


def prefilter_frames(ctx: JobContext) -> dict[str, Any]:
    """Job handler for kind ``prefilter``: params ``frame_ids``, ``backend``, ``base_url``, ``model``, ``sparse``."""
    backend = backend_for(ctx.settings, ctx.params)
    with ctx.sessions() as s:
        answered = select(PrefilterResult.id).where(
            PrefilterResult.frame_id == Frame.id, PrefilterResult.model_id == backend.model_id,
            PrefilterResult.prompt_version == backend.prompt_version).exists()
        todo = s.execute(select(Frame.id, Frame.media_key).where(
            Frame.id.in_(ctx.params["frame_ids"]), Frame.state == FrameState.ingested, ~answered)
            .order_by(Frame.video_id, Frame.index)).all()
    ctx.log(f"{backend.name} ({backend.model_id}, prompt {backend.prompt_version}): "
            f"{len(todo)} of {plural(len(ctx.params['frame_ids']), 'frame')} to ask about")
    if ctx.params.get("sparse"):
        verdicts = _sparse(ctx, backend, todo)
    else:
        verdicts = {}
        for start in range(0, len(todo), BATCH):
            batch = todo[start:start + BATCH]
            for (frame_id, _), verdict in zip(batch, backend.classify([_load(ctx, key) for _, key in batch]), strict=True):
                verdicts[frame_id] = verdict
            _record(ctx, backend, {fid: verdicts[fid] for fid, _ in batch}, sparse_from={})
            ctx.progress((start + len(batch)) / max(len(todo), 1))
    kept = sum(v.keep is True for v in verdicts.values())
    dropped = sum(v.keep is False for v in verdicts.values())
    unparsed = sum(not v.parsed for v in verdicts.values())
    return {"frames": len(verdicts), "keep": kept, "reject": dropped, "undecided": len(verdicts) - kept - dropped,
            "unparsed": unparsed, "backend": backend.name, "model_id": backend.model_id}


def _sparse(ctx: JobContext, backend: PrefilterBackend, todo: list[Any]) -> dict[int, Verdict]:
    n = len(todo)
    samples = sparse_samples(n)
    asked: dict[int, Verdict] = {}
    for start in range(0, len(samples), BATCH):
        positions = samples[start:start + BATCH]
        for pos, verdict in zip(positions, backend.classify([_load(ctx, todo[p][1]) for p in positions]), strict=True):
            asked[pos] = verdict
        ctx.progress((start + len(positions)) / max(len(samples), 1) * 0.9)
    expanded = sparse_expand(n, {pos: v.keep for pos, v in asked.items()})
    step = sparse_step(n)
    verdicts, sparse_from = {}, {}
    for pos, (frame_id, _) in enumerate(todo):
        if pos in asked:
            verdicts[frame_id] = asked[pos]
        else:
            verdicts[frame_id] = Verdict(raw="", answers=None, parsed=False, keep=expanded[pos],
                                         reason=f"sparse mode: inferred from samples every {step} frames",
                                         metrics={}, error=None)
            sparse_from[frame_id] = step
    _record(ctx, backend, verdicts, sparse_from)
    return verdicts


def _record(ctx: JobContext, backend: PrefilterBackend, verdicts: dict[int, Verdict], sparse_from: dict[int, int]) -> None:
    """Store verdicts and move frames on: a sure 'reject' is rejected, anything else goes to curators."""
    with transaction(ctx.sessions) as s:
        for frame_id, v in verdicts.items():
            frame = s.get(Frame, frame_id, with_for_update=True)
            if frame is None or frame.state != FrameState.ingested:
                continue  # deleted or moved on by a person meanwhile: their decision stands
            try:
                update_frame(s, frame, state=FrameState.rejected if v.keep is False else FrameState.prefiltered)
            except Conflict:
                continue  # changed by someone between our read and our write: theirs stands too
            metrics = dict(v.metrics)
            if frame_id in sparse_from:
                metrics["sparse_step"] = sparse_from[frame_id]
            s.add(PrefilterResult(frame_id=frame_id, backend=backend.name + ("+sparse" if frame_id in sparse_from else ""),
                                  model_id=backend.model_id, prompt_version=backend.prompt_version,
                                  raw_answer=v.raw if not v.error else f"{v.raw}\n[error] {v.error}".strip(),
                                  answers=list(v.answers) if v.answers is not None else [],
                                  parsed=v.parsed, keep=v.keep, reason=v.reason, metrics=metrics))


def _load(ctx: JobContext, key: str) -> np.ndarray:
    bgr = cv2.imdecode(np.frombuffer(ctx.media.read_bytes(key), np.uint8), cv2.IMREAD_COLOR)
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
