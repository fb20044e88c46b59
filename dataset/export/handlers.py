"""The ``export`` and ``import`` jobs: parameters, progress, and the handlers the queue runs."""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from core.wording import plural
from dataset.db import transaction
from dataset.export.authors_export import export_authors
from dataset.export.authors_import import read_authors
from dataset.export.authors_layout import MASK_FORMATS
from dataset.export.errors import LayoutError
from dataset.export.importer import add_sample
from dataset.export.native import export_native, read_native
from dataset.export.records import Progress
from dataset.export.selection import DEFAULT_STATES, parse_states, select_samples
from dataset.export.splits import DEFAULT_SPLIT, format_split_spec, parse_split_spec
from dataset.export.staging import check_target, staged_dir
from dataset.services.jobs import Handler, JobContext

FORMATS = ("native", "authors")


def export_params(out: str | Path, *, format: str, split: str = DEFAULT_SPLIT, seed: int = 0,
                  states: Sequence[str] = DEFAULT_STATES, video_ids: Sequence[int] = (), overwrite: bool = False,
                  mask_format: str = "png") -> dict[str, Any]:
    """Validated parameters of an ``export`` job (raises :class:`LayoutError` with a one-line reason).

    ``split`` like ``train=0.8,test=0.2`` (native only: the authors' layout has its own training/test
    parts); ``mask_format`` (authors only) ``png`` or ``jpg``.
    """
    _check_format(format)
    spec = parse_split_spec(split)
    if format == "authors" and spec != parse_split_spec(DEFAULT_SPLIT):
        raise LayoutError("the authors' layout has no splits (captures go to testing/, the rest to training); "
                          "use --format native for --split")
    if mask_format not in MASK_FORMATS:
        raise LayoutError(f"mask format must be one of {', '.join(MASK_FORMATS)}")
    check_target(Path(out).absolute(), overwrite=overwrite)  # early; the job checks again when it starts
    return {"out": str(Path(out).absolute()), "format": format, "split": format_split_spec(spec), "seed": int(seed),
            "states": parse_states(states), "video_ids": sorted(set(video_ids)), "overwrite": overwrite,
            "mask_format": mask_format}


def import_params(path: str | Path, *, format: str) -> dict[str, Any]:
    """Validated parameters of an ``import`` job."""
    _check_format(format)
    return {"path": str(Path(path).absolute()), "format": format}


def _check_format(format: str) -> None:
    if format not in FORMATS:
        raise LayoutError(f"unknown format {format!r}; choose {' or '.join(FORMATS)}")


def export_job(ctx: JobContext) -> dict[str, Any]:
    """Job ``export`` (params from :func:`export_params`): the selected samples into a new folder."""
    p = ctx.params
    with ctx.sessions() as s:
        records = select_samples(s, p["states"], p["video_ids"])
    if not records:
        raise LayoutError(f"no samples to export: none is {' or '.join(p['states'])}"
                          + (f" in videos {p['video_ids']}" if p["video_ids"] else ""))
    ctx.log(f"exporting {plural(len(records), 'sample')} as {p['format']} to {p['out']}")
    progress = _progress(ctx, 0.0, 0.95, "exported")
    with staged_dir(Path(p["out"]), tag=f"job{ctx.job_id}", overwrite=p["overwrite"]) as root:
        if p["format"] == "native":
            summary = export_native(records, ctx.media, root, spec=parse_split_spec(p["split"]), seed=p["seed"],
                                    progress=progress)
        else:
            summary = export_authors(records, ctx.media, root, mask_format=p["mask_format"], progress=progress)
    ctx.log(f"wrote {p['out']}")
    return {"out": p["out"], "format": p["format"], **summary}


def import_job(ctx: JobContext) -> dict[str, Any]:
    """Job ``import`` (params from :func:`import_params`): validate the whole folder, then add what is missing."""
    p = ctx.params
    read = read_native if p["format"] == "native" else read_authors
    pending = read(Path(p["path"]), _progress(ctx, 0.0, 0.3, "checked"))
    ctx.log(f"{p['path']}: {plural(len(pending), 'sample')}, layout valid")
    outcomes: Counter[str] = Counter()
    progress = _progress(ctx, 0.3, 1.0, "imported")
    for done, item in enumerate(pending, start=1):
        record = item.store(ctx.media)  # media first, rows last: a crash leaves files, never rows without them
        with transaction(ctx.sessions) as s:
            outcome = add_sample(s, ctx.media, record)
        outcomes[outcome] += 1
        if outcome == "conflict":
            ctx.log(f"{item.name}: its frame already has another sample for annotation version "
                    f"{record.annotation_version}; kept that one")
        progress(done, len(pending), item.name)
    return {"path": p["path"], "format": p["format"], "samples": len(pending), "added": outcomes["added"],
            "present": outcomes["present"], "conflicts": outcomes["conflict"]}


def _progress(ctx: JobContext, start: float, end: float, verb: str) -> Progress:
    """Progress in [start, end] of the job; a log line about every tenth of the way."""
    def report(done: int, total: int, what: str) -> None:
        milestone = done == total or done % max(1, total // 10) == 0
        ctx.progress(start + (end - start) * done / max(total, 1), f"{verb} {done}/{total}: {what}" if milestone else None)
    return report


HANDLERS: dict[str, Handler] = {"export": export_job, "import": import_job}
