"""Exports are written into a hidden folder next to the target and renamed into place at the end.

So the target is at every moment absent, the previous dataset, or the complete new one: a crashed
export never leaves a half dataset that looks complete. A crash leaves only the hidden
``.<name>.partial-<tag>`` folder, which the next attempt with the same tag (a retried job) removes.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from dataset.export.errors import LayoutError


@contextmanager
def staged_dir(out: Path, *, tag: str, overwrite: bool = False) -> Iterator[Path]:
    """Yield an empty staging folder; when the block succeeds it becomes ``out``.

    ``out`` must not exist, be an empty folder, or (with ``overwrite``) be replaced as a whole.
    """
    out = Path(out).absolute()
    check_target(out, overwrite=overwrite)
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = out.parent / f".{out.name}.partial-{tag}"
    shutil.rmtree(staging, ignore_errors=True)
    staging.mkdir()
    try:
        yield staging
        _replace(staging, out, tag)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def check_target(out: Path, *, overwrite: bool) -> None:
    """Refuse an ``out`` that exists and is not an empty folder (unless ``overwrite`` and a folder)."""
    if not out.exists() or (out.is_dir() and not any(out.iterdir())):
        return
    # --overwrite replaces an earlier export only: never a folder that merely happens to be there.
    earlier_export = (out / "manifest.json").is_file() or (out / "meta_data" / "scale_factors.csv").is_file()
    if not (overwrite and out.is_dir() and earlier_export):
        raise LayoutError(f"{out} already exists and is not an empty folder"
                          + ("" if overwrite else "; choose another path or overwrite an earlier export")
                          + (" (nor an earlier export, so it is not overwritten)" if overwrite else ""))


def _replace(staging: Path, out: Path, tag: str) -> None:
    if out.is_dir() and any(out.iterdir()):
        old = out.parent / f".{out.name}.old-{tag}"
        shutil.rmtree(old, ignore_errors=True)
        os.rename(out, old)
        os.rename(staging, out)
        shutil.rmtree(old)
    else:
        os.replace(staging, out)  # rename(2) replaces an empty folder in one step


def write_bytes(path: Path, data: bytes) -> None:
    """Write a file of a staged export (parents created; no per-file rename: the folder is staged)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(data)


def copy_file(src: Path, dst: Path) -> None:
    """Copy a media file into a staged export, byte for byte."""
    dst.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(src, dst)
