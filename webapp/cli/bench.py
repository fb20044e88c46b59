"""``illusion-studio bench …``: speed benchmarks (fixed seeds, figures for docs/benchmarks.md)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click

from core.geometry.benchmark import run_geometry_benchmark
from dataset.readers import READER_FORMATS, LayoutError
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
    from benchmarks.prefilter import run_prefilter_bench

    _report(run_prefilter_bench(frames=frames, concurrency=concurrency), as_json)


@bench.command("click")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
@click.option("--clicks", type=click.IntRange(min=5), default=30, show_default=True)
@click.option("--no-sam2", is_flag=True, help="Only the classical backend.")
def click_benchmark(as_json: bool, clicks: int, no_sam2: bool) -> None:
    """Click → mask over HTTP at 1080p (p50/p95), classical and SAM2, beside in-process predict times."""
    from benchmarks.click import run_click_bench

    _report(run_click_bench(clicks=clicks, sam2=not no_sam2), as_json)


@bench.command("proposals")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
@click.option("--real", type=click.Path(exists=True, file_okay=False, path_type=Path),
              help="A folder of real pairs with ground truth: pictures are composited into each, beside the Motorcycle's.")
@click.option("--format", "fmt", type=click.Choice(READER_FORMATS), help="The layout of --real.")
@click.option("--threshold", type=click.FloatRange(0, 1), default=None,
              help="Score below which a proposal does not count (default: plane-break's DEFAULT_THRESHOLD).")
def proposals_benchmark(as_json: bool, real: Path | None, fmt: str | None, threshold: float | None) -> None:
    """Illusion proposers on held-out synthetic videos and on real scenes with composited pictures: recall,
    precision, false proposals on untouched frames, a threshold sweep, IoU, ms, and clicks saved."""
    from benchmarks.proposals import report_lines, run_proposals_bench

    if real is not None and fmt is None:
        raise click.UsageError("--real needs --format (the layout of its pairs)")
    try:
        results = run_proposals_bench(real=real, real_format=fmt, **({} if threshold is None else {"threshold": threshold}))
    except LayoutError as exc:
        raise click.BadParameter(str(exc), param_hint="--real") from None
    click.echo(json.dumps(results) if as_json else "\n".join(report_lines(results)))


@bench.command("generate")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
@click.option("--repeats", type=click.IntRange(min=1), default=3, show_default=True)
def generate_benchmark(as_json: bool, repeats: int) -> None:
    """One 1080p sample end to end through the generation job (CPU seconds), beside the authors' steps."""
    from benchmarks.generate import run_generate_bench

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
    from benchmarks.scale import run_scale_bench

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
    from benchmarks.load import run_load_bench

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
    from benchmarks.train import run_train_bench

    _report(run_train_bench(steps=steps), as_json)


@bench.command("memory")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
def memory_benchmark(as_json: bool) -> None:
    """The lite trainer's peak memory at several crops and iterations, the memory model's fit to them,
    and the estimate launches are checked with (model/runs/capacity.py's MEMORY_MB)."""
    from benchmarks.memory import run_memory_bench

    _report(run_memory_bench(), as_json)


@bench.command("model")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
@click.option("--repeats", type=click.IntRange(min=1), default=2, show_default=True)
@click.option("--train-steps", type=click.IntRange(min=1), default=3, show_default=True)
@click.option("--no-raft-stereo", "no_raft_stereo", is_flag=True,
              help="Skip RAFT-Stereo's network (32 iterations at 1080p: minutes on a CPU).")
@click.option("--no-selective-raft", "no_selective_raft", is_flag=True,
              help="Skip Selective-RAFT's network (32 iterations at 1080p: minutes on a CPU).")
@click.option("--no-selective-igev", "no_selective_igev", is_flag=True,
              help="Skip Selective-IGEV's network (32 iterations at 1080p, max_disp 192: minutes on a CPU).")
@click.option("--no-mocha-stereo", "no_mocha_stereo", is_flag=True,
              help="Skip MoCha-Stereo's network (32 iterations at 1080p, max_disp 192: minutes on a CPU).")
def model_benchmark(as_json: bool, repeats: int, train_steps: int, no_raft_stereo: bool,
                    no_selective_raft: bool, no_selective_igev: bool, no_mocha_stereo: bool) -> None:
    """The lite fusion model on a 1080p pair (own process: seconds, peak MB) beside OpenCV SGBM, RAFT-Stereo's,
    Selective-RAFT's, Selective-IGEV's and MoCha-Stereo's networks; parameters; train steps/s."""
    from benchmarks.model import run_model_bench

    skipped = {"raft_stereo": no_raft_stereo, "selective_raft": no_selective_raft, "selective_igev": no_selective_igev,
               "mocha_stereo": no_mocha_stereo}
    _report(run_model_bench(repeats=repeats, train_steps=train_steps,
                            skip=[key for key, skip in skipped.items() if skip]), as_json)


def _lite_overrides(ctx: click.Context, param: click.Parameter, values: tuple[str, ...]) -> dict[str, str]:
    """``KEY=VALUE`` options as overrides of ``lite``, checked against its config as each network trains
    it (BadParameter naming the first that does not fit, or that the benchmark sets itself)."""
    from benchmarks import fusion

    overrides: dict[str, str] = {}
    for value in values:
        key, sep, text = value.partition("=")
        if not sep or not key.strip():
            raise click.BadParameter(f"{value!r} is not KEY=VALUE", param=param)
        overrides[key.strip()] = text.strip()
    networks = (fusion.FUSION, *fusion.ABLATIONS) if ctx.params.get("ablations") else (fusion.FUSION,)
    try:
        fusion.check_overrides(overrides, networks)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param=param) from None
    return overrides


@bench.command("fusion")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
@click.option("--seeds", type=click.IntRange(min=1), default=1, show_default=True,
              help="Training runs per network, all on the same train/val split; figures are their mean and spread, "
                   "and fusion's differences paired by seed.")
@click.option("--steps", type=click.IntRange(min=1), default=None,
              help="Training steps per run (default: 1500 from scratch, 500 fine-tuning from the trunk).")
@click.option("--work-dir", type=click.Path(file_okay=False, path_type=Path), default=Path("var/bench-fusion"),
              show_default=True, help="Where the prepared data (and the pre-trained trunk) is cached between runs.")
@click.option("--mono-only", is_flag=True,
              help="No training: score mono-gt-align on the held-out pairs (the monocular input's calibration) and "
                   "the oracle gate's headroom per region over SGBM and the trunk's stereo branch at 0 steps.")
@click.option("--ablations", is_flag=True, is_eager=True,
              help="Per seed, also train the no-VLM network (use_vlm = false) and the stereo-only one (use_mono = false).")
@click.option("--split", type=click.Choice(["test", "val"]), default=None,
              help="The realistic mono's held-out pairs scored: val (seeds of its own) to decide on, test once, at "
                   "the end. Default: test. Not with --mono warp, whose pairs have seeds of their own.")
@click.option("--mono", type=click.Choice(["realistic", "warp"]), default="realistic", show_default=True,
              help="The held-out pairs' monocular input: realistic (the family training shows; --split's pairs) or "
                   "warp (another family: a smooth warp of the scene's mono-fooled disparity, blur, noise and an "
                   "unknown affine, on seeds 3000-3099 of its own). Trained networks are reused: scoring warp after "
                   "val or test trains nothing.")
@click.option("--workers", type=click.IntRange(1, 64), default=1, show_default=True,
              help="Trainings run side by side (each one process; give each a core: OMP_NUM_THREADS=1 on 2 cores).")
@click.option("--pretrained", type=click.Path(dir_okay=False, exists=True, path_type=Path), default=None,
              help="Fine-tune every network from this trunk (`bench pretrain`'s trunk.safetensors, trunk.json beside "
                   "it). Default: WORK_DIR/pretrain/trunk.safetensors when it exists.")
@click.option("--stereo-only-pretrained", type=click.Path(dir_okay=False, exists=True, path_type=Path), default=None,
              help="With --ablations: fine-tune the stereo-only network from this trunk, pre-trained without the "
                   "mono input (`bench pretrain --stereo-only`), and score it at 0 steps too; without it the "
                   "stereo-only network starts from --pretrained's trunk, whose context learnt with the mono.")
@click.option("--scratch", is_flag=True, help="Train from scratch even when WORK_DIR holds a pre-trained trunk.")
@click.option("--set", "settings", multiple=True, metavar="KEY=VALUE", callback=_lite_overrides,
              help="Override lite's config for every network (repeatable), e.g. --set model.fusion_gate=false: "
                   "how a design is compared with another on the same data, seeds and trunk.")
def fusion_benchmark(as_json: bool, seeds: int, steps: int | None, work_dir: Path, mono_only: bool,
                     ablations: bool, split: str | None, mono: str, workers: int, pretrained: Path | None,
                     stereo_only_pretrained: Path | None, scratch: bool, settings: dict[str, str]) -> None:
    """The synthetic illusion benchmark: train lite on the product's own samples and rendered captures
    (fine-tuned from the pre-trained trunk when there is one), score fusion, stereo, mono-gt-align and
    sgbm (with --ablations also the no-VLM network's fusion and stereo branch, and stereo_only) on frozen
    held-out rendered pairs (all, picture, mirror, non-illusion), their monocular input the realistic
    estimator's or, with --mono warp, one of another family."""
    from benchmarks.fusion import DEFAULT_STEPS, FINETUNE_STEPS, load_stereo_only_trunk, run_fusion_bench, run_mono_bench
    from benchmarks.trunk import TRUNK_FILE

    if mono == "warp" and split is not None:
        raise click.UsageError("--mono warp scores pairs of seeds of their own: --split is for the realistic mono's pairs")
    if pretrained and scratch:
        raise click.UsageError("--pretrained names a trunk to start from and --scratch starts from none: pass one")
    work_dir = work_dir.absolute()
    found = work_dir / TRUNK_FILE
    trunk = None if scratch else pretrained or (found if found.is_file() else None)
    if mono_only:
        if ablations or workers > 1 or settings or stereo_only_pretrained:
            raise click.UsageError("--ablations, --workers, --stereo-only-pretrained and --set are about training, "
                                   "and --mono-only trains nothing: pass one or the other")
        _report(run_mono_bench(split=split, mono=mono, work_dir=work_dir, pretrained=trunk), as_json)
        return
    steps = steps or (DEFAULT_STEPS if trunk is None else FINETUNE_STEPS)
    try:
        load_stereo_only_trunk(stereo_only_pretrained, ablations)
    except ValueError as exc:
        raise click.UsageError(str(exc)) from None
    results = run_fusion_bench(work_dir, seeds=seeds, steps=steps, ablations=ablations, split=split, mono=mono,
                               workers=workers, pretrained=trunk, stereo_only_pretrained=stereo_only_pretrained,
                               overrides=settings)
    if as_json:
        click.echo(json.dumps(results))
        return
    _print_fusion(results)


@bench.command("compare")
@click.argument("first", type=click.Path(dir_okay=False, exists=True, path_type=Path))
@click.argument("second", type=click.Path(dir_okay=False, exists=True, path_type=Path))
@click.option("--method", default="fusion", show_default=True, help="The method of FIRST compared.")
@click.option("--other", default=None, help="The method of SECOND it is compared with (default: the same).")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
def compare_benchmark(first: Path, second: Path, method: str, other: str | None, as_json: bool) -> None:
    """Two `bench fusion --json` records of the same pairs, frame by frame: METHOD of FIRST minus OTHER of
    SECOND per region, each record's seeds averaged, with a 95 % interval over scenes — how one design is
    decided against another on val."""
    from benchmarks.compare import compare_records

    try:
        records = [json.loads(path.read_text()) for path in (first, second)]
        found = compare_records(*records, method=method, other=other)
    except (ValueError, KeyError) as exc:
        raise click.UsageError(str(exc).strip("'\"")) from None
    if as_json:
        click.echo(json.dumps(found))
        return
    click.echo(f"{method} of {first.name} minus {found['other']} of {second.name}, {found['scenes']} scenes "
               "(< 0: the first is better), 95 % interval over scenes")
    for region, figures in found["regions"].items():
        click.echo(f"  {region:13}" + "".join(
            f"  {key} {v['value']:+.3f} [{v['low']:+.3f}, {v['high']:+.3f}] {v['decided']:9}"
            for key, v in figures.items()))


@bench.command("pretrain")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
@click.option("--work-dir", type=click.Path(file_okay=False, path_type=Path), default=Path("var/bench-fusion"),
              show_default=True, help="`bench fusion`'s work dir: the trunk goes to WORK_DIR/pretrain/trunk.safetensors.")
@click.option("--videos", type=click.IntRange(min=2, max=50_000), default=None,
              help="Rendered scenes (seeds 10000 on), default the benchmark's.")
@click.option("--frames", type=click.IntRange(min=1, max=100), default=None, help="Frames per scene.")
@click.option("--steps", type=click.IntRange(min=1), default=None, help="Training steps.")
@click.option("--stereo-only", is_flag=True,
              help="Pre-train the stereo-only network (never reads the mono input) instead; its trunk goes to "
                   "WORK_DIR/pretrain/trunk-stereo-only.safetensors.")
@click.option("--truth", type=click.Choice(["surface", "matcher"]), default="surface", show_default=True,
              help="The pre-training data's ground truth: the surface (a mirror's glass), or what a stereo matcher "
                   "finds (a mirror's reflection), as data that never teaches where glass is (the paper's SceneFlow); "
                   "its trunk's name ends in -matcher.")
def pretrain_benchmark(as_json: bool, work_dir: Path, videos: int | None, frames: int | None, steps: int | None,
                       stereo_only: bool, truth: str) -> None:
    """Pre-train lite's trunk (mono context encoder and stereo branch) on many rendered scenes with exact
    disparity, never the benchmark's seeds, through the product's training job; `bench fusion` then
    fine-tunes every network from it."""
    from benchmarks.pretrain import PRETRAIN_FRAMES, PRETRAIN_STEPS, PRETRAIN_VIDEOS, run_pretrain

    results = run_pretrain(work_dir.absolute(), videos=videos or PRETRAIN_VIDEOS, frames=frames or PRETRAIN_FRAMES,
                           steps=steps or PRETRAIN_STEPS, stereo_only=stereo_only, truth=truth)  # type: ignore[arg-type]
    if as_json:
        click.echo(json.dumps(results))
        return
    trunk = results["trunk"]
    click.echo(f"trunk: {work_dir / trunk['file']} ({trunk['tensors']} tensors, {trunk['parameters']} parameters, "
               f"{trunk['bytes']} bytes), sha256 {trunk['sha256']}; recipe in trunk.json")
    click.echo(f"  run {trunk['recipe']['run']}, best step {trunk['recipe']['best_step']}, "
               f"seeds {trunk['recipe']['data']['seeds'][0]}..{trunk['recipe']['data']['seeds'][1]}")
    _print_conditions({"pre-training captures": results["conditions"]["training"]["captures"],
                       "test pairs": results["conditions"]["held_out"]})
    click.echo(f"timings_s {results['timings_s']}")


def _print_fusion(results: dict[str, Any]) -> None:
    """The fusion benchmark for people: the pairs, the conditions, every method's figures, fusion's paired
    differences, the trunk it started from and the timings."""
    pairs = results["pairs"]
    name = pairs["split"] or pairs["mono"]
    click.echo(f"held-out pairs: {name}, mono {pairs['mono']}, seeds {pairs['seeds'][0]}-{pairs['seeds'][-1]}, "
               f"{pairs['samples']} pairs at {pairs['baseline_m']} m, "
               f"disparity {pairs['disparity_px'][0]}-{pairs['disparity_px'][1]} px "
               f"(training {results['train_disparity_px'][0]}-{results['train_disparity_px'][1]}), "
               f"sha256 {pairs['sha256'][:16]}")
    training = results["conditions"]["training"]
    _print_conditions({"training captures": training["captures"], "training generated": training["generated"],
                       f"{name} pairs": results["conditions"]["held_out"]})
    seeds = results["seeds"]
    click.echo(f"EPE px / bad-2 %, mean{' ± spread' if seeds > 1 else ''} over {seeds} seed(s) "
               f"(launch seeds {results['train_seeds']}, split of seed {results['split_seed']})")
    regions = list(next(iter(results["methods"].values())))
    click.echo(f"  {'method':16}" + "".join(f"  {r:>30}" for r in regions))
    for method, figures in results["methods"].items():
        click.echo(f"  {method:16}" + "".join(f"  {_figure(figures[r], 'epe') + ' / ' + _figure(figures[r], 'bad2'):>30}"
                                             for r in regions))
    paired = results["paired"]
    for key, unit in (("epe", "EPE px"), ("bad2", "bad-2 %")):
        click.echo(f"{unit}, {paired['reference']} minus each method, paired by seed (< 0: {paired['reference']} better; "
                   f"[k]: lower in k of {paired['seeds']} seeds)")
        for method, figures in paired["against"].items():
            click.echo(f"  {method:16}" + "".join(
                f"  {_figure(figures[r], key, signed=True) + ' [' + str(figures[r][key + '_lower']) + ']':>30}" for r in regions))
    _print_intervals(results["intervals"], regions)
    trunk = results["pretrained"]
    if trunk is None:
        click.echo("pretrained: none (from scratch)")
    else:
        fresh = {name: len(init["fresh"]) for name, init in trunk["init"].items()}
        click.echo(f"pretrained: {trunk['file']} sha256 {trunk['sha256'][:16]}; tensors started fresh: {fresh}")
    if results.get("stereo_only_pretrained"):
        own = results["stereo_only_pretrained"]
        click.echo(f"stereo_only pretrained: {own['file']} sha256 {own['sha256'][:16]}")
    click.echo(f"timings_s {results['timings_s']}")


def _print_intervals(found: dict[str, Any], regions: list[str]) -> None:
    """The decisions: each difference's 95 % interval over scenes and seeds, the oracle gate's headroom
    and each gate's share of it."""
    def cell(value: dict[str, float], signed: bool = True) -> str:
        sign = "+" if signed else ""
        return f"{value['value']:{sign}.3f} [{value['low']:{sign}.3f}, {value['high']:{sign}.3f}]"

    click.echo(f"EPE px, {int(found['level'] * 100)} % intervals over {found['scenes']} scenes and {found['seeds']} "
               "seed(s): fusion minus each method (lower / higher / undecided), each gate minus its own stereo branch")
    rows = [(f"fusion - {m}", v) for m, v in found["against"].items()] + list(found["isolation"].items())
    for name, figures in rows:
        click.echo(f"  {name:30}" + "".join(f"  {cell(figures[r]['epe']) + ' ' + figures[r]['epe']['decided']:>36}"
                                            for r in regions))
    for title, block, signed in (("oracle gate's headroom, px (stereo minus oracle)", found["oracle"], False),
                                 ("share of its stereo branch's oracle headroom each gate takes", found["capture"], True)):
        click.echo(title)
        for name, figures in block.items():
            click.echo(f"  {name:30}" + "".join(f"  {cell(figures[r], signed):>36}" for r in regions))


def _figure(figures: dict[str, float], key: str, *, signed: bool = False) -> str:
    value = f"{figures[key]:+.2f}" if signed else f"{figures[key]:.2f}"
    spread = figures.get(f"{key}_spread")
    return value if spread is None else f"{value} ± {spread:.2f}"


def _print_conditions(groups: dict[str, dict[str, Any]]) -> None:
    """Per group of frames the ranges (min / median / max over frames) of the mirror fooling and the
    aligned mono's error: what training shows beside what the test meets."""
    click.echo(f"  {'conditions (min / median / max)':32}  {'mirror fooling px':>32}  {'aligned mono EPE px':>32}")
    for group, ranges in groups.items():
        cells = [f"{r['frames']} frames: {r['min']:.2f} / {r['median']:.2f} / {r['max']:.2f}" if r["frames"] else "none"
                 for r in (ranges["mirror_fooling_px"], ranges["aligned_mono_epe_px"])]
        click.echo(f"  {group:32}" + "".join(f"  {cell:>32}" for cell in cells))


def _report(results: dict[str, object], as_json: bool) -> None:
    if as_json:
        click.echo(json.dumps(results))
        return
    for key, value in results.items():
        budget = _BUDGETS_MS.get(key)
        verdict = "" if budget is None else f"  (budget {budget} ms: {'ok' if value <= budget else 'OVER'})"
        click.echo(f"{key:32} {value}{verdict}")
