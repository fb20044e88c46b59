"""The folders the app owns on disk — a run's (``runs/<id>``) and a report's (``evaluations/<id>``) —
and the files served from them by a relative name.

``runs/`` and ``evaluations/`` themselves may be links or mounts an admin made (shared storage across
machines): each is resolved once per process, the first time the process names it (the app and the
workers name theirs as they start), and that place is kept. Nothing below them may be a link, since
whoever could plant one could point it anywhere: a run's or a report's own folder that is a link is
refused (:class:`LinkedFolder`), to the jobs that would write into it as to the pages that would
read it, and a file is served only when no part of its path below the folder is a link.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path, PurePosixPath
from typing import TYPE_CHECKING

from dataset.services.errors import NotFound

if TYPE_CHECKING:
    from dataset.settings import Settings

REPORTS = "evaluations"  # the workspace's folder of evaluation reports, beside runs/


class LinkedFolder(NotFound):
    """A run's or a report's folder, or a folder or file inside one, is a symbolic link: not the app's."""


@functools.cache
def storage_root(folder: Path) -> Path:
    """``runs/`` or ``evaluations/`` as this process uses them: followed once if an admin made it a
    link, then never again (a link swapped in later is not followed)."""
    return Path(folder).resolve()


def resolve_storage(settings: Settings) -> None:
    """Resolve the workspace's ``runs/`` and ``evaluations/`` now, as a process (the app, a worker) starts."""
    storage_root(settings.runs_dir)
    storage_root(Path(settings.home) / REPORTS)


def owned_folder(top: Path, name: str, *, whole: bool = False) -> Path:
    """``top/name``, a run's or a report's own folder, under :func:`storage_root`; LinkedFolder when
    it is a symbolic link or, with ``whole`` (a job about to write into it), when anything below it is."""
    label = f"{Path(top).name}/{name}"
    folder = storage_root(Path(top)) / name
    linked = folder if folder.is_symlink() else _first_link(folder) if whole else None
    if linked is not None:
        what = PurePosixPath(label, linked.relative_to(folder).as_posix()) if linked != folder else label
        raise LinkedFolder(f"{what} is a symbolic link: {Path(top).name}/ may be one an admin made, "
                           f"nothing below it may be (remove the link)")
    return folder


def _first_link(folder: Path) -> Path | None:
    for parent, dirs, files in os.walk(folder):  # never descends into a linked folder
        for name in sorted(dirs + files):
            if os.path.islink(os.path.join(parent, name)):
                return Path(parent, name)
    return None


def contained_file(folder: Path, relative: str) -> Path | None:
    """``folder/relative`` when it is a regular file reached without leaving ``folder`` (an
    :func:`owned_folder`, itself no link) and without any symbolic link below it; else None.
    A name the file system refuses (a part over 255 bytes, a link loop) is None too."""
    parts = PurePosixPath(relative)
    if not relative or "\0" in relative or parts.is_absolute() or ".." in parts.parts:
        return None
    path = Path(folder) / parts
    try:
        # The folder's own path has no link (its parent is resolved, it is not one): resolving changes
        # the path exactly when some part of it below the folder is a link.
        if Path(os.path.normpath(path)) != path.resolve(strict=True) or not path.is_file():
            return None
    except (OSError, RuntimeError):  # missing, a name too long, a loop (RuntimeError before Python 3.13)
        return None
    return path
