"""Files served by a relative name from inside a folder the app owns (a run's, a report's)."""

from __future__ import annotations

import os
from pathlib import Path, PurePosixPath


def contained_file(root: Path, relative: str) -> Path | None:
    """``root/relative`` when it is a regular file reached without leaving ``root`` and without any
    symbolic link below ``root`` (a link planted inside could point anywhere); else None."""
    parts = PurePosixPath(relative)
    if not relative or "\0" in relative or parts.is_absolute() or ".." in parts.parts:
        return None
    base = Path(root).resolve()
    path = base / parts
    # Resolving changes the path exactly when some part of it below root is a link.
    if Path(os.path.normpath(path)) != path.resolve() or not path.is_file():
        return None
    return path
