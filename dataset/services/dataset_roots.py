"""Dataset folders a request may name: a root an admin registered in settings (``dataset_roots``,
by name) and a relative path inside it — never a server path.

A folder that does not exist and one that is not allowed (``..``, a symbolic link out of the root,
an absolute path) get the same answer, so a request learns nothing about the server's files.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path, PurePosixPath

from core.wording import quoted
from dataset.services.errors import InvalidInput


def folder_label(root: str, path: str = "") -> str:
    """How answers name a folder: ``root:relative/path``."""
    return f"{root}:{path}" if path else f"{root}:"


def resolve_folder(roots: Mapping[str, Path], root: str, path: str = "") -> Path:
    """The folder ``path`` inside the registered root ``root``; InvalidInput otherwise."""
    if root not in roots:
        known = ", ".join(sorted(roots)) or "none: an admin lists them as dataset_roots in the settings"
        raise InvalidInput(f"no dataset root named {quoted(root)}; registered roots: {known}")
    refused = InvalidInput(f"{quoted(folder_label(root, path))} is not a folder inside dataset root {quoted(root)}")
    relative = PurePosixPath(path)
    if "\0" in path or "\\" in path or relative.is_absolute() or ".." in relative.parts:
        raise refused
    try:
        base = Path(roots[root]).resolve()
        folder = (base / relative).resolve()
        inside = folder.is_relative_to(base) and folder.is_dir()
    except (OSError, RuntimeError):  # a part too long for the file system, a link loop (RuntimeError before 3.13)
        inside = False
    if not inside:
        raise refused
    return folder
