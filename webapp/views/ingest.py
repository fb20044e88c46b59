"""The curators' upload page: each video becomes an ingest job."""

from __future__ import annotations

from flask import Blueprint, render_template
from flask.typing import ResponseReturnValue

from dataset.ingest.sources import VIDEO_EXTENSIONS
from dataset.services.sample_blockers import sample_blocker
from dataset.tables import IllusionType, Role, SourceKind
from webapp.auth import requires
from webapp.runtime import runtime

bp = Blueprint("ingest", __name__)


@bp.get("/ingest")
@requires(Role.curator)
def ingest() -> ResponseReturnValue:
    """Upload videos; each becomes an ingest job."""
    return render_template("ingest.html", sources=list(SourceKind), illusion_types=list(IllusionType),
                           max_upload_mb=runtime().settings.max_upload_mb,
                           extensions=sorted(VIDEO_EXTENSIONS),
                           # said before the upload: an uploaded video brings no depth of its own
                           sample_blocker=sample_blocker(runtime().settings, None))
