"""Imported checkpoints by name: where ``imported:NAME`` lives in a workspace, and the setting
``depth_model_path`` when it names an imported Depth Anything V2 model rather than a directory.

``illusion-studio checkpoints import`` writes a stereo network's file to
``<home>/checkpoints/imported/NAME.pt`` and a Depth Anything V2 model to the ``transformers``
directory ``<home>/checkpoints/imported/NAME/`` (``model.runs.registry``). The names resolve here,
below ``model``, because generation (``dataset``) and the train worker (``model``) both read
``depth_model_path`` and ``dataset`` never imports ``model``. Nothing is followed through a link:
a linked folder or file is not the workspace's own import.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from dataset.services.errors import InvalidInput, NotFound

IMPORTED = "imported"
IMPORTED_DIR = Path("checkpoints") / IMPORTED  # under the workspace home
IMPORTED_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}")
DEPTH_IMPORT_HINT = "`illusion-studio checkpoints import --from depth-anything-v2 FILE --name NAME` adds one"


def imported_path(home: Path, name: str) -> Path:
    """Where the imported checkpoint ``name`` lives; InvalidInput for a name that is not one."""
    if not IMPORTED_NAME.fullmatch(name):
        raise InvalidInput(f"imported checkpoint name {name!r}: use 1–64 letters, digits, '.', '_' or '-', "
                           "starting with a letter or digit")
    return Path(home) / IMPORTED_DIR / f"{name}.pt"


def imported_model_dir(home: Path, name: str) -> Path:
    """Where the imported depth model ``name`` (a ``transformers`` directory) lives; InvalidInput for a
    name that is not one."""
    return imported_path(home, name).with_suffix("")


def imported_names(home: Path, *, depth_models: bool = False) -> list[str]:
    """The workspace's imported checkpoints (``depth_models``: its imported depth-model directories), by
    name (never through a link)."""
    folder = Path(home) / IMPORTED_DIR
    if not folder.is_dir() or folder.is_symlink():
        return []
    if depth_models:
        return sorted(p.name for p in folder.iterdir() if p.is_dir() and not p.is_symlink()
                      and IMPORTED_NAME.fullmatch(p.name) and (p / "config.json").is_file())
    return sorted(p.stem for p in folder.glob("*.pt") if p.is_file() and not p.is_symlink()
                  and IMPORTED_NAME.fullmatch(p.stem))


def imported_depth_model(home: Path, name: str) -> Path:
    """The directory of the workspace's imported depth model ``name``; InvalidInput for a name that
    cannot be one, NotFound (one line: what is imported, how to import) for one that names nothing."""
    path = imported_model_dir(home, name)
    have = imported_names(home, depth_models=True)
    if name not in have:
        listed = ", ".join(f"{IMPORTED}:{n}" for n in have) or "none"
        raise NotFound(f"no imported depth model {name!r} (imported: {listed}; {DEPTH_IMPORT_HINT})")
    return path


def depth_model_dir(settings: Any) -> Path | None:
    """The Depth Anything V2 directory the setting ``depth_model_path`` names in the workspace of
    ``settings``: ``imported:NAME`` resolved against ``<home>/checkpoints/imported/``, any other value
    as the directory's path, None when unset. InvalidInput / NotFound (one line, naming the setting)
    for an ``imported:`` name that names nothing."""
    value = settings.depth_model_path
    if value is None:
        return None
    text = str(value)
    if not text.startswith(f"{IMPORTED}:"):
        return Path(value)
    try:
        return imported_depth_model(Path(settings.home), text.split(":", 1)[1])
    except (InvalidInput, NotFound) as exc:
        raise type(exc)(f"depth_model_path {text}: {exc}") from None
