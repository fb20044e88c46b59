"""The Export page: curators export the dataset as the CLI's ``export`` does, follow the job, download
the result as one zip (streamed from ``<home>/exports/<id>``) and delete it.

A plain form post (CSRF token in the form, like every cookie request's): a refusal renders the page
again with the reason under the field it names; a launch redirects back to the list, whose rows
follow their jobs through the jobs API (``static/js/exports.js``).
"""

from __future__ import annotations

from typing import Any

from flask import Blueprint, Response, flash, g, redirect, render_template, request, url_for
from flask.typing import ResponseReturnValue
from flask_login import current_user
from werkzeug.datastructures import MultiDict

from core.wording import quoted
from dataset.export import FORMATS
from dataset.export.authors_layout import MASK_FORMATS
from dataset.export.selection import DEFAULT_STATES
from dataset.export.splits import DEFAULT_SPLIT
from dataset.services import exports
from dataset.services.errors import Conflict, FieldError
from dataset.services.validate import DB_INT_MAX
from dataset.tables import Role, SampleState, User, Video
from webapp.auth import requires
from webapp.runtime import runtime

bp = Blueprint("exports", __name__)
SEED_MAX = 2**32 - 1


def _page(form: MultiDict[str, str] | None = None, errors: dict[str, str] | None = None) -> str:
    settings = runtime().settings
    if exports.delete_expired(g.db, settings):
        g.db.commit()
    videos = g.db.query(Video.id, Video.name).order_by(Video.id).all()
    return render_template("exports.html", exports=[exports.export_json(e) for e in exports.list_exports(g.db)],
                           videos=videos, formats=FORMATS, mask_formats=MASK_FORMATS,
                           states=[s.value for s in SampleState], default_split=DEFAULT_SPLIT,
                           form=form or MultiDict([("states", s) for s in DEFAULT_STATES]), errors=errors or {},
                           retention_days=settings.export_retention_days)


@bp.get("/exports")
@requires(Role.curator)
def index() -> ResponseReturnValue:
    """The exports made here, newest first, and the form that makes one."""
    return _page()


def _int(text: str, field: str, what: str, maximum: int) -> int:
    if not text.isascii() or not text.isdigit() or int(text) > maximum:
        raise FieldError(field, f"{what} must be a whole number from 0 to {maximum}, not {quoted(text)}")
    return int(text)


def _options(form: MultiDict[str, str]) -> dict[str, Any]:
    """The form's fields as :func:`dataset.services.exports.create_export` takes them."""
    return {"format": form.get("format", ""), "split": form.get("split", "").strip() or DEFAULT_SPLIT,
            "seed": _int(form.get("seed", "").strip() or "0", "seed", "the seed", SEED_MAX),
            "states": form.getlist("states"), "mask_format": form.get("mask_format", "png"),
            "video_ids": [_int(v, "video_ids", "a video id", DB_INT_MAX) for v in form.getlist("video_ids")]}


@bp.post("/exports")
@requires(Role.curator)
def create() -> ResponseReturnValue:
    """Queue an export with the CLI's options; refused at once, under its field, when an option is wrong."""
    user = g.db.get(User, current_user.id)
    try:
        export, params = exports.create_export(g.db, runtime().settings, user, **_options(request.form))
    except FieldError as exc:
        g.db.rollback()
        return _page(request.form, {exc.field: exc.reason}), 400
    export.job_id = runtime().submit(g.db, "export", params, user).id
    g.db.commit()
    flash(f"Export {export.id} queued: it appears below with its progress.", "info")
    return redirect(url_for("exports.index", _anchor=f"export-{export.id}"), 303)


@bp.get("/exports/<int:export_id>.zip")
@requires(Role.curator)
def download(export_id: int) -> ResponseReturnValue:
    """The finished export as one zip, made while it is sent (nothing is built in memory or on disk)."""
    export = exports.get_export(g.db, export_id)
    _, files = exports.export_files(export, runtime().settings)
    name = exports.zip_name(export)
    return Response(exports.zip_stream(files, name), mimetype="application/zip",
                    headers={"Content-Disposition": f'attachment; filename="{name}.zip"', "Cache-Control": "no-store"})


@bp.post("/exports/<int:export_id>/delete")
@requires(Role.curator)
def delete(export_id: int) -> ResponseReturnValue:
    """Delete an export's files and its entry (not while its job still runs)."""
    try:
        exports.delete_export(g.db, runtime().settings, export_id, g.db.get(User, current_user.id))
    except Conflict as exc:
        flash(str(exc), "error")
    else:
        g.db.commit()
        flash(f"Export {export_id} deleted.", "info")
    return redirect(url_for("exports.index"), 303)
