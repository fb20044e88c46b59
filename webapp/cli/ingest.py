"""`illusion-studio ingest …` and `illusion-studio frames list`."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Any

import click

from core.wording import plural
from dataset.db import transaction
from dataset.ingest import IngestError, find_sources
from dataset.ingest.sources import SCENE_FILE
from dataset.services.frames import list_frames
from dataset.services.ingest import DEFAULT_DEDUP_HAMMING, DEFAULT_FPS, ingest_params
from dataset.services.sample_blockers import sample_blocker
from dataset.tables import FrameState, IllusionType, Job, SourceKind, Video
from webapp.cli.errors import service_errors
from webapp.cli.state import CliState, pass_state

NO_WORKER_HINT_S = 10.0


@click.command()
@click.argument("paths", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--fps", default=DEFAULT_FPS, show_default=True, type=float, help="Frames per second to keep (0: all).")
@click.option("--source", type=click.Choice([k.value for k in SourceKind]), default=None,
              help="Where the videos come from (default: web; generated for synthetic scenes).")
@click.option("--illusion-type", "illusion_types", multiple=True, type=click.Choice([t.value for t in IllusionType]),
              help="Illusion types shown (repeatable).")
@click.option("--dedup", default=DEFAULT_DEDUP_HAMMING, show_default=True, type=click.IntRange(-1, 64),
              help="Drop a frame within this many dHash bits of the last kept one (-1: keep all).")
@click.option("--prefilter/--no-prefilter", default=False, show_default=True,
              help="Queue the VLM prefilter for the new frames once a video is ingested.")
@click.option("--mono", "mono_dir", type=click.Path(path_type=Path, file_okay=False), default=None,
              help="A folder of the video's per-frame monocular disparities (.pfm/.npy, float HxW, larger = "
                   "nearer; each name ends with its frame's index, e.g. frame_000012.npy): its frames can then "
                   "become samples without a depth model (the precomputed backend). One video only.")
@click.option("--wait", is_flag=True, help="Wait for the jobs, show progress, exit non-zero if one fails.")
@pass_state
def ingest(state: CliState, paths: tuple[Path, ...], fps: float, source: str | None,
           illusion_types: tuple[str, ...], dedup: int, prefilter: bool, mono_dir: Path | None, wait: bool) -> None:
    """Queue video files, folders of videos, or synthetic scenes for ingest (a worker decodes them)."""
    try:
        sources = find_sources(list(paths))
    except IngestError as exc:
        raise click.ClickException(str(exc)) from None
    if not sources:
        raise click.ClickException("no video files or synthetic scenes found under the given paths")
    if mono_dir is not None and len(sources) != 1:
        raise click.ClickException(f"--mono is one video's disparities, but {len(sources)} videos were given")
    rt = state.runtime
    with service_errors(), transaction(rt.sessions) as s:
        job_ids = [rt.queue.submit(s, "ingest", ingest_params(
            str(p), fps=fps or None, source=source, illusion_types=list(illusion_types),
            dedup_hamming=None if dedup < 0 else dedup, prefilter=prefilter,
            mono_dir=str(mono_dir.resolve()) if mono_dir else None), None).id for p in sources]
    for path, job_id in zip(sources, job_ids, strict=True):
        click.echo(f"job {job_id}: ingest {path}")
    # Said now, not when the generate job fails after the annotators' work.
    blocker = sample_blocker(state.settings, None if mono_dir is None else Video(meta={"mono": "precomputed"}))
    if blocker and not any(is_scene(p) for p in sources):
        click.echo(f"note: {blocker}", err=True)
    if wait:
        wait_for_jobs(state, job_ids)


def is_scene(path: Path) -> bool:
    """Whether ``path`` is a synthetic scene (it brings its own depth)."""
    return (path / SCENE_FILE).is_file()


def brief_result(result: dict[str, Any]) -> str:
    """A job's result in one short line: its plain figures (the whole result is in `jobs show`)."""
    return json.dumps({k: v for k, v in result.items() if isinstance(v, int | float | str | bool | None)})


def wait_for_jobs(state: CliState, job_ids: list[int], *, quiet: bool = False) -> None:
    """Show one progress bar over ``job_ids`` until all finish; a failure is reported and exits 1.
    ``quiet`` writes the closing lines to stderr, keeping stdout for a command's ``--json``."""
    started = time.monotonic()
    hinted = False
    with click.progressbar(length=1000, label="working", file=sys.stderr, show_eta=False) as bar:
        while True:
            with state.runtime.sessions() as s:
                jobs = [s.get(Job, j) for j in job_ids]
            done = sum(j.progress if not j.state.finished else 1.0 for j in jobs) / len(jobs)
            bar.update(int(done * 1000) - bar.pos)
            if all(j.state.finished for j in jobs):
                break
            if not hinted and time.monotonic() - started > NO_WORKER_HINT_S and all(j.state.value == "queued" for j in jobs):
                click.echo(f"\nstill queued after {NO_WORKER_HINT_S:.0f} s: is a worker running? "
                           f"(`illusion-studio --data-dir {state.settings.home} worker`)", err=True)
                hinted = True
            time.sleep(0.25)
    failed = [j for j in jobs if j.state.value != "succeeded"]
    for job in jobs:
        click.echo(f"job {job.id}: {job.state.value} {brief_result(job.result) if job.result else job.error or ''}",
                   err=quiet)
        if job.result and (copy := job.result.get("copy_of")):
            click.echo(f"  looks like a copy of video {copy['video_id']} ({copy['video_name']}); kept in the same "
                       "scene group", err=quiet)
    if failed:
        raise click.ClickException(f"{len(failed)} of {plural(len(jobs), 'job')} did not succeed: "
                                   + "; ".join(f"job {j.id}: {j.error}" for j in failed))


@click.group()
def frames() -> None:
    """Query frames."""


@frames.command("list")
@click.option("--video", "video_id", type=int, default=None, help="Only this video's frames.")
@click.option("--state", "frame_state", type=click.Choice([s.value for s in FrameState]), default=None)
@click.option("--limit", default=10_000, show_default=True, type=click.IntRange(1, 10_000))
@click.option("--offset", default=0, type=click.IntRange(0))
@click.option("--json", "as_json", is_flag=True, help="Print a JSON array.")
@pass_state
def list_frames_cmd(state: CliState, video_id: int | None, frame_state: str | None, limit: int, offset: int,
                    as_json: bool) -> None:
    with state.runtime.sessions() as s:
        items, total = list_frames(s, video_id=video_id, state=FrameState(frame_state) if frame_state else None,
                                   limit=limit, offset=offset)
    if as_json:
        click.echo(json.dumps(items))
        return
    for f in items:
        keep = {True: "keep", False: "drop", None: "-"}[f["prefilter_keep"]]
        click.echo(f"{f['id']:>7} video {f['video_id']:<5} {f['time_s']:8.2f} s  {f['width']}x{f['height']}  "
                   f"{f['state']:<12} {keep}")
    click.echo(f"{len(items)} of {plural(total, 'frame')}", err=True)


@click.command()
@click.option("--video", "video_id", type=int, default=None, help="Only this video (default: every ingested frame).")
@click.option("--backend", type=click.Choice(["heuristic", "openai", "transformers"]), default=None,
              help="VLM backend (default from settings: vlm_backend).")
@click.option("--base-url", default=None, help="openai backend: the server's /v1 URL (default: vlm_base_url).")
@click.option("--model", default=None, help="openai backend: model name (default: vlm_model).")
@click.option("--sparse", is_flag=True, help="The authors' sparse mode: ask about every step-th frame of a video.")
@click.option("--chunk", default=32, show_default=True, type=click.IntRange(1, 1000), help="Frames per job.")
@click.option("--wait", is_flag=True, help="Wait for the jobs, show progress, exit non-zero if one fails.")
@pass_state
def prefilter(state: CliState, video_id: int | None, backend: str | None, base_url: str | None, model: str | None,
              sparse: bool, chunk: int, wait: bool) -> None:
    """Ask the VLM the paper's 12 questions about every ingested frame; survivors go to curators."""
    from dataset.services.prefilter import launch_prefilter

    rt = state.runtime
    with service_errors(), transaction(rt.sessions) as s:
        job_ids = [j.id for j in launch_prefilter(s, rt.submit, None, video_id=video_id, backend=backend,
                                                   base_url=base_url, model=model, sparse=sparse, chunk=chunk)]
    if not job_ids:
        click.echo("no ingested frames waiting for the prefilter")
        return
    click.echo(f"queued {len(job_ids)} prefilter jobs: {', '.join(map(str, job_ids))}")
    if wait:
        wait_for_jobs(state, job_ids)
