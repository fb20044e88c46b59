"""Rank 0's log of a training run, as the pages show it: its tail while the run goes, the whole of
it to download. The lines are the trainers' own; the web layer rewrites server folders out of them
(``webapp/redact.py``).

``torchrun --log-dir RUN_DIR/logs`` (``model/launcher.py``) writes every rank's output to
``logs/<rendezvous id>_<random>/attempt_<n>/<local rank>/{stdout,stderr}.log``, one rendezvous
folder per launch (a resume is a new launch). Rank 0's log is its two files of every launch,
oldest launch first, stdout before stderr (a traceback ends its launch).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

RANK = "0"
STREAMS = ("stdout.log", "stderr.log")
TAIL_MAX_BYTES = 256 * 1024  # read of a file's end for its tail: far more than the lines a page shows


def rank0_files(run_dir: Path) -> list[Path]:
    """Rank 0's log files under ``run_dir/logs``: launches oldest first, stdout then stderr.

    Only regular files inside the run directory count (a planted symlink is never followed)."""
    logs = run_dir / "logs"
    if not logs.is_dir() or logs.is_symlink():
        return []
    root = run_dir.resolve()
    files = []
    for launch in sorted(_subdirs(logs), key=_started):
        for attempt in sorted(_subdirs(launch, "attempt_"), key=lambda p: _attempt_number(p.name)):
            for stream in STREAMS:
                path = attempt / RANK / stream
                if path.is_file() and not path.is_symlink() and path.resolve().is_relative_to(root):
                    files.append(path)
    return files


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
    files = rank0_files(run_dir)
    for index, path in enumerate(files, 1):
        yield _header(run_dir, path, index, len(files)) + "\n"
        with path.open("r", encoding="utf-8", errors="replace") as handle:
            for line in handle:
                yield line if line.endswith("\n") else line + "\n"


def tail(run_dir: Path, count: int) -> dict[str, object]:
    """The last ``count`` lines of rank 0's log (headers included): ``lines``, the ``files``
    (relative to the run directory), their total ``bytes`` and whether earlier lines were left out
    (``more``)."""
    files = rank0_files(run_dir)
    lines: list[str] = []
    more = False
    for index in range(len(files), 0, -1):
        path = files[index - 1]
        wanted = count - len(lines)
        if wanted <= 0:
            more = True
            break
        body, cut = _last_lines(path, wanted)
        block = [_header(run_dir, path, index, len(files)), *body]
        if len(block) > wanted or cut:
            more = True
        lines = block[-wanted:] + lines
    return {"lines": lines,
            "files": [str(p.relative_to(run_dir)) for p in files],
            "bytes": sum(p.stat().st_size for p in files), "more": more}


def _last_lines(path: Path, count: int) -> tuple[list[str], bool]:
    """Up to ``count`` last lines of a file (read from its end) and whether earlier ones exist."""
    size = path.stat().st_size
    with path.open("rb") as handle:
        handle.seek(max(0, size - TAIL_MAX_BYTES))
        data = handle.read(TAIL_MAX_BYTES)
    lines = data.decode("utf-8", "replace").splitlines()
    if size > TAIL_MAX_BYTES and lines:
        lines = lines[1:]  # the first is a part of a line
    return lines[-count:], size > TAIL_MAX_BYTES or len(lines) > count
