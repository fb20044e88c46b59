"""The annotators' click-annotation page."""

from __future__ import annotations

from flask import Blueprint, render_template
from flask.typing import ResponseReturnValue

from dataset.services.annotate import DELETE_REASONS
from dataset.tables import IllusionType, Role
from webapp.auth import requires
from webapp.runtime import runtime

bp = Blueprint("annotate", __name__)


@bp.get("/annotate")
@bp.get("/annotate/<int:frame_id>")
@requires(Role.annotator)
def annotate(frame_id: int | None = None) -> ResponseReturnValue:
    """The click-annotation canvas; without a frame id it asks the queue for the next frame."""
    return render_template("annotate.html", frame_id=frame_id, illusion_types=list(IllusionType),
                           delete_reasons=DELETE_REASONS, lease_s=runtime().settings.annotation_lease_s)
