"""No answer shows an absolute server path: the last step of every page and JSON answer.

Services already name files the way answers should (a run's checkpoint by name, a dataset folder
as ``root:path``); this net catches what they pass through from elsewhere — a job's log, a
traceback in an error, a command-line job's parameters. Paths under the workspace become relative
to it, a registered dataset root becomes its name, the app's and Python's own folders (in
tracebacks) become ``[app]`` and ``[python]``. Only these known prefixes are rewritten, so the
app's URLs (``/api/v1/…``) and other text stay as they are. File downloads are not rewritten.
"""

from __future__ import annotations

import os
import re
import sys
from dataclasses import dataclass
from pathlib import Path

from flask import Flask, Response, current_app

from dataset.settings import Settings

PROJECT_ROOT = Path(__file__).resolve().parent.parent
EXTENSION = "illusion_studio_redact"
_TEXT_TYPES = ("application/json", "text/html", "text/plain")
Rewrite = tuple[re.Pattern[bytes], bytes, bytes]


@dataclass(frozen=True)
class Redactor:
    """Rewrites server paths out of a text answer: first the known folders (see :func:`known_folders`),
    then any other absolute path under a top-level folder of this machine — one a command-line job
    named, a system library in a traceback — down to its last part (``…/name``)."""

    folders: list[Rewrite]
    others: re.Pattern[bytes] | None

    def __call__(self, body: bytes) -> bytes:
        for pattern, inside, bare in self.folders:
            body = pattern.sub(lambda m, i=inside, b=bare: i if m.group(1) else b, body)
        if self.others is not None:
            body = self.others.sub(lambda m: b"\xe2\x80\xa6/" + m.group(0).rstrip(b"/").rpartition(b"/")[2], body)
        return body


def known_folders(settings: Settings) -> list[Rewrite]:
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


def other_server_paths(url_segments: set[str]) -> re.Pattern[bytes] | None:
    """Absolute paths that start with a top-level folder of this machine (``/tmp/…``, ``/usr/…``),
    except the first parts of the app's own URLs (``/media/…`` is a route here, not the folder)."""
    tops = sorted(name for name in os.listdir("/") if name not in url_segments and re.fullmatch(r"[\w.-]+", name))
    if not tops:
        return None
    names = b"|".join(re.escape(name.encode()) for name in tops)
    # Not after a word, a path, a URL's host or a marker this net wrote (``[python]/lib/…``), nor a
    # label's colon (``root:path`` names a place in a registered root).
    return re.compile(rb"(?<![\w.~/:\]-])/(?:" + names + rb")(?:/[\w.@+~%-]+)*/?(?![\w.-])")


def redactor_for(app: Flask, settings: Settings) -> Redactor:
    """The app's redactor: its URLs' first parts are known once its routes are registered."""
    segments = {rule.rule.lstrip("/").split("/", 1)[0] for rule in app.url_map.iter_rules()}
    return Redactor(known_folders(settings), other_server_paths(segments))


def app_redactor() -> Redactor:
    """This app's redactor, for an answer the net does not see (a streamed file): take it in the
    view, since a stream runs after the request's context has gone."""
    return current_app.extensions[EXTENSION]


def init_redaction(app: Flask, settings: Settings) -> None:
    """Rewrite server paths out of every text answer the app builds. Call it once the app's routes
    are registered."""
    redactor = app.extensions[EXTENSION] = redactor_for(app, settings)

    @app.after_request
    def _redact(response: Response) -> Response:
        if response.direct_passthrough or response.is_streamed or response.mimetype not in _TEXT_TYPES:
            return response
        body = response.get_data()
        redacted = redactor(body)
        if redacted != body:
            response.set_data(redacted)
        return response
