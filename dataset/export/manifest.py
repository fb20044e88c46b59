"""The native export's ``manifest.json``: deterministic JSON out, validated JSON in.

The manifest holds no wall-clock time of the export: the same samples give the same bytes, so an
export can be checksummed, diffed and compared across workspaces. When an export was made is
recorded in its job row; when each sample was generated is in the sample's ``created_at``.
"""

from __future__ import annotations

import enum
import json
from pathlib import Path, PurePosixPath
from typing import Any

from dataset.export.errors import LayoutError
from dataset.states import FrameState, IllusionType, SampleState, SourceKind
from dataset.version import code_version

FORMAT = "illusion-studio/native"
FORMAT_VERSION = 1
MANIFEST = "manifest.json"


def created_by() -> str:
    return f"illusion-studio {code_version()}"


def dump_json(value: Any) -> bytes:
    """Canonical JSON: sorted keys, two-space indent, UTF-8, a final newline; NaN is refused."""
    return (json.dumps(value, indent=2, sort_keys=True, ensure_ascii=False, allow_nan=False) + "\n").encode()


def read_json(path: Path, what: str) -> Any:
    """Parse a JSON file of a dataset folder; a missing or malformed file is a :class:`LayoutError`."""
    if not path.is_file():
        raise LayoutError(f"{path}: missing ({what})")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise LayoutError(f"{path}: not readable JSON ({what}): {exc}") from None


def read_manifest(root: Path) -> dict[str, Any]:
    """The manifest of the native export at ``root``, checked for the fields import relies on."""
    if not root.is_dir():
        raise LayoutError(f"{root}: no such folder")
    path = root / MANIFEST
    if not path.is_file():
        raise LayoutError(f"{root}: no {MANIFEST}; not a native Illusion Studio export "
                          "(export with --format native, or import the authors' layout with --format authors)")
    data = read_json(path, "the export's manifest")
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise LayoutError(f"{path}: not an {FORMAT} manifest (format is {_get(data, 'format')!r})")
    if not isinstance(data.get("format_version"), int) or data["format_version"] > FORMAT_VERSION:
        raise LayoutError(f"{path}: format version {data.get('format_version')!r} is newer than this tool reads "
                          f"({FORMAT_VERSION}); upgrade Illusion Studio")
    _check(path, data, {"videos": dict, "samples": list, "splits": list})
    for n, split in enumerate(data["splits"]):
        _check(path, split, {"name": str, "annotations": str}, f"split {n}")
    for name, video in data["videos"].items():
        _check(path, video, {"name": str, "content_sha256": str, "source_kind": str, "illusion_types": list,
                             "meta": dict}, f"video {name!r}")
        _member(path, f"video {name!r}", video["source_kind"], SourceKind)
    for n, sample in enumerate(data["samples"]):
        where = f"sample {n} ({_get(sample, 'id')})"
        _check(path, sample, {"id": str, "split": str, "video": str, "frame": dict, "files": dict, "state": str,
                              "flagged": bool, "params": dict, "provenance": dict, "qa": dict}, where)
        _check(path, sample["frame"], {"index": int, "time_s": (int, float), "width": int, "height": int,
                                       "state": str}, f"{where} frame")
        _member(path, where, sample["state"], SampleState)
        _member(path, f"{where} frame", sample["frame"]["state"], FrameState)
        if sample.get("illusion_type") is not None:
            _member(path, where, sample["illusion_type"], IllusionType)
        if sample["video"] not in data["videos"]:
            raise LayoutError(f"{path}: {where} names video {sample['video']!r}, which the manifest does not list")
        if "left" not in sample["files"]:
            raise LayoutError(f"{path}: {where} has no left image")
    return data


def _get(value: Any, key: str) -> Any:
    return value.get(key) if isinstance(value, dict) else None


def _check(path: Path, value: Any, fields: dict[str, type | tuple[type, ...]], where: str = "top level") -> None:
    for key, kind in fields.items():
        if not isinstance(_get(value, key), kind) or isinstance(_get(value, key), bool) and kind is int:
            raise LayoutError(f"{path}: {where}: field {key!r} is missing or not a {_type_name(kind)}")


def _member(path: Path, where: str, value: str, kind: type[enum.StrEnum]) -> None:
    if value not in kind.__members__:
        raise LayoutError(f"{path}: {where}: {value!r} is not one of {', '.join(kind)}")


def _type_name(kind: type | tuple[type, ...]) -> str:
    return "number" if isinstance(kind, tuple) else {dict: "object", list: "list", str: "string"}.get(kind, kind.__name__)


def manifest_file(root: Path, relative: str, what: str) -> Path:
    """``root/relative``, a file a manifest names: it must exist and stay inside ``root`` — no
    absolute path, no ``..``, no symbolic link out (a dataset from elsewhere could name any file)."""
    path = root / relative
    if PurePosixPath(relative).is_absolute() or ".." in PurePosixPath(relative).parts \
            or not path.resolve().is_relative_to(root.resolve()):
        raise LayoutError(f"{root / MANIFEST}: {what}: path {relative!r} leaves the dataset folder")
    if not path.is_file():
        raise LayoutError(f"{path}: missing, but {MANIFEST} names it ({what})")
    return path
