"""Media files, to logged-in users only; keys that are not store keys are a 404."""

from __future__ import annotations

from flask import Blueprint, abort, send_file
from flask.typing import ResponseReturnValue

from dataset.media import MediaKeyError
from dataset.tables import Role
from webapp.auth import requires
from webapp.runtime import runtime

media = Blueprint("media", __name__)


@media.get("/media/<path:key>")
@requires(Role.annotator)
def serve(key: str) -> ResponseReturnValue:
    try:
        path = runtime().media.path(key)
    except MediaKeyError:
        abort(404, "no such media file")
    if not path.is_file():
        abort(404, "no such media file")
    # Content-addressed: a key's bytes never change, so caches may keep them for good.
    return send_file(path, max_age=31536000, conditional=True, etag=True)
