"""Sample pages: the grid of generated samples, one sample's 2D views and QA, and its 3D preview.

The 3D preview is viser's prebuilt static client playing back a ``.viser`` scene; both are served
here, behind the login, so there is no second port, no websocket and no proxy. Accept/reject
goes through the API (``POST /api/v1/samples/<id>/review``).
"""

from __future__ import annotations

import importlib.util
from functools import cache
from pathlib import Path

from flask import Blueprint, abort, g, redirect, render_template, request, send_file, send_from_directory, url_for
from flask.typing import ResponseReturnValue
from flask_login import current_user

from core.wording import quoted
from dataset.preview import images, qa
from dataset.preview.cache import RenderCache
from dataset.preview.sample_preview import STAGES, SamplePreview
from dataset.services import evaluations, sample_review
from dataset.services.validate import REASON_CHARS
from dataset.tables import Frame, Role, SampleState
from webapp.auth import requires
from webapp.runtime import runtime

samples = Blueprint("samples", __name__)

def _preview() -> SamplePreview:
    rt = runtime()
    budget = rt.settings.preview_cache_mb * 1024 * 1024
    return SamplePreview(rt.media, RenderCache(rt.settings.cache_dir / "preview", budget))


@cache
def _viser_client_dir() -> Path:
    # Located without importing viser, which pulls in its server stack.
    spec = importlib.util.find_spec("viser")
    if spec is None or spec.origin is None:
        abort(501, "the 3D preview needs the viser package: pip install viser")
    return Path(spec.origin).parent / "client" / "build"


@samples.get("/samples")
@requires(Role.annotator)
def index() -> ResponseReturnValue:
    """The grid of samples, filtered by state and flags, reviewed with the keyboard."""
    return render_template("samples.html", states=list(SampleState), reasons=sample_review.REJECT_REASONS,
                           note_chars=REASON_CHARS, can_review=current_user.allows(Role.curator))


@samples.get("/samples/<int:sample_id>")
@requires(Role.annotator)
def detail(sample_id: int) -> ResponseReturnValue:
    """One sample: 2D views with a colour bar, QA figures, accept/reject, the 3D preview on demand."""
    return _sample_page(sample_id, open_3d=False)


@samples.get("/samples/<int:sample_id>/preview")
@requires(Role.annotator)
def preview(sample_id: int) -> ResponseReturnValue:
    """The sample page with its 3D preview open (a link target for other pages)."""
    return _sample_page(sample_id, open_3d=True)


def _sample_page(sample_id: int, open_3d: bool) -> ResponseReturnValue:
    sample = sample_review.sample_detail(g.db, sample_id)
    previews = _preview()
    stages = previews.stages(sample)
    return render_template(
        "sample.html", sample=sample, views=previews.views(sample), stages=stages,
        value_range=previews.disparity_range(sample) if stages else None, stops=images.colorbar_stops(),
        summary=qa.summary_rows(sample["qa"]), pairs=qa.pair_rows(sample["qa"]), reasons=sample_review.REJECT_REASONS,
        note_chars=REASON_CHARS, can_review=current_user.allows(Role.curator), open_3d=open_3d and bool(stages),
        evaluated=evaluations.sample_evaluations(g.db, sample_id) if current_user.allows(Role.curator) else [])


@samples.get("/samples/<int:sample_id>/views/<view>.png")
@requires(Role.annotator)
def render(sample_id: int, view: str) -> ResponseReturnValue:
    """A 2D view as PNG (``?size=thumb`` for the grid)."""
    sample = sample_review.get_sample(g.db, sample_id)
    try:
        path = _preview().render(sample, view, thumb=request.args.get("size") == "thumb")
    except KeyError:
        abort(404, f"sample {sample_id} has no {quoted(view)} view")
    # A regenerated sample keeps its id but not its images: revalidate (cheap, by ETag) every time.
    return send_file(path, mimetype="image/png", max_age=0, conditional=True, etag=True)


@samples.get("/samples/<int:sample_id>/scene.viser")
@requires(Role.annotator)
def scene(sample_id: int) -> ResponseReturnValue:
    """The ``.viser`` scene: both point clouds, ``?stage=after|before`` shown at first."""
    stage = request.args.get("stage", STAGES[0])
    sample = sample_review.get_sample(g.db, sample_id)
    try:
        path = _preview().scene(sample, stage)
    except KeyError:
        abort(404, f"sample {sample_id} has no {quoted(stage)} point cloud (stages: {', '.join(STAGES)})")
    return send_file(path, mimetype="application/octet-stream", max_age=0, conditional=True, etag=True)


@samples.get("/viser/<path:asset>")
@requires(Role.annotator)
def viser_client(asset: str) -> ResponseReturnValue:
    """viser's prebuilt web client: ``index.html?playbackPath=<scene url>`` plays a scene back."""
    return send_from_directory(_viser_client_dir(), asset, max_age=3600)


@samples.get("/frames/<int:frame_id>/preview")
@requires(Role.annotator)
def frame_preview(frame_id: int) -> ResponseReturnValue:
    """The 3D preview of a frame's newest sample (for the annotation page)."""
    if g.db.get(Frame, frame_id) is None:
        abort(404, f"no frame {frame_id}")
    sample_id = sample_review.newest_sample_id(g.db, frame_id)
    if sample_id is None:
        abort(404, f"frame {frame_id} has no generated sample yet: submit its annotation, and the preview "
                   "is here once the generate job has run (see Jobs)")
    return redirect(url_for("samples.preview", sample_id=sample_id))
