"""Server paths kept out of what answers show from the sources that bring them in.

Answers name files the app's way (a run's checkpoint by name, a dataset folder as ``root:path``), and
what people type is shown as they typed it. Paths come in with text from outside the app's own
answers: a job's log (a traceback, a trainer's output), its error, a command-line job's parameters and
what it returned, a run's end reason, a run's log files and a report's files. Those are rewritten where
they are shown, with what this module knows of the machine: paths under the workspace become
relative to it, a registered dataset root becomes its name, the media store ``media``, the app's and
Python's own folders (in tracebacks) ``[app]`` and ``[python]``, and any other absolute path under a
top-level folder of this machine (``/usr/…``, ``/tmp/…``) its last part (``…/name``).

The web app makes its redactor the current one for each request (``webapp.redact``), so services
that build answers (:func:`dataset.services.jobs.job_json`) call :func:`shown` without knowing the
web; outside a request (the command line, whose user has a shell) :func:`shown` changes nothing.
"""

from __future__ import annotations

import functools
import os
import re
import sys
from collections.abc import Mapping
from contextvars import ContextVar, Token
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

from dataset.settings import Settings

PROJECT_ROOT = Path(__file__).resolve().parent.parent
Rewrite = tuple[re.Pattern[str], str, str]
T = TypeVar("T")


@dataclass(frozen=True)
class Redactor:
    """Rewrites server paths out of text: first the known folders (see :func:`known_folders`), then
    any other absolute path under a top-level folder of this machine down to its last part."""

    folders: tuple[Rewrite, ...]
    others: re.Pattern[str] | None

    def __call__(self, text: str) -> str:
        for pattern, inside, bare in self.folders:
            text = pattern.sub(lambda m, i=inside, b=bare: i if m.group(1) else b, text)
        if self.others is not None:
            text = self.others.sub(lambda m: "…/" + m.group(0).rstrip("/").rpartition("/")[2], text)
        return text

    def value(self, value: T) -> T:
        """``value`` with every string in it rewritten (JSON-like data: mappings, lists, strings)."""
        if isinstance(value, str):
            return self(value)  # type: ignore[return-value]
        if isinstance(value, Mapping):
            return {key: self.value(item) for key, item in value.items()}  # type: ignore[return-value]
        if isinstance(value, list | tuple):
            return [self.value(item) for item in value]  # type: ignore[return-value]
        return value


def known_folders(home: Path | None, media_root: Path | None,
                  dataset_roots: Mapping[str, Path]) -> tuple[Rewrite, ...]:
    """(pattern, what ``folder/`` becomes, what the bare folder becomes) per known server folder, the
    longest first, so a folder inside another (the demo's workspace inside the app's checkout)
    keeps its own name."""
    named: dict[Path, tuple[str, str]] = {}
    if home is not None:
        named[Path(home)] = ("", "[workspace]")
    if media_root is not None:
        named[Path(media_root)] = ("media/", "media")
    named.update({Path(folder): (f"{name}:", f"{name}:") for name, folder in dataset_roots.items()})
    for folder, name in ((Path(sys.base_prefix), "[python]"), (Path(sys.prefix), "[python]"), (PROJECT_ROOT, "[app]")):
        named.setdefault(folder.resolve(), (f"{name}/", name))
    rewrites = []
    for folder in sorted(named, key=lambda p: len(str(p)), reverse=True):
        if folder == Path("/"):
            continue
        # The folder followed by "/…", or the folder itself (not a longer name that starts with it).
        pattern = re.compile(re.escape(str(folder)) + r"(/|(?![\w.-]))")
        rewrites.append((pattern, *named[folder]))
    return tuple(rewrites)


def other_server_paths() -> re.Pattern[str] | None:
    """Absolute paths that start with a top-level folder of this machine (``/tmp/…``, ``/usr/…``);
    text such as a URL's path (``/api/v1/…``) names none and stays as it is."""
    tops = sorted(name for name in os.listdir("/") if re.fullmatch(r"[\w.-]+", name))
    if not tops:
        return None
    names = "|".join(re.escape(name) for name in tops)
    # Not after a word, a path, a URL's host or a marker this net wrote (``[python]/lib/…``), nor a
    # label's colon (``root:path`` names a place in a registered root).
    return re.compile(r"(?<![\w.~/:\]-])/(?:" + names + r")(?:/[\w.@+~%-]+)*/?(?![\w.-])")


@functools.lru_cache(maxsize=32)
def _redactor(home: Path | None, media_root: Path | None, roots: tuple[tuple[str, Path], ...]) -> Redactor:
    return Redactor(known_folders(home, media_root, dict(roots)), other_server_paths())


def redactor_for(settings: Settings | None) -> Redactor:
    """The redactor of a workspace (built once per workspace and process); without settings, the one
    that knows only the app's, Python's and the machine's folders."""
    if settings is None:
        return _redactor(None, None, ())
    return _redactor(Path(settings.home), Path(settings.media_root), tuple(sorted(settings.dataset_roots.items())))


_CURRENT: ContextVar[Redactor | None] = ContextVar("illusion_studio_redactor", default=None)


def use_redactor(redactor: Redactor | None) -> Token[Redactor | None]:
    """Make ``redactor`` the one :func:`shown` applies in this context (a request); returns the token
    that :func:`stop_using` takes to restore the one before."""
    return _CURRENT.set(redactor)


def stop_using(token: Token[Redactor | None]) -> None:
    _CURRENT.reset(token)


def redacted(value: T) -> T:
    """``value`` (text or JSON-like data from a source that may carry server paths) as the answer
    being built may show it: rewritten by the current request's redactor; as it is outside a request."""
    redactor = _CURRENT.get()
    return value if redactor is None else redactor.value(value)
