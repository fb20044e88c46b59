"""Rank 0's log of a training run, as the pages show it: its tail while the run goes, the whole of
it to download. The lines are the trainers' own; the web layer rewrites server folders out of them
(``webapp/redact.py``).

``torchrun --log-dir RUN_DIR/logs`` (``model/runs/launcher.py``) writes every rank's output to
``logs/<rendezvous id>_<random>/attempt_<n>/<local rank>/{stdout,stderr}.log``, one rendezvous
folder per launch (a resume is a new launch). Rank 0's log is its two files of every launch,
oldest launch first, stdout before stderr (a traceback ends its launch).

The folders are listed by name, but every file is read from the descriptor
:func:`dataset.contained.open_contained` opens (no link anywhere below the run's folder, a regular
file with a single link), never by its path again: a log file swapped for a link, or a hard link to
a file outside the workspace, is never read.
"""

from __future__ import annotations

import io
import os
from collections.abc import Iterator
from contextlib import ExitStack
from pathlib import Path
from typing import BinaryIO

from dataset.contained import open_contained
from dataset.run_layout import LOG_DIR

RANK = "0"
STREAMS = ("stdout.log", "stderr.log")
TAIL_MAX_BYTES = 256 * 1024  # read of a file's end for its tail: far more than the lines a page shows

Opened = list[tuple[Path, BinaryIO]]  # rank 0's log files, each with the file open_contained opened


def rank0_files(run_dir: Path) -> list[Path]:
    """Rank 0's log files under ``run_dir/logs``: launches oldest first, stdout then stderr.

    Only regular files with a single link, reached inside the run directory without a symbolic
    link, count (a planted link is never followed). Only for listing: the readers below read what
    they opened themselves."""
    with ExitStack() as stack:
        return [path for path, _ in _open_rank0(run_dir, stack)]


def _open_rank0(run_dir: Path, stack: ExitStack) -> Opened:
    """Rank 0's log files that :func:`open_contained` opens, each closed with ``stack``."""
    opened = []
    for path in _candidates(run_dir):
        file = open_contained(run_dir, path.relative_to(run_dir).as_posix())
        if file is not None:
            opened.append((path, stack.enter_context(file)))
    return opened


def _candidates(run_dir: Path) -> list[Path]:
    """The names rank 0's log files have, in order, whatever they are (the listing only: nothing is read)."""
    logs = run_dir / LOG_DIR
    if not logs.is_dir() or logs.is_symlink():
        return []
    return [attempt / RANK / stream
            for launch in sorted(_subdirs(logs), key=_started)
            for attempt in sorted(_subdirs(launch, "attempt_"), key=lambda p: _attempt_number(p.name))
            for stream in STREAMS]


def _subdirs(folder: Path, prefix: str = "") -> list[Path]:
    return [p for p in folder.iterdir() if p.name.startswith(prefix) and p.is_dir() and not p.is_symlink()]


def _started(launch: Path) -> float:
    """When a launch wrote first: its rank folders appear as it starts (a folder's own times move later)."""
    times = [p.stat().st_mtime for p in launch.glob(f"attempt_*/{RANK}")]
    return min(times, default=launch.stat().st_mtime)


def _attempt_number(name: str) -> int:
    digits = name.removeprefix("attempt_")
    return int(digits) if digits.isdigit() else 0


def _header(run_dir: Path, path: Path, index: int, count: int) -> str:
    return f"── {index} of {count}: {path.relative_to(run_dir)} ──"


def log_lines(run_dir: Path) -> Iterator[str]:
    """The whole of rank 0's log, line by line (each ending in a newline); each file opens with a
    header naming it relative to the run directory."""
    with ExitStack() as stack:
        files = _open_rank0(run_dir, stack)
        for index, (path, file) in enumerate(files, 1):
            yield _header(run_dir, path, index, len(files)) + "\n"
            # As open(path, "r") read it: universal newlines, undecodable bytes replaced.
            with io.TextIOWrapper(file, encoding="utf-8", errors="replace") as handle:
                for line in handle:
                    yield line if line.endswith("\n") else line + "\n"


def tail(run_dir: Path, count: int) -> dict[str, object]:
    """The last ``count`` lines of rank 0's log (headers included): ``lines``, the ``files``
    (relative to the run directory), their total ``bytes`` and whether earlier lines were left out
    (``more``)."""
    with ExitStack() as stack:
        files = _open_rank0(run_dir, stack)
        lines: list[str] = []
        more = False
        for index in range(len(files), 0, -1):
            path, file = files[index - 1]
            wanted = count - len(lines)
            if wanted <= 0:
                more = True
                break
            body, cut = _last_lines(file, wanted)
            block = [_header(run_dir, path, index, len(files)), *body]
            if len(block) > wanted or cut:
                more = True
            lines = block[-wanted:] + lines
        return {"lines": lines,
                "files": [str(p.relative_to(run_dir)) for p, _ in files],
                "bytes": sum(os.fstat(f.fileno()).st_size for _, f in files), "more": more}


def _last_lines(file: BinaryIO, count: int) -> tuple[list[str], bool]:
    """Up to ``count`` last lines of an open file (read from its end) and whether earlier ones exist."""
    size = os.fstat(file.fileno()).st_size
    file.seek(max(0, size - TAIL_MAX_BYTES))
    data = file.read(TAIL_MAX_BYTES)
    lines = data.decode("utf-8", "replace").splitlines()
    if size > TAIL_MAX_BYTES and lines:
        lines = lines[1:]  # the first is a part of a line
    return lines[-count:], size > TAIL_MAX_BYTES or len(lines) > count
