"""Videos: list them, and upload new ones (each upload becomes an ingest job)."""

from __future__ import annotations

import os
from pathlib import Path

from flask import abort, g, request
from flask.typing import ResponseReturnValue
from flask_login import current_user
from sqlalchemy import func, select

from annotation.vlm import BACKEND_NAMES
from dataset.ingest.sources import VIDEO_EXTENSIONS, image_kind
from dataset.services import jobs as job_service
from dataset.services.errors import InvalidInput
from dataset.services.ingest import DEFAULT_DEDUP_HAMMING, ingest_params, mono_index
from dataset.services.paging import keyset_page
from dataset.services.prefilter import launch_prefilter
from dataset.services.sample_blockers import sample_blocker
from dataset.services.validate import db_int
from dataset.tables import FrameCount, Role, User, Video
from webapp.api.blueprint import api, cursor_args, int_arg, json_body
from webapp.auth import requires
from webapp.bodies import MIB, size_text
from webapp.jobs.queue import check_reachable, queue_for
from webapp.runtime import runtime


@api.get("/videos")
@requires(Role.annotator)
def list_videos() -> ResponseReturnValue:
    limit = int_arg("limit", 100, minimum=1, maximum=1000)
    page = keyset_page(g.db, select(Video, Video.id), (Video.id,), limit=limit, descending=True, **cursor_args())
    videos = [row[0] for row in page.rows]
    counts = dict(g.db.execute(select(FrameCount.video_id, func.sum(FrameCount.n))
                               .where(FrameCount.video_id.in_([v.id for v in videos])).group_by(FrameCount.video_id)).all())
    return {"prev": page.prev, "next": page.next, "items": [{"id": v.id, "name": v.name, "source_kind": v.source_kind.value,
                       "illusion_types": v.illusion_types, "fps": v.fps, "width": v.width, "height": v.height,
                       "frames": counts.get(v.id, 0), "ingest": v.meta.get("ingest"),
                       "created_at": v.created_at.isoformat() + "Z"} for v in videos]}


MAX_FILE_NAME = 255


@api.post("/videos")
@requires(Role.curator)
def upload_video() -> ResponseReturnValue:
    """Multipart upload: ``file`` plus optional ``fps``, ``source``, ``illusion_type`` (repeatable) and
    ``mono`` (repeatable): the video's per-frame monocular disparities, named by frame index.

    The answer is the ingest job's, with ``sample_blocker``: why this workspace cannot make samples of
    the video's frames (no depth model, and no ``mono`` maps), or None."""
    upload = request.files.get("file")
    if upload is None or not upload.filename:
        raise InvalidInput("send the video as the multipart field 'file'")
    name = Path(upload.filename).name
    if len(name) > MAX_FILE_NAME:  # stored and shown as the video's name; no file system takes longer names
        raise InvalidInput(f"the file's name has {len(name)} characters; rename it to at most {MAX_FILE_NAME}")
    ext = Path(name).suffix.lower()
    if ext not in VIDEO_EXTENSIONS:
        raise InvalidInput(f"{name}: not a video file name (expected one of {', '.join(sorted(VIDEO_EXTENSIONS))})")
    rt = runtime()
    upload.stream.seek(0, os.SEEK_END)
    size = upload.stream.tell()
    # The request's own limit allows for the form around the file: this one is the file's, exactly.
    if size > rt.settings.max_upload_mb * MIB:
        abort(413, f"{name} is {size_text(size)}; uploads take at most {rt.settings.max_upload_mb} MiB (max_upload_mb)")
    upload.stream.seek(0)
    head = upload.stream.read(16)
    upload.stream.seek(0)
    if kind := image_kind(head):
        raise InvalidInput(f"{name} is a {kind} image, not a video; upload a video file")
    try:
        fps = float(request.form.get("fps") or 2.0)
    except ValueError:
        raise InvalidInput("fps must be a number") from None
    if not 0 <= fps <= 1000:
        raise InvalidInput("fps must be in 0..1000 (0: every frame)")
    maps = [m for m in request.files.getlist("mono") if m.filename]
    mono = mono_index([Path(m.filename).name for m in maps])  # refused before anything is stored
    params = ingest_params("", fps=fps or None, source=request.form.get("source") or None,
                           illusion_types=request.form.getlist("illusion_type"),
                           dedup_hamming=DEFAULT_DEDUP_HAMMING, user_id=current_user.id, original_name=name,
                           prefilter=request.form.get("prefilter", "1") not in ("0", "false", ""))
    # Before the file is stored: a request refused with 503 leaves nothing behind.
    check_reachable(rt.queue.hueys[queue_for("ingest")])
    key = rt.media.put_stream(upload.stream, ext)
    params["path"] = str(rt.media.path(key))
    stored = []
    for index, upload_map in zip(mono, maps, strict=True):  # mono_index keeps the maps' order
        name = mono[index]
        stored.append([index, str(rt.media.path(rt.media.put_stream(upload_map.stream, Path(name).suffix))), name])
    if stored:
        params["mono_files"] = stored
    user = g.db.get(User, current_user.id)
    job = rt.queue.submit(g.db, "ingest", params, user)
    g.db.commit()
    # The maps make the video's own depth: an upload without them has none.
    own = Video(meta={"mono": "precomputed"}) if maps else None
    return {**job_service.job_json(job), "sample_blocker": sample_blocker(rt.settings, own)}, 202


@api.post("/prefilter")
@requires(Role.curator)
def start_prefilter() -> ResponseReturnValue:
    """Queue prefilter jobs: body ``{"video_id"?, "backend"?, "sparse"?}``."""
    body = json_body()
    video_id = body.get("video_id")
    if video_id is not None:
        video_id = db_int(video_id, "video_id", minimum=0)
    backend = body.get("backend") or None
    if backend is not None and backend not in BACKEND_NAMES:
        raise InvalidInput(f"backend must be one of {', '.join(BACKEND_NAMES)}")
    jobs = launch_prefilter(g.db, runtime().submit, g.db.get(User, current_user.id), video_id=video_id,
                            backend=backend, sparse=bool(body.get("sparse")))
    g.db.commit()
    return {"jobs": [job_service.job_json(j) for j in jobs]}, 202
