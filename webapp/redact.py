"""No answer shows an absolute server path: the last step of every page and JSON answer.

Services already name files the way answers should (a run's checkpoint by name, a dataset folder
as ``root:path``); this net catches what they pass through from elsewhere — a job's log, a
traceback in an error, a command-line job's parameters. Paths under the workspace become relative
to it, a registered dataset root becomes its name, the app's and Python's own folders (in
tracebacks) become ``[app]`` and ``[python]``. Only these known prefixes are rewritten, so the
app's URLs (``/api/v1/…``) and other text stay as they are. File downloads are not rewritten.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

from flask import Flask, Response, current_app

from dataset.settings import Settings

PROJECT_ROOT = Path(__file__).resolve().parent.parent
EXTENSION = "illusion_studio_redact"
_TEXT_TYPES = ("application/json", "text/html", "text/plain")


def path_rewrites(settings: Settings) -> list[tuple[re.Pattern[bytes], bytes, bytes]]:
    """(pattern, what ``folder/`` becomes, what the bare folder becomes) per known server folder, the
    longest first, so a folder inside another (the demo's workspace inside the app's checkout)
    keeps its own name."""
    named: dict[Path, tuple[str, str]] = {Path(settings.home): ("", "[workspace]"),
                                          Path(settings.media_root): ("media/", "media")}
    named.update({Path(folder): (f"{name}:", f"{name}:") for name, folder in settings.dataset_roots.items()})
    for folder, name in ((Path(sys.base_prefix), "[python]"), (Path(sys.prefix), "[python]"), (PROJECT_ROOT, "[app]")):
        named.setdefault(folder.resolve(), (f"{name}/", name))
    rewrites = []
    for folder in sorted(named, key=lambda p: len(str(p)), reverse=True):
        if folder == Path("/"):
            continue
        prefix = re.escape(str(folder).encode())
        # The folder followed by "/…", or the folder itself (not a longer name that starts with it).
        pattern = re.compile(prefix + rb"(/|(?![\w.-]))")
        rewrites.append((pattern, named[folder][0].encode(), named[folder][1].encode()))
    return rewrites


def redact(body: bytes, rewrites: list[tuple[re.Pattern[bytes], bytes, bytes]]) -> bytes:
    """``body`` with every known server folder rewritten (see :func:`path_rewrites`)."""
    for pattern, inside, bare in rewrites:
        body = pattern.sub(lambda m, i=inside, b=bare: i if m.group(1) else b, body)
    return body


def app_rewrites() -> list[tuple[re.Pattern[bytes], bytes, bytes]]:
    """This app's rewrites, for an answer the net does not see (a streamed file): take them in the
    view, since a stream runs after the request's context has gone."""
    return current_app.extensions[EXTENSION]


def init_redaction(app: Flask, settings: Settings) -> None:
    """Rewrite server paths out of every text answer the app builds."""
    rewrites = app.extensions[EXTENSION] = path_rewrites(settings)

    @app.after_request
    def _redact(response: Response) -> Response:
        if response.direct_passthrough or response.is_streamed or response.mimetype not in _TEXT_TYPES:
            return response
        body = response.get_data()
        redacted = redact(body, rewrites)
        if redacted != body:
            response.set_data(redacted)
        return response
