"""Finding the files of an import folder: one subfolder per kind of file, matched by file stem."""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from pathlib import Path

from dataset.capture.errors import CaptureError

_TRAILING_NUMBER = re.compile(r"(\d+)$")
_DIGITS = re.compile(r"(\d+)")
_SHOWN = 5  # names listed in an error message before "…"


def files_by_stem(folder: Path, suffixes: Iterable[str]) -> dict[str, Path]:
    """``{stem: file}`` of the files in ``folder`` whose suffix (case-insensitive) is one of
    ``suffixes``; hidden files are skipped, and two files with one stem are an error."""
    if not folder.is_dir():
        raise CaptureError(f"{folder}: folder not found")
    allowed = {s.lower() for s in suffixes}
    found: dict[str, Path] = {}
    for path in sorted(folder.iterdir()):
        if path.name.startswith(".") or not path.is_file() or path.suffix.lower() not in allowed:
            continue
        if path.stem in found:
            raise CaptureError(f"{folder}: two files for {path.stem!r}: {found[path.stem].name} and {path.name}")
        found[path.stem] = path
    return found


def matched_stems(groups: Mapping[str, Mapping[str, Path]]) -> list[str]:
    """The stems every group has, in natural order; any stem missing from some group is an error
    that names the group and the stems."""
    stems = set().union(*(g.keys() for g in groups.values()))
    problems = [f"{name}/ lacks {names(sorted(stems - g.keys(), key=natural_key))}"
                for name, g in groups.items() if stems - g.keys()]
    if problems:
        raise CaptureError("unmatched files: " + "; ".join(problems))
    if not stems:
        raise CaptureError(f"no files found in {', '.join(f'{name}/' for name in groups)}")
    return sorted(stems, key=natural_key)


def natural_key(stem: str) -> tuple[object, ...]:
    """Sort key that orders embedded numbers by value: frame_2 before frame_10."""
    return tuple(int(part) if part.isdigit() else part for part in _DIGITS.split(stem))


def trailing_number(stem: str) -> int | None:
    """The number a stem ends with (``frame_000012`` → 12), or None."""
    match = _TRAILING_NUMBER.search(stem)
    return int(match.group(1)) if match else None


def names(items: list[str]) -> str:
    """A short list for an error message: the first few names, then how many more."""
    shown = ", ".join(items[:_SHOWN])
    return shown + (f" and {len(items) - _SHOWN} more" if len(items) > _SHOWN else "")


