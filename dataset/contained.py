"""The folders the app owns on disk — a run's (``runs/<id>``) and a report's (``evaluations/<id>``) —
and the files served from them by a relative name.

``runs/`` and ``evaluations/`` themselves may be links or mounts an admin made (shared storage across
machines): each is resolved once per process, the first time the process names it (the app and the
workers name theirs as they start), and that place is kept. Nothing below them may be a link, since
whoever could plant one could point it anywhere: a run's or a report's own folder that is a link is
refused (:class:`LinkedFolder`), to the jobs that would write into it as to the pages that would
read it, and a file is served only when no part of its path below the folder is a link.

A file is served from the descriptor :func:`open_contained` opens, walking down from ``runs/`` (or
``evaluations/``) one name at a time without following links: checking a path and opening it again
later would serve whatever a swap put under that name meanwhile. A regular file with a second (hard)
link is not served either: that link may be the name of a file outside the workspace.
"""

from __future__ import annotations

import fcntl
import functools
import os
from collections.abc import Callable
from pathlib import Path, PurePosixPath
from stat import S_ISREG
from typing import TYPE_CHECKING, BinaryIO

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
    """``folder/relative`` when :func:`open_contained` would open it (a regular file with one link,
    reached without leaving ``folder`` and without any symbolic link); else None. Only for a check or
    a message: a caller that reads or serves the file opens it with :func:`open_contained`, since
    the name may be swapped for a link between this check and a later open by path."""
    file = open_contained(folder, relative)
    if file is None:
        return None
    file.close()
    return Path(folder) / PurePosixPath(relative)


# Never follow a link, never block (a FIFO planted under a served name would hold the worker until a
# writer came), never take a terminal as the process's own.
_WALK = os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC | os.O_NONBLOCK | os.O_NOCTTY
SharedLinks = Callable[[int, str, int], bool]  # (the folder's descriptor, the file's name, its descriptor)


def open_contained(folder: Path, relative: str, *, shared: SharedLinks | None = None) -> BinaryIO | None:
    """``folder/relative`` opened for reading, or None when it is missing, not a regular file, has
    more than one (hard) link, or is reached through a symbolic link anywhere below ``folder``'s
    parent — ``folder`` being an :func:`owned_folder` (``storage_root(top)/name``) — or through
    ``..``. Each part is opened from its parent's descriptor without following links, so no swap of
    a name for a link, before or after, changes which file is served: serve and read what this
    returns, never the path again. ``shared(dir_fd, name, fd)`` may accept a file with more than
    one link (the caller's own second name for it in the same folder)."""
    parts = _parts(relative)
    if parts is None:
        return None
    folder = Path(folder)
    try:
        # The top folder (storage_root's, resolved once per process) is opened by its path; from it
        # on, nothing is.
        parent = os.open(folder.parent, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    except OSError:
        return None
    try:
        for name in (folder.name, *parts[:-1]):
            below = os.open(name, _WALK | os.O_DIRECTORY, dir_fd=parent)
            os.close(parent)
            parent = below
        fd = os.open(parts[-1], _WALK, dir_fd=parent)
    except (OSError, ValueError):  # missing, a link (ELOOP), not a folder, a name too long, a NUL
        os.close(parent)
        return None
    try:
        served = _served(parent, parts[-1], fd, shared)
    except OSError:
        served = False
    finally:
        os.close(parent)
    if not served:
        os.close(fd)
        return None
    # Reads of a regular file never block anyway; the flag was for the open alone.
    fcntl.fcntl(fd, fcntl.F_SETFL, fcntl.fcntl(fd, fcntl.F_GETFL) & ~os.O_NONBLOCK)
    return os.fdopen(fd, "rb")


def _parts(relative: str) -> tuple[str, ...] | None:
    """The names ``relative`` walks through, or None for an empty, absolute or ``..`` path."""
    if not relative or "\0" in relative:
        return None
    path = PurePosixPath(relative)
    if path.is_absolute() or ".." in path.parts or not path.parts:
        return None
    return path.parts


def _served(dir_fd: int, name: str, fd: int, shared: SharedLinks | None) -> bool:
    """Whether the opened ``fd`` may be served: a regular file whose only link is ``name``, or one
    ``shared`` accepts. A second link may be one to a file outside the workspace (a secret)."""
    stat = os.fstat(fd)
    if not S_ISREG(stat.st_mode):
        return False
    if stat.st_nlink != 1:
        return shared is not None and shared(dir_fd, name, fd)
    # One link now is not enough: a second link present at the open and removed since leaves the file
    # opened (the outside one) with its one outside link. ``name`` must still be that file, with that
    # one link, and the count must not have moved meanwhile (a link made or removed changes the ctime).
    named = os.stat(name, dir_fd=dir_fd, follow_symlinks=False)
    again = os.fstat(fd)
    return ((named.st_dev, named.st_ino) == (stat.st_dev, stat.st_ino) and named.st_nlink == 1
            and again.st_nlink == 1 and again.st_ctime_ns == stat.st_ctime_ns)
