"""Provenance of a benchmark record: what it takes to rebuild the networks a JSON reports.

Three things pin a trained network besides its seed and starting weights: the code that shapes
what training sees and does (:data:`TRAINING_SOURCES`, hashed by
:func:`training_sources_fingerprint`), the resolved config (:func:`resolved_config`: every field,
so that a preset's later edit cannot change what a recorded command meant) and the data
(:func:`pretrain_data_digest` for the pre-training captures). :func:`source_commit` names the git
commit the code was at. None of these functions trains or writes anything.
"""

from __future__ import annotations

import hashlib
import subprocess
import tomllib
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from model.presets import Config, _locate, load_preset

ROOT = Path(__file__).resolve().parent.parent  # the repository root

# Every source that shapes what a training run sees or does, relative to ROOT: a folder stands for
# every ``.py`` under it. Kept explicit so that a new module that matters is added on purpose.
TRAINING_SOURCES: tuple[str, ...] = (
    "model",  # the network, losses, training engine, config loader, and the training job (model/runs/handlers.py)
    "dataset/readers",  # how a pinned dataset version's samples are read (VersionReader) and cropped into regions
    "dataset/samples.py",  # how a sample's stored outputs (images, disparity, mono, masks) are encoded and decoded
    "dataset/media.py",  # the media store the readers load those outputs from
    "core/formats",  # the PFM / image / mask codecs the stored outputs go through
    "dataset/services/training.py",  # the selection pinned, the split (parse_split, split_version) and the launch
    "dataset/export/splits.py",  # the split's arithmetic: which video lands in train or val for a seed
    "webapp/jobs/handlers.py",  # which function runs a queued "train" job
    "webapp/jobs/runs.py",  # the launch: config resolution, init checkpoint, the seed given to split and training
    "dataset/synthetic",  # the renderer of the benchmark's scenes, pairs and mono input
    "dataset/capture/synthetic.py",  # how rendered videos are imported as capture samples
    "benchmarks/fusion.py",  # the benchmark's data, seeds, overrides and networks
    "benchmarks/pretrain.py",  # the pre-training recipe
    "benchmarks/trunk.py",  # how the trunk is kept and composed into each network's starting weights
)


def source_commit(root: Path | None = None) -> dict[str, Any]:
    """The git commit of ``root`` (default: the repository root) as ``{"commit": 40 hex digits,
    "dirty": whether tracked or untracked files differ from it}``; both None when ``root`` is not a
    git checkout or git cannot be run. Never raises."""
    where = Path(root) if root is not None else ROOT
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=where, capture_output=True, text=True, timeout=30)
        if head.returncode != 0:
            return {"commit": None, "dirty": None}
        status = subprocess.run(["git", "status", "--porcelain"], cwd=where, capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.SubprocessError):
        return {"commit": None, "dirty": None}
    commit = head.stdout.strip()
    if len(commit) != 40:
        return {"commit": None, "dirty": None}
    return {"commit": commit, "dirty": None if status.returncode != 0 else bool(status.stdout.strip())}


def source_files(root: Path | None = None, covers: Iterable[str] = TRAINING_SOURCES) -> list[Path]:
    """The ``.py`` files that ``covers`` names under ``root`` (default: the repository root), sorted by
    their path relative to it; FileNotFoundError for an entry that does not exist."""
    base = Path(root) if root is not None else ROOT
    files: set[Path] = set()
    for entry in covers:
        path = base / entry
        if path.is_dir():
            files.update(p for p in path.rglob("*.py") if "__pycache__" not in p.parts)
        elif path.is_file():
            files.add(path)
        else:
            raise FileNotFoundError(f"training source {entry} is not in {base}")
    return sorted(files, key=lambda p: p.relative_to(base).as_posix())


def training_sources_fingerprint(root: Path | None = None,
                                 covers: Iterable[str] = TRAINING_SOURCES) -> dict[str, Any]:
    """sha256 over every file of :func:`source_files` — its path relative to ``root`` (POSIX), a NUL,
    its bytes, a NUL — in path order; with the file count and the ``covers`` entries hashed."""
    base = Path(root) if root is not None else ROOT
    covers = tuple(covers)
    digest = hashlib.sha256()
    files = source_files(base, covers)
    for path in files:
        digest.update(path.relative_to(base).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return {"sha256": digest.hexdigest(), "files": len(files), "covers": list(covers)}


def resolved_config(preset: str, overrides: Mapping[str, Any]) -> dict[str, Any]:
    """Every field of preset ``preset`` with ``overrides`` applied, as today's preset file and
    loader resolve them (``Config.to_dict``: JSON-able, tuples as lists)."""
    return load_preset(preset, overrides).to_dict()


def resolved_config_from_text(preset: str, toml_text: str, overrides: Mapping[str, Any]) -> dict[str, Any]:
    """Like :func:`resolved_config` for a preset file's text ``toml_text`` (e.g. the preset as an old
    commit had it): fields the text does not set take today's defaults, which keep the old behaviour."""
    data = tomllib.loads(toml_text)
    for key, value in overrides.items():
        section, field = _locate(key)
        data.setdefault(section, {})[field] = value
    return Config.from_dict({"preset": preset, **data}).to_dict()


def config_differences(a: Mapping[str, Any], b: Mapping[str, Any]) -> dict[str, tuple[Any, Any]]:
    """The fields ("section.field") where two resolved configs differ, with both values."""
    return {f"{section}.{field}": (a[section].get(field), b[section].get(field))
            for section in ("model", "train")
            for field in sorted(set(a[section]) | set(b[section]))
            if a[section].get(field) != b[section].get(field)}


def pretrain_data_digest(seeds: Iterable[int], frames: int, families: bool | None = None,
                         truth: str = "surface") -> str:
    """sha256 of the pre-training captures as ``bench pretrain`` imports them (``fusion.capture_video``,
    of the scene ``families`` or not, default the benchmark's SCENE_FAMILIES; with ``truth``): each seed's ``frames``
    frames rendered at the benchmark's SIZE and that seed's capture baseline, hashed as
    ``fusion.pairs_digest`` hashes pairs (per frame, in seed then frame order: its name, left and right
    images, disparity and the realistic mono disparity the capture stores)."""
    from benchmarks import fusion  # imported here: the renderer and the benchmark are heavy to load

    def samples() -> Iterable[Any]:
        for seed in seeds:
            video = fusion.capture_video(seed, frames, fusion.SCENE_FAMILIES if families is None else families,
                                         truth)  # type: ignore[arg-type]
            yield from fusion.video_samples(video)

    return fusion.pairs_digest(samples())


def provenance_block(preset: str, overrides_by_network: Mapping[str, Mapping[str, Any]],
                     root: Path | None = None) -> dict[str, Any]:
    """A benchmark JSON's ``provenance``: the :func:`source_commit`, the
    :func:`training_sources_fingerprint` and, per network name, the :func:`resolved_config` of
    ``preset`` under that network's overrides."""
    return {"commit": source_commit(root), "sources": training_sources_fingerprint(root),
            "resolved_configs": {name: resolved_config(preset, overrides)
                                 for name, overrides in overrides_by_network.items()}}
