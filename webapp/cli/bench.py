"""``illusion-studio bench …``: speed benchmarks (fixed seeds, figures for the README)."""

from __future__ import annotations

import json
from pathlib import Path

import click

from dataset.geometry.benchmark import run_geometry_benchmark
from dataset.settings import drop_settings_environment

# The budgets of DESIGN.md for this class of 2-core machine (ms).
_BUDGETS_MS = {"plane_fit_1m_ms": 50, "right_view_1080p_ms": 120, "reproject_1080p_ms": 400}


@click.group("bench")
def bench() -> None:
    """Speed benchmarks, each on scratch workspaces of its own."""
    # A deployment's ILLUSION_STUDIO_* variables outrank the settings a benchmark writes for its
    # scratch workspace and reach the servers and workers it starts: they would point the benchmark
    # at that deployment's database and queue. A benchmark is defined by its options alone.
    dropped = drop_settings_environment()
    if dropped:
        click.echo(f"bench: ignoring {', '.join(dropped)} (benchmarks use scratch workspaces)", err=True)


@bench.command("geometry")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
@click.option("--repeats", type=click.IntRange(min=1), default=5, show_default=True, help="Timed runs per figure.")
def geometry_benchmark(as_json: bool, repeats: int) -> None:
    """Time plane fitting, right-view synthesis, inpainting and reprojection against references."""
    _report(run_geometry_benchmark(repeats=repeats), as_json)


@bench.command("prefilter")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
@click.option("--frames", type=click.IntRange(min=10), default=400, show_default=True)
@click.option("--concurrency", type=click.IntRange(min=1, max=256), default=16, show_default=True)
def prefilter_benchmark(as_json: bool, frames: int, concurrency: int) -> None:
    """Frames per second the openai backend's client sustains against an instant local server."""
    from webapp.benchmarks.prefilter import run_prefilter_bench

    _report(run_prefilter_bench(frames=frames, concurrency=concurrency), as_json)


@bench.command("click")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
@click.option("--clicks", type=click.IntRange(min=5), default=30, show_default=True)
@click.option("--no-sam2", is_flag=True, help="Only the classical backend.")
def click_benchmark(as_json: bool, clicks: int, no_sam2: bool) -> None:
    """Click → mask over HTTP at 1080p (p50/p95), classical and SAM2, beside in-process predict times."""
    from webapp.benchmarks.click import run_click_bench

    _report(run_click_bench(clicks=clicks, sam2=not no_sam2), as_json)


@bench.command("proposals")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
def proposals_benchmark(as_json: bool) -> None:
    """Illusion proposers on held-out synthetic videos: recall, precision, IoU, ms, and clicks saved."""
    from webapp.benchmarks.proposals import run_proposals_bench

    _report(run_proposals_bench(), as_json)


@bench.command("generate")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
@click.option("--repeats", type=click.IntRange(min=1), default=3, show_default=True)
def generate_benchmark(as_json: bool, repeats: int) -> None:
    """One 1080p sample end to end through the generation job (CPU seconds), beside the authors' steps."""
    from webapp.benchmarks.generate import run_generate_bench

    _report(run_generate_bench(repeats=repeats), as_json)


@bench.command("scale")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
@click.option("--frames", type=click.IntRange(min=1000), default=1_400_000, show_default=True,
              help="Frames to seed (the paper curated 1.4M); the routes are also timed at a tenth of it.")
@click.option("--database-url", default=None,
              help="A PostgreSQL server, e.g. postgresql://postgres@127.0.0.1:5432/postgres (its database only serves "
                   "to connect): the bench creates, uses and drops its own database bench_scale. SQLite is always measured.")
@click.option("--repeats", type=click.IntRange(min=2), default=20, show_default=True, help="Timed calls per route.")
def scale_benchmark(as_json: bool, frames: int, database_url: str | None, repeats: int) -> None:
    """p50/p95 of every list and queue route with N frames seeded, beside the same at N/10."""
    from webapp.benchmarks.scale import run_scale_bench

    results = run_scale_bench(frames=frames, database_url=database_url, repeats=repeats)
    if as_json:
        click.echo(json.dumps(results))
        return
    for backend, figures in results["backends"].items():
        click.echo(f"{backend}: {results['frames']} frames (seed {figures['seed_s']} s, upgrade {figures['upgrade_s']} s)")
        tenth = figures["tenth"]["routes"]
        for route, times in figures["routes"].items():
            small = tenth[route]
            click.echo(f"  {route:56} p50 {times['p50_ms']:>8} ms  p95 {times['p95_ms']:>8} ms"
                       f"   (at {figures['tenth']['frames']}: p50 {small['p50_ms']} ms, p95 {small['p95_ms']} ms)")


@bench.command("load")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
@click.option("--annotators", type=click.IntRange(min=0, max=64), default=4, show_default=True)
@click.option("--curators", type=click.IntRange(min=0, max=64), default=2, show_default=True)
@click.option("--seconds", type=click.FloatRange(min=1, max=3600), default=30, show_default=True,
              help="How long the clients work.")
@click.option("--frames", type=click.IntRange(min=2, max=2000), default=40, show_default=True,
              help="Frames of the synthetic video (half approved, half awaiting review).")
@click.option("--database-url", default=None,
              help="A PostgreSQL server (its database only serves to connect): the bench creates, uses and drops its "
                   "own database bench_load. Default: SQLite in a scratch workspace.")
@click.option("--queue-url", default=None, help="A Redis server for the job queue (redis://…). Default: the SQLite queue.")
def load_benchmark(as_json: bool, annotators: int, curators: int, seconds: float, frames: int,
                   database_url: str | None, queue_url: str | None) -> None:
    """Annotators and curators at once against a served app with a worker: requests, 5xx, 409s,
    lost writes (checked in the database afterwards) and p50/p95 per route."""
    from webapp.benchmarks.load import run_load_bench

    if annotators + curators == 0:
        raise click.BadParameter("needs at least one annotator or curator", param_hint="--annotators/--curators")
    results = run_load_bench(annotators=annotators, curators=curators, seconds=seconds, frames=frames,
                             database_url=database_url, queue_url=queue_url)
    if as_json:
        click.echo(json.dumps(results))
        return
    click.echo(f"{results['database']} + {results['queue']} queue: {annotators} annotators, {curators} curators, "
               f"{seconds:g} s: {results['requests']} requests, 5xx {results['5xx']}, lost writes "
               f"{results['lost_writes']}, 409 {results['conflicts']}")
    for route, times in results["routes"].items():
        click.echo(f"  {route:44} {times['count']:>6}  p50 {times['p50_ms']:>7} ms  p95 {times['p95_ms']:>7} ms")


@bench.command("train")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
@click.option("--steps", type=click.IntRange(min=2), default=8, show_default=True, help="Timed steps per process count.")
def train_benchmark(as_json: bool, steps: int) -> None:
    """Training samples/s of the lite preset at its crop with 1 and 2 processes (gloo DDP on CPU)."""
    from webapp.benchmarks.train import run_train_bench

    _report(run_train_bench(steps=steps), as_json)


@bench.command("memory")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
def memory_benchmark(as_json: bool) -> None:
    """The lite trainer's peak memory at several crops and iterations, the memory model's fit to them,
    and the estimate launches are checked with (model/fit.py's MEMORY_MB)."""
    from webapp.benchmarks.memory import run_memory_bench

    _report(run_memory_bench(), as_json)


@bench.command("model")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
@click.option("--repeats", type=click.IntRange(min=1), default=2, show_default=True)
@click.option("--train-steps", type=click.IntRange(min=1), default=3, show_default=True)
def model_benchmark(as_json: bool, repeats: int, train_steps: int) -> None:
    """The lite fusion model on a 1080p pair (own process: seconds, peak MB) beside OpenCV SGBM; parameters; train steps/s."""
    from webapp.benchmarks.model import run_model_bench

    _report(run_model_bench(repeats=repeats, train_steps=train_steps), as_json)


@bench.command("fusion")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
@click.option("--seeds", type=click.IntRange(min=1), default=1, show_default=True,
              help="Training runs with seeds 0..N-1; figures are their mean and spread.")
@click.option("--steps", type=click.IntRange(min=1), default=None, help="Training steps per run (default: the benchmark's).")
@click.option("--work-dir", type=click.Path(file_okay=False, path_type=Path), default=Path("var/bench-fusion"),
              show_default=True, help="Where the prepared data is cached between runs.")
@click.option("--mono-only", is_flag=True,
              help="No training: score mono-gt-align alone on the held-out pairs (the monocular input's calibration).")
@click.option("--ablations", is_flag=True,
              help="Per seed, also train the no-VLM network (use_vlm = false) and the stereo-only one (use_mono = false).")
@click.option("--split", type=click.Choice(["test", "val"]), default="test", show_default=True,
              help="The held-out pairs scored: val (seeds of its own) to decide on, test once, at the end.")
@click.option("--workers", type=click.IntRange(1, 64), default=1, show_default=True,
              help="Trainings run side by side (each one process; give each a core: OMP_NUM_THREADS=1 on 2 cores).")
def fusion_benchmark(as_json: bool, seeds: int, steps: int | None, work_dir: Path, mono_only: bool,
                     ablations: bool, split: str, workers: int) -> None:
    """The synthetic illusion benchmark: train lite on the product's own samples and rendered captures,
    score fusion, stereo, mono-gt-align and sgbm (with --ablations also fusion_no_vlm and stereo_only)
    on held-out rendered pairs (all, picture, mirror, non-illusion)."""
    from webapp.benchmarks.fusion import DEFAULT_STEPS, run_fusion_bench, run_mono_bench

    if mono_only:
        if ablations or workers > 1:
            raise click.UsageError("--ablations and --workers are about training, and --mono-only trains nothing: "
                                   "pass one or the other")
        _report(run_mono_bench(work_dir.absolute(), split=split), as_json)
        return
    _report(run_fusion_bench(work_dir.absolute(), seeds=seeds, steps=steps or DEFAULT_STEPS, ablations=ablations,
                             split=split, workers=workers), as_json)


def _report(results: dict[str, object], as_json: bool) -> None:
    if as_json:
        click.echo(json.dumps(results))
        return
    for key, value in results.items():
        budget = _BUDGETS_MS.get(key)
        verdict = "" if budget is None else f"  (budget {budget} ms: {'ok' if value <= budget else 'OVER'})"
        click.echo(f"{key:32} {value}{verdict}")
