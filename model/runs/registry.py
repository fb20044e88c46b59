"""Checkpoints by name: a run's ``best``, ``last`` or one of its files — what a request may name
instead of a server path — an imported checkpoint, and the current model, which ``predict`` and
evaluation use when none is named.

One way to name a checkpoint (:func:`resolve`): ``RUN:NAME`` — a run's ``best``, ``last`` or file
name, as the web's forms name it (``3:best``, ``3:step_0001000.pt``) — or ``imported:NAME``, a
checkpoint ``illusion-studio checkpoints import`` wrote to ``<home>/checkpoints/imported/NAME.pt``
(a Depth Anything V2 depth model: the ``transformers`` directory ``<home>/checkpoints/imported/NAME/``,
which ``illusion-studio depth`` runs); the command line may also give a file's path.

``<home>/models/current.json`` = ``{"run": id, "file": name, "step": n, "checkpoint": path}``
(the path relative to the workspace for a run's file; absolute only for a file the command line
promoted from outside any run), written atomically. Checkpoints that must outlive the engine's
keep-last-k rotation (the current model, those an evaluation pinned) are listed in their run's
``keep.json``; a run's ``best.pt``, replaced whenever validation improves, is pinned as a hard
link ``best_step_XXXXXXX.pt`` that stays put.
"""

from __future__ import annotations

import fcntl
import functools
import importlib
import json
import os
import re
import uuid
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

from sqlalchemy.orm import Session

from core.atomic import atomic_write_bytes
from dataset.contained import LinkedFolder, open_contained
from dataset.imported import IMPORTED, imported_depth_model, imported_model_dir, imported_names, imported_path
from dataset.run_layout import RUN_FILE
from dataset.services import training
from dataset.services.errors import Conflict, InvalidInput, NotFound
from model.train import BEST_NAME, CHECKPOINT_DIR, KEEP_FILE

CURRENT = "current.json"
ALIASES = ("best", "last")
_RUN_NAME = re.compile(r"(\d+):([^/\\]+)")
_PINNED = re.compile(r"best_step_\d{7,}\.pt")  # freeze's hard link to best.pt
NAME_HINT = "RUN:NAME (a run's best, last or checkpoint file, e.g. 3:best) or imported:NAME"


@dataclass(frozen=True)
class CheckpointFile:
    """One checkpoint of a run: its file name in ``RUN_DIR/checkpoints``, its step, where it is."""

    run: int
    name: str
    step: int | None  # None for best.pt (its step is the run's best_step)
    path: Path
    bytes: int

    @property
    def label(self) -> str:
        """How answers name it: never its server path."""
        return f"run {self.run} · {self.name}"


def run_checkpoints(runs_dir: Path, run_id: int) -> list[CheckpointFile]:
    """The run's checkpoint files (:func:`dataset.services.training.checkpoint_files`' order)."""
    return [CheckpointFile(run_id, f["name"], f["step"], f["path"], f["bytes"])
            for f in training.checkpoint_files(training.run_dir(Path(runs_dir), run_id))]


def run_checkpoint(runs_dir: Path, run_id: int, which: str, *, best_step: int | None) -> CheckpointFile:
    """``which`` = ``best``, ``last`` or a file name of the run's checkpoints; ``best_step`` is the
    run's (what ``best.pt`` holds, as the database last heard). NotFound saying what the run has
    when there is no such file."""
    files = run_checkpoints(runs_dir, run_id)
    if which in ("best", BEST_NAME):
        best = next((f for f in files if f.name == BEST_NAME), None)
        if best is None:
            raise NotFound(f"run {run_id} has no best checkpoint yet: it appears after the first validation")
        return CheckpointFile(run_id, best.name, best_step, best.path, best.bytes)
    if which == "last":
        last = next((f for f in files if f.name.startswith("step_")), None)
        if last is None:
            raise NotFound(f"run {run_id} has no checkpoint yet")
        return last
    found = next((f for f in files if f.name == which), None)
    if found is None:
        names = ", ".join([*ALIASES, *(f.name for f in files)])
        raise NotFound(f"run {run_id} has no checkpoint {which!r}; it has {names}")
    return found


def open_run_checkpoint(runs_dir: Path, run_id: int, which: str, *,
                        best_step: int | None) -> tuple[CheckpointFile, BinaryIO]:
    """:func:`run_checkpoint`, and its file opened to send, walking down from ``runs/`` without
    following links (``dataset.contained.open_contained``): NotFound, as for a missing file, when it
    has been swapped for a link or something not a regular file, or has a (hard) link outside its
    folder."""
    found = run_checkpoint(runs_dir, run_id, which, best_step=best_step)
    file = open_contained(training.run_dir(Path(runs_dir), run_id), f"{CHECKPOINT_DIR}/{found.name}",
                          shared=_pinned_pair)
    if file is None:
        raise NotFound(f"run {run_id} has no checkpoint {found.name!r} to download")
    return found, file


def _pinned_pair(dir_fd: int, name: str, fd: int) -> bool:
    """Whether the file with two links opened as ``name`` (``fd``) is one :func:`freeze` pinned:
    ``best.pt`` and ``best_step_N.pt``, both in this folder. A second link of any other name, or a
    third, may be the name of a file outside the workspace. The count is read again at the end: a
    link made or removed meanwhile changes it or the file's change time, and the file is refused."""
    stat = os.fstat(fd)
    if stat.st_nlink != 2:
        return False
    if name == BEST_NAME:  # open_contained counts an error here as a refusal
        partners = [n for n in os.listdir(dir_fd) if _PINNED.fullmatch(n)]
    elif _PINNED.fullmatch(name):
        partners = [BEST_NAME]
    else:
        return False
    if not _same_file(dir_fd, name, stat) or not any(_same_file(dir_fd, n, stat) for n in partners):
        return False
    again = os.fstat(fd)
    return again.st_nlink == 2 and again.st_ctime_ns == stat.st_ctime_ns


def _same_file(dir_fd: int, name: str, stat: os.stat_result) -> bool:
    """Whether ``name`` in the folder is, without following a link, the file ``stat`` describes."""
    try:
        other = os.stat(name, dir_fd=dir_fd, follow_symlinks=False)
    except OSError:
        return False
    return (other.st_dev, other.st_ino) == (stat.st_dev, stat.st_ino)


@dataclass(frozen=True)
class ResolvedCheckpoint:
    """A named checkpoint's file and how answers name it (``3:best``, ``imported:x``; never a path)."""

    path: Path
    name: str
    run: int | None = None


def checkpoint_name(run: int, file: str) -> str:
    """The name :func:`resolve` takes for a run's checkpoint file (or alias)."""
    return f"{run}:{file}"


def is_name(text: str) -> bool:
    """Whether ``text`` is a checkpoint name (``RUN:NAME`` or ``imported:NAME``) rather than a path."""
    return text.startswith(f"{IMPORTED}:") or _RUN_NAME.fullmatch(text) is not None


def resolve(settings: Any | None, text: str, *, allow_path: bool = False) -> ResolvedCheckpoint:
    """The checkpoint ``text`` names: ``RUN:NAME`` or ``imported:NAME`` in the workspace of
    ``settings`` — or, with ``allow_path`` (the command line's), any other text as a file path, which
    needs no workspace. InvalidInput for what is not a name, NotFound saying what exists for a name
    that names nothing."""
    if not is_name(text):
        if allow_path:
            return ResolvedCheckpoint(Path(text).expanduser(), Path(text).name)
        raise InvalidInput(f"checkpoint {text!r}: expected {NAME_HINT}")
    if settings is None:
        raise InvalidInput(f"checkpoint {text!r} is a name: naming a checkpoint needs a workspace (--data-dir)")
    kind, name = text.split(":", 1)
    if kind == IMPORTED:
        path = imported_path(Path(settings.home), name)
        if (not path.is_file() or path.is_symlink()) and name in imported_names(Path(settings.home), depth_models=True):
            raise InvalidInput(f"{text} is an imported depth model (Depth Anything V2), not a stereo checkpoint: "
                               f"`illusion-studio depth IMAGE --checkpoint {text}` runs it")
        if not path.is_file() or path.is_symlink():
            have = ", ".join(f"{IMPORTED}:{n}" for n in imported_names(Path(settings.home))) or "none"
            raise NotFound(f"no imported checkpoint {name!r} (imported: {have}; "
                           "`illusion-studio checkpoints import --from raft-stereo FILE` adds one)")
        return ResolvedCheckpoint(path, text)
    run, runs_dir = int(kind), Path(settings.runs_dir)
    if not training.run_dir(runs_dir, run).is_dir():
        raise NotFound(f"no run {run} in this workspace")
    return ResolvedCheckpoint(run_checkpoint(runs_dir, run, name, best_step=None).path, text, run)


def resolve_depth_model(settings: Any | None, text: str) -> ResolvedCheckpoint:
    """The depth-model directory ``text`` names: ``imported:NAME`` in the workspace of ``settings``, or
    any other text as a directory's path. InvalidInput for a run's checkpoint name, NotFound saying
    what exists for a name that names nothing."""
    if not text.startswith(f"{IMPORTED}:"):
        if is_name(text):
            raise InvalidInput(f"{text} names a run's checkpoint, not a depth model: give imported:NAME "
                               "or a checkpoint directory")
        return ResolvedCheckpoint(Path(text).expanduser(), Path(text).name)
    if settings is None:
        raise InvalidInput(f"checkpoint {text!r} is a name: naming a checkpoint needs a workspace (--data-dir)")
    path = imported_depth_model(Path(settings.home), text.split(":", 1)[1])
    return ResolvedCheckpoint(path, text)


# Stereo networks whose published files import (`checkpoints import --from SOURCE`): the module
# holding each one's ``convert``, its ``Flags`` and ``FLAGS`` (the Flags fields its files may need).
STEREO_IMPORTERS: dict[str, str] = {"raft-stereo": "model.raft_import", "selective-raft": "model.selective_raft_import",
                                    "selective-igev": "model.selective_igev_import", "mocha-stereo": "model.mocha_import"}
IMPORT_SOURCES = (*STEREO_IMPORTERS, "depth-anything-v2")
# How the CLI spells each architecture flag (the importers' Flags fields).
FLAG_OPTIONS = {"context_norm": "--context-norm", "slow_fast_gru": "--slow-fast", "corr_levels": "--corr-levels",
                "corr_radius": "--corr-radius", "max_disp": "--max-disp", "iterations": "--iters"}


def import_checkpoint(settings: Any, file: Path, *, source: str, name: str | None = None,
                      replace: bool = False, flags: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Convert the published checkpoint ``file`` (``source``: one of IMPORT_SOURCES) and register it
    in the workspace as ``imported:NAME`` (default NAME: the file's stem): a stereo network's file
    (STEREO_IMPORTERS) as ``NAME.pt``, a Depth Anything V2 one as the directory ``NAME/``. Returns
    ``{"checkpoint": the name, "architecture", "keys_loaded", …}``; InvalidInput for a bad name or a
    file that is not such a checkpoint (one line), Conflict when the name is taken and ``replace`` is
    not given. ``flags``: a stereo file's architecture where its tensors do not settle it, by its
    importer's ``Flags`` field (those given; InvalidInput for a flag its network has no use for)."""
    if source not in IMPORT_SOURCES:
        raise InvalidInput(f"unknown checkpoint source {source!r}; choose one of {', '.join(IMPORT_SOURCES)}")
    given = {field: value for field, value in (flags or {}).items() if value is not None}
    if given and source not in STEREO_IMPORTERS:
        raise InvalidInput(f"architecture flags are for stereo networks' files ({', '.join(STEREO_IMPORTERS)}); "
                           f"a {source} file's tensors settle its own")
    importer = importlib.import_module(STEREO_IMPORTERS[source]) if source in STEREO_IMPORTERS else None
    if importer is not None:
        refused = [FLAG_OPTIONS.get(field, field) for field in given if field not in importer.FLAGS]
        if refused:
            raise InvalidInput(f"{', '.join(refused)}: not an option of {source} files (its code fixes it or never reads it)")
    name = name or re.sub(r"[^A-Za-z0-9._-]", "-", Path(file).stem).lstrip("._-")[:64] or source
    stereo, depth = imported_path(Path(settings.home), name), imported_model_dir(Path(settings.home), name)
    # One namespace for both kinds: imported:NAME must name one thing.
    taken = stereo if source == "depth-anything-v2" else depth
    if os.path.lexists(taken):
        raise Conflict(f"{IMPORTED}:{name} is taken by another kind of checkpoint; choose another name")
    destination = depth if source == "depth-anything-v2" else stereo
    if os.path.lexists(destination) and not replace:
        raise Conflict(f"{IMPORTED}:{name} exists; choose another name or replace it")
    if destination.is_symlink():
        raise Conflict(f"{IMPORTED}:{name} is a symbolic link, not the workspace's own checkpoint; remove it first")
    if importer is None:
        from annotation.depth.depth_anything_import import import_file as import_depth
        from model.checkpoint import read_weights_only

        import_file = functools.partial(import_depth, read=read_weights_only)
    else:
        from model.raft_import import import_file as import_stereo

        import_file = functools.partial(import_stereo, flags=importer.Flags(**given), converter=importer.convert,
                                        source=source)
    try:
        result = import_file(Path(file), destination)
    except ValueError as exc:  # not a checkpoint of that source, unreadable, or a pickle naming code
        raise InvalidInput(str(exc).splitlines()[0]) from None
    if source == "depth-anything-v2":  # a monocular model: no stereo preset to fit
        return {"checkpoint": f"{IMPORTED}:{name}", **result}
    from model.runs.start_fit import fitting_presets, write_sidecar

    write_sidecar(destination, result["config"])
    return {"checkpoint": f"{IMPORTED}:{name}", **{k: v for k, v in result.items() if k != "config"},
            "fits": fitting_presets(result["config"].model)}


def imported_fits(home: Path) -> list[dict[str, Any]]:
    """The imported checkpoints a form offers, each with the presets it fits as ``init`` and as
    ``init_stereo`` (None where its config cannot be read here): ``{"name", "init", "init_stereo"}``."""
    from model.runs.start_fit import describe_fits, imported_model

    return [{"name": f"{IMPORTED}:{n}", **describe_fits(imported_model(imported_path(Path(home), n)))}
            for n in imported_names(Path(home))]


def with_checkpoint_names(row: dict[str, Any]) -> dict[str, Any]:
    """A run's JSON (:func:`dataset.services.training.run_json`) with ``checkpoint_name`` and
    ``best_checkpoint_name`` added: its last and best checkpoints as :func:`resolve` takes them."""
    return {**row,
            "checkpoint_name": checkpoint_name(row["run"], row["checkpoint"]) if row.get("checkpoint") else None,
            "best_checkpoint_name": checkpoint_name(row["run"], "best") if row.get("best_checkpoint") else None}


def named_checkpoints(session: Session, runs_dir: Path, limit: int = 50) -> list[dict[str, Any]]:
    """What a form offers to start from or evaluate: each recent run's ``best`` and ``last``, with
    their steps — ``{"run", "checkpoint", "label"}``, newest run first."""
    choices = []
    for run_id, best_step in training.recent_runs(session, limit):
        try:
            files = run_checkpoints(runs_dir, run_id)
        except LinkedFolder:  # a planted link is refused where the run is opened; the forms still list the others
            continue
        if best_step is not None and any(f.name == BEST_NAME for f in files):
            choices.append({"run": run_id, "checkpoint": "best", "label": f"run {run_id} · best (step {best_step})"})
        last = next((f for f in files if f.name.startswith("step_")), None)
        if last is not None:
            choices.append({"run": run_id, "checkpoint": "last", "label": f"run {run_id} · last (step {last.step})"})
    return choices


def freeze(checkpoint: CheckpointFile) -> tuple[CheckpointFile, bool]:
    """The checkpoint under a name validation never replaces: ``best.pt`` becomes a hard link
    ``best_step_N.pt``, N read from the linked file itself (a trainer replacing ``best.pt`` meanwhile
    cannot mislabel it); other files stay as they are. Returns (the file, whether it was created
    now). ValueError when the file is not a checkpoint that loads."""
    if checkpoint.name != BEST_NAME:
        return checkpoint, False
    from model.checkpoint import load_checkpoint

    pending = checkpoint.path.with_name(f".pin-{uuid.uuid4().hex}.pt")
    try:
        try:
            os.link(checkpoint.path, pending)
        except OSError:  # a file system without hard links
            atomic_write_bytes(pending, checkpoint.path.read_bytes())
        step = int(load_checkpoint(pending, label=checkpoint.label)["step"])
        frozen = pending.with_name(f"best_step_{step:07d}.pt")
        if frozen.is_symlink():
            raise ValueError(f"run {checkpoint.run}'s {frozen.name} is a symbolic link, not the run's own file")
        created = not frozen.exists()
        if created:
            os.replace(pending, frozen)
    finally:
        pending.unlink(missing_ok=True)
    return CheckpointFile(checkpoint.run, frozen.name, step, frozen, frozen.stat().st_size), created


def pin(checkpoint: CheckpointFile) -> CheckpointFile:
    """:func:`freeze` the checkpoint and list it in its run's ``keep.json``, so rotation never deletes it."""
    frozen, _ = freeze(checkpoint)
    keep_checkpoint(frozen.path)
    return frozen


def keep_checkpoint(checkpoint: Path) -> None:
    """List ``checkpoint`` in its run directory's ``keep.json`` so the engine never deletes it.

    The run directory is the checkpoint's folder's parent (``RUN_DIR/checkpoints/x.pt``); a
    checkpoint outside a run directory has no rotation to fear and is left alone. Entries are
    relative to the run directory, so a workspace can move. Two pins at once (a promote and an
    evaluation's launch) take turns on a lock, so neither entry is lost.
    """
    checkpoint = Path(checkpoint).resolve()
    run_dir = checkpoint.parent.parent
    if checkpoint.parent.name != CHECKPOINT_DIR or not (run_dir / RUN_FILE).is_file():
        return
    path = run_dir / KEEP_FILE
    with (run_dir / f"{KEEP_FILE}.lock").open("a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        kept: list[str] = []
        if path.is_file():
            try:
                kept = list(json.loads(path.read_text(encoding="utf-8")).get("paths", []))
            except (OSError, ValueError, AttributeError):
                kept = []
        entry = str(checkpoint.relative_to(run_dir))
        if entry not in kept and str(checkpoint) not in kept:
            atomic_write_bytes(path, json.dumps({"paths": [*kept, entry]}, indent=1).encode())


# --- the current model -------------------------------------------------------------------------

def current_model(settings: Any) -> dict[str, Any] | None:
    """What answers say of the current model: ``{"run", "file", "step", "best"}``, or None when none
    has been promoted. Never a path."""
    doc = _current_doc(settings)
    if doc is None:
        return None
    file = doc.get("file") or Path(doc["checkpoint"]).name
    return {"run": doc.get("run"), "file": file, "step": doc.get("step"), "best": file.startswith("best")}


def current_checkpoint(settings: Any) -> Path | None:
    """The current model's checkpoint file, or None when none has been promoted."""
    doc = _current_doc(settings)
    if doc is None:
        return None
    path = Path(doc["checkpoint"])
    return path if path.is_absolute() else Path(settings.home) / path


def current_reference(settings: Any) -> tuple[int, str] | None:
    """The current model as (run, file name), when it is a run's checkpoint."""
    doc = _current_doc(settings)
    if doc is None or doc.get("run") is None:
        return None
    return int(doc["run"]), str(doc.get("file") or Path(doc["checkpoint"]).name)


def _current_doc(settings: Any) -> dict[str, Any] | None:
    path = Path(settings.models_dir) / CURRENT
    if not path.is_file():
        return None
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        raise InvalidInput(f"models/{CURRENT} is not a readable current-model file; promote a checkpoint again") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("checkpoint"), str):
        raise InvalidInput(f"models/{CURRENT} names no checkpoint; promote a checkpoint again")
    return doc


def promote(settings: Any, checkpoint: CheckpointFile | Path, *, run: int | None = None,
            step: int | None = None) -> dict[str, Any]:
    """Make a run's checkpoint (pinned first) — or, from the command line, any checkpoint file —
    the current model; returns what answers say of it (:func:`current_model`)."""
    if isinstance(checkpoint, CheckpointFile):
        checkpoint = pin(checkpoint)
        path, run, step, file = checkpoint.path, checkpoint.run, checkpoint.step, checkpoint.name
    else:
        path, file = Path(checkpoint).resolve(), Path(checkpoint).name
        if run is not None and path.parent != (training.run_dir(Path(settings.runs_dir), run) / CHECKPOINT_DIR).resolve():
            run = None  # a file from elsewhere is no run's checkpoint, whichever run promoted it
        keep_checkpoint(path)
    home = Path(settings.home).resolve()
    stored = str(path.relative_to(home)) if path.is_relative_to(home) else str(path)
    doc = {"checkpoint": stored, "run": run, "file": file, "step": step}
    atomic_write_bytes(Path(settings.models_dir) / CURRENT, json.dumps(doc, indent=1).encode())
    return current_model(settings) or {}
