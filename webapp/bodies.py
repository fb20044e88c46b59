"""How large a request body each route takes, checked before anything reads one.

The server (:mod:`webapp.server`) reads a body ahead before a worker takes the request: up to 32 KiB
for anyone, up to the limit here for a client whose credentials the route serves
(:mod:`webapp.admission`). The hook here runs before the rate limits, authentication and the CSRF
check: a declared length over the route's limit is answered 413 at once, and a chunked body is
refused at the first byte past the limit. Then :mod:`webapp.auth` answers an anonymous client 401,
and a role too low 403, before anything reads the body.
"""

from __future__ import annotations

from typing import IO, Any

from flask import Flask, abort, current_app, request
from werkzeug.exceptions import RequestEntityTooLarge
from werkzeug.wsgi import LimitedStream

from dataset.services.annotate import MAX_CLICKS, MAX_REGIONS
from dataset.settings import Settings
from webapp.auth import PUBLIC, ROLE_ATTR
from webapp.server import READ_AHEAD_BYTES, BodyCut

MIB = 1 << 20
# Forms and JSON: a segment call's previous mask or a propagated mask is one mask (a SAM2 mask's RLE
# runs to ~255 KB); launches, reviews and user forms are a few KB.
DEFAULT_BODY_BYTES = MIB
# A draft carries every region's mask and its clicks: up to MAX_REGIONS of them (~20 MiB).
MASK_RLE_BYTES = 256 * 1024
CLICK_BYTES = 64  # {"x":1919.2534912109375,"y":1079.4967041015625,"label":1}
DRAFT_BODY_BYTES = MAX_REGIONS * (MASK_RLE_BYTES + MAX_CLICKS * CLICK_BYTES)
# A route open to anyone (the login form) takes no more than the server reads before a worker
# takes the request: a stranger's body never keeps a worker waiting.
PUBLIC_BODY_BYTES = READ_AHEAD_BYTES
# A file of exactly max_upload_mb comes wrapped in multipart boundaries and the form's other fields.
UPLOAD_ENVELOPE_BYTES = MIB
UPLOAD_ENDPOINT = "api.upload_video"
BODY_LIMITS = {"api.save_annotation": DRAFT_BODY_BYTES}


def upload_body_limit(settings: Settings) -> int:
    """The upload route's body limit in bytes: a file of ``max_upload_mb`` MiB and its envelope."""
    return settings.max_upload_mb * MIB + UPLOAD_ENVELOPE_BYTES


def body_limit(app: Flask, endpoint: str | None, settings: Settings) -> int:
    """The most bytes of body the route of ``endpoint`` takes."""
    if endpoint == UPLOAD_ENDPOINT:
        return upload_body_limit(settings)
    view = app.view_functions.get(endpoint or "")
    if getattr(view, ROLE_ATTR, None) == PUBLIC:
        return PUBLIC_BODY_BYTES
    return BODY_LIMITS.get(endpoint or "", DEFAULT_BODY_BYTES)


def size_text(n: int) -> str:
    """``n`` bytes for people: "512 bytes", "32 KiB", "2.5 MiB"."""
    if n < 1024:
        return f"{n} bytes"
    return f"{n / 1024:.3g} KiB" if n < MIB else f"{n / MIB:.3g} MiB"


class CappedStream(LimitedStream):
    """A streamed (chunked) body that answers 413 once a byte past ``limit`` arrives. werkzeug's own
    cap (``request.max_content_length``) stops at the limit and hands over what came so far: a JSON
    or urlencoded body cut short instead of a refusal."""

    def __init__(self, stream: IO[bytes], limit: int, message: str) -> None:
        super().__init__(stream, limit + 1, is_max=True)
        self.message = message

    def readinto(self, b: bytearray) -> int | None:  # type: ignore[override]
        n = super().readinto(b)
        if self.is_exhausted:  # the byte past the limit came
            self.on_exhausted()
        return n

    def on_exhausted(self) -> None:
        raise RequestEntityTooLarge(self.message)


def init_body_limits(app: Flask, settings: Settings) -> None:
    """Give every request its route's body limit; register before any hook that may read a body."""

    @app.errorhandler(BodyCut)
    def _cut(_: BodyCut) -> Any:
        limit = body_limit(current_app, request.endpoint, settings)
        return app.handle_http_exception(RequestEntityTooLarge(
            f"{request.method} {request.path} takes at most {size_text(limit)} of body"))

    @app.before_request
    def _limit_body() -> None:
        limit = body_limit(current_app, request.endpoint, settings)
        length = request.content_length
        if length is None:
            message = f"{request.method} {request.path} takes at most {size_text(limit)} of body"
            request.environ["wsgi.input"] = CappedStream(request.environ["wsgi.input"], limit, message)
        elif length > limit:
            abort(413, f"the request body is {size_text(length)}; {request.method} {request.path} takes at most "
                       f"{size_text(limit)}")
