"""The synthetic illusion benchmark: the paper's protocol in miniature, with exact ground truth.

Training data, made by the product itself: (a) synthetic videos ingested, approved, annotated from
their true masks, generated and accepted — as ``demo`` does — and (b) rendered stereo pairs of
other seeds imported as captures, whose raytraced right views show stereo fooled by mirrors (the
generated samples never do: their right views are warped from the rectified disparity). A short
``lite`` run trains on them through the real training job. The test set is rendered pairs of yet
other seeds, never seen in training or validation, rendered with a baseline that brings their
disparities into the training range, with their realistic monocular disparity (relative, coarse,
fooled by pictures and partly by mirrors: ``dataset.synthetic.mono``) as the monocular input.
Validation pairs of their own seeds (``split="val"``), rendered alike, are what the model's decisions
are made on, so that the test pairs are scored once. Every method is scored densely over the same
valid pixels. ``ablations`` trains, per seed, the no-VLM and stereo-only networks beside fusion
(ABLATIONS). ``run_mono_bench`` scores mono-gt-align alone, without training: the figure the
monocular model was calibrated on.

Preparing the data is cached in the work folder; preparing, rendering the held-out pairs, each
network's training and each scoring are timed apart.
"""

from __future__ import annotations

import json
import statistics
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy import select

from dataset.capture.synthetic import import_rendered_video
from dataset.db import transaction
from dataset.models import Frame, FrameState, Job, JobState, Role, TrainingRun, User
from dataset.readers import StereoSample
from dataset.readers.base import make_regions
from dataset.readers.version import VersionReader, pin_dataset_version
from dataset.services import jobs as job_service
from dataset.services import training
from dataset.services import users as user_service
from dataset.services.demo import accept_generated_samples, seed_reviews_and_annotations
from dataset.services.ingest import ingest_params
from dataset.services.review import review_frame
from dataset.services.sample_review import review_sample
from dataset.synthetic import render_video, write_synthetic_dataset
from dataset.synthetic.io import FORMAT as SYNTHETIC_FORMAT
from dataset.synthetic.layout import BASELINE_M
from model.evaluate import EvalOptions, evaluate
from model.methods import Predict, build_methods
from webapp.cli.workspace import init_workspace
from webapp.jobs import runs as run_control
from webapp.jobs.handlers import HANDLERS
from webapp.runtime import Runtime

SIZE = (320, 192)  # W x H of every rendered frame
FRAMES = 6  # per video
GENERATED_VIDEOS = 6  # seeds 0..5 through the pipeline
RENDERED_SEEDS = tuple(range(40, 46))  # imported as captures
TEST_SEEDS = tuple(range(100, 104))  # held out: never in training or validation; scored once, at the end
VAL_SEEDS = tuple(range(200, 204))  # held out as well, rendered alike: the model's decisions are made on these
SPLITS: dict[str, tuple[int, ...]] = {"test": TEST_SEEDS, "val": VAL_SEEDS}
REGIONS = ("all", "picture", "mirror", "non_illusion")
BASELINES = ("mono_gt_align", "sgbm")  # untrained: scored once per benchmark, not per seed
TRAIN_OVERRIDES: dict[str, Any] = {"train.batch_size": 2, "train.crop": (160, 288), "train.val_every": 200,
                                   "train.checkpoint_every": 200}
DEFAULT_STEPS = 1500
SPLIT = "train=0.85,val=0.15"


@dataclass(frozen=True)
class Network:
    """A network each benchmark seed trains: ``lite`` with TRAIN_OVERRIDES and ``overrides``, scored as
    ``methods`` ({report key: method of model.methods})."""

    name: str
    overrides: Mapping[str, Any]
    methods: Mapping[str, str]


FUSION = Network("fusion", {}, {"fusion": "fusion", "stereo": "stereo"})
# --ablations, the paper's in miniature. no_vlm: the confidence from image features alone (the PF
# ablation). stereo_only: the stereo branch alone (model.use_mono off: its context encoder is fed a
# constant instead of the mono input, no confidence or fusion, RAFT-Stereo's sequence loss), trained
# the same way on the same data; unlike the fusion network's stereo branch it never sees the mono input.
ABLATIONS = (Network("no_vlm", {"model.use_vlm": False}, {"fusion_no_vlm": "fusion"}),
             Network("stereo_only", {"model.use_vlm": False, "model.use_mono": False}, {"stereo_only": "stereo"}))


def run_fusion_bench(work_dir: Path, *, seeds: int = 1, steps: int = DEFAULT_STEPS, ablations: bool = False,
                     split: str = "test", workers: int = 1) -> dict[str, Any]:
    """Prepare (or reuse) the data in ``work_dir``, train per seed the fusion network (and, with
    ``ablations``, the no-VLM and stereo-only ones), ``workers`` trainings at a time, and score every
    method on the held-out pairs of ``split`` (SPLITS). Returns per method and region the mean (and
    spread over seeds) of EPE and bad-2, the disparity ranges of training and the pairs, and the
    timings (seconds; a network's training time is its job's, from start to end)."""
    started = time.perf_counter()
    rt, cached = prepared_workspace(work_dir / "workspace")
    prepare_s = time.perf_counter() - started
    train_range = training_disparity_range(rt)
    pairs, render_s, info = _held_out(train_range, split)
    networks = (FUSION, *ABLATIONS) if ablations else (FUSION,)
    timed = time.perf_counter()
    baselines = _score(pairs, build_methods(list(BASELINES), checkpoint=None, predictions=None, mono_dir=None))
    baselines_s = time.perf_counter() - timed
    launched = {(seed, network.name): _launch(rt, seed, steps, network) for seed in range(seeds) for network in networks}
    timed = time.perf_counter()
    _run_jobs(rt, workers)
    train_wall_s = time.perf_counter() - timed
    runs = [_seed_scores(rt, seed, pairs, networks, launched) for seed in range(seeds)]
    rt.close()
    return {
        "methods": {**_aggregate([r["methods"] for r in runs]), **_aggregate([baselines])},
        "seeds": seeds, "steps": steps, "preset": "lite", "size": f"{SIZE[0]}x{SIZE[1]}", "workers": workers,
        "networks": {n.name: {"overrides": dict(n.overrides), "methods": list(n.methods)} for n in networks},
        "train_disparity_px": train_range, "pairs": info, "prepare_cached": cached,
        "timings_s": {"prepare": round(prepare_s, 1), "render_pairs": round(render_s, 1),
                      "score_baselines": round(baselines_s, 1),
                      "train": {n.name: [r["networks"][n.name]["train_s"] for r in runs] for n in networks},
                      "train_wall": round(train_wall_s, 1),
                      "score": {n.name: [r["networks"][n.name]["score_s"] for r in runs] for n in networks},
                      "total": round(time.perf_counter() - started, 1)},
        "runs": [{"seed": r["seed"], **{name: net["run"] for name, net in r["networks"].items()}} for r in runs],
    }


def _held_out(train_range: list[float], split: str) -> tuple[list[StereoSample], float, dict[str, Any]]:
    """The pairs of ``split``, the seconds rendering them took, and what describes them."""
    if split not in SPLITS:
        raise ValueError(f"unknown split {split!r}; choose {' or '.join(SPLITS)}")
    started = time.perf_counter()
    pairs, baseline = test_samples(train_range, SPLITS[split])
    values = np.concatenate([s.disparity[np.isfinite(s.disparity)] for s in pairs])
    info = {"split": split, "seeds": list(SPLITS[split]), "samples": len(pairs), "disparity_px": _range(values),
            "baseline_m": round(baseline, 4)}
    return pairs, time.perf_counter() - started, info


def prepared_workspace(home: Path) -> tuple[Runtime, bool]:
    """The benchmark's workspace: every synthetic frame generated and accepted, and the rendered
    captures imported and accepted. Built once; a later call finds ``prepared.json`` and reuses it."""
    marker = home / "prepared.json"
    recipe = {"size": SIZE, "frames": FRAMES, "generated": GENERATED_VIDEOS, "rendered": RENDERED_SEEDS,
              "synthetic": SYNTHETIC_FORMAT}
    cached = marker.is_file() and json.loads(marker.read_text()) == json.loads(json.dumps(recipe))
    settings = init_workspace(home)
    rt = Runtime(settings)
    if cached:
        return rt, True
    with transaction(rt.sessions) as s:
        users = {role: s.scalar(select(User).where(User.name == f"bench-{role.value}"))
                 or user_service.create_user(s, f"bench-{role.value}", role, f"bench-{role.value}-password")
                 for role in Role}
        user_ids = {role: u.id for role, u in users.items()}
    videos = write_synthetic_dataset(home / "synthetic", videos=GENERATED_VIDEOS, seed=0, n_frames=FRAMES,
                                     width=SIZE[0], height=SIZE[1])
    with transaction(rt.sessions) as s:
        for path in videos:
            rt.submit(s, "ingest", ingest_params(str(path), dedup_hamming=None, prefilter=True), None)
    _run_jobs(rt)
    with transaction(rt.sessions) as s:
        curator, annotator = s.get(User, user_ids[Role.curator]), s.get(User, user_ids[Role.annotator])
        # Every frame joins, whatever the prefilter said: the benchmark measures the model, not the filter.
        for frame_id in s.scalars(select(Frame.id).where(Frame.state.in_((FrameState.prefiltered, FrameState.rejected)))):
            review_frame(s, frame_id, curator, "approve")
        for frame_id in seed_reviews_and_annotations(s, rt.media, curator, annotator, approve=FRAMES, annotate=FRAMES):
            rt.submit(s, "generate", {"frame_id": frame_id}, annotator)
    _run_jobs(rt)
    with transaction(rt.sessions) as s:
        curator = s.get(User, user_ids[Role.curator])
        accept_generated_samples(s, curator)
        for seed in RENDERED_SEEDS:
            for sample_id in import_rendered_video(s, rt.media, render_video(seed, FRAMES, *SIZE)):
                review_sample(s, sample_id, curator, "accept")
    marker.write_text(json.dumps(recipe))
    return rt, False


def _run_jobs(rt: Runtime, workers: int = 1) -> None:
    ran = job_service.run_queued_jobs(HANDLERS, rt, workers=workers)
    failed = [job_id for job_id, state in ran if state != JobState.succeeded]
    if failed:
        raise RuntimeError(f"benchmark: jobs {failed} did not succeed (`illusion-studio jobs show ID`)")


def training_disparity_range(rt: Runtime) -> list[float]:
    """The 1st and 99th percentile of the accepted samples' disparities (px)."""
    with rt.sessions() as s:
        version = pin_dataset_version(s, rt.media)
    reader = VersionReader(version, rt.settings.media_root)
    values = np.concatenate([d[np.isfinite(d)] for d in (reader[i].disparity for i in range(len(reader)))])
    return _range(values)


def _range(values: np.ndarray) -> list[float]:
    return [round(float(np.percentile(values, 1)), 2), round(float(np.percentile(values, 99)), 2)]


def test_samples(train_range: list[float], seeds: tuple[int, ...] = TEST_SEEDS,
                 frames: int = FRAMES) -> tuple[list[StereoSample], float]:
    """The held-out rendered pairs (``frames`` of each seed, at SIZE), at a baseline putting their
    first seed's 99th percentile disparity at the training one's; regions all / picture / mirror /
    non_illusion; mono = the realistic monocular disparity."""
    probe = render_video(seeds[0], 1, *SIZE)
    baseline = BASELINE_M * train_range[1] / float(np.percentile(probe.frames[0].disparity, 99))
    samples = []
    for seed in seeds:
        video = render_video(seed, frames, *SIZE, baseline_m=baseline)
        for frame in video.frames:
            masks = {pair.illusion_type: pair.illusion for pair in frame.regions}
            illusion = np.logical_or.reduce(list(masks.values()))
            samples.append(StereoSample(
                name=f"{video.name}/{frame.index:04d}", left=frame.left, right=frame.right,
                disparity=frame.disparity, regions=make_regions(frame.disparity, {**masks, "non_illusion": ~illusion}),
                mono=frame.mono_disparity, meta={"seed": seed}))
    return samples, baseline


def run_mono_bench(work_dir: Path, *, split: str = "test") -> dict[str, Any]:
    """mono-gt-align on the held-out pairs of ``split``, no training: EPE and bad-2 per region, the
    non-illusion bad-2 (the monocular model's calibration figure) on top. Prepares (or reuses) the
    workspace in ``work_dir`` for the training disparity range that fixes the pairs' baseline."""
    started = time.perf_counter()
    rt, cached = prepared_workspace(work_dir / "workspace")
    train_range = training_disparity_range(rt)
    rt.close()
    pairs, _render_s, info = _held_out(train_range, split)
    figures = mono_figures(pairs)
    return {"non_illusion_bad2": figures["non_illusion"]["bad2"], "methods": {"mono_gt_align": figures},
            "size": f"{SIZE[0]}x{SIZE[1]}", "train_disparity_px": train_range, "pairs": info,
            "prepare_cached": cached, "seconds": round(time.perf_counter() - started, 1)}


def mono_figures(samples: list[StereoSample]) -> dict[str, dict[str, float]]:
    """mono-gt-align's EPE (px) and bad-2 (%) per region of REGIONS, mean over ``samples``."""
    figures = _score(samples, build_methods(["mono_gt_align"], checkpoint=None, predictions=None, mono_dir=None))
    return {r: {k: round(v, 3) for k, v in f.items()} for r, f in figures["mono_gt_align"].items()}


def _seed_scores(rt: Runtime, seed: int, pairs: list[StereoSample], networks: tuple[Network, ...],
                 launched: Mapping[tuple[int, str], int]) -> dict[str, Any]:
    """Each of ``networks``, trained with ``seed`` (its run id in ``launched``), scored on ``pairs``: their
    figures by report key, and per network its run id and the seconds its training and its scoring took."""
    figures: dict[str, Any] = {}
    timings: dict[str, dict[str, Any]] = {}
    for network in networks:
        run_id = launched[seed, network.name]
        checkpoint, train_s = _trained(rt, run_id)
        started = time.perf_counter()
        built = build_methods(sorted(set(network.methods.values())), checkpoint=checkpoint, predictions=None,
                              mono_dir=None)
        figures.update(_score(pairs, {key: built[method] for key, method in network.methods.items()}))
        timings[network.name] = {"run": run_id, "train_s": round(train_s, 1),
                                 "score_s": round(time.perf_counter() - started, 1)}
    return {"seed": seed, "methods": figures, "networks": timings}


def network_overrides(network: Network, steps: int) -> dict[str, Any]:
    """The overrides of ``lite`` that ``network`` is trained with for ``steps`` steps."""
    return {**TRAIN_OVERRIDES, "train.steps": steps, **network.overrides}


def _launch(rt: Runtime, seed: int, steps: int, network: Network) -> int:
    """Queue ``network``'s training with ``seed`` through the product's training job: its run id."""
    with transaction(rt.sessions) as s:
        admin = s.scalar(select(User).where(User.name == "bench-admin"))
        run = run_control.launch(
            rt, s, preset="lite", overrides=network_overrides(network, steps), selection=training.DataSelection(),
            launch=training.Launch(split=training.parse_split(SPLIT), seed=seed), user=admin)
        return run.id


def _trained(rt: Runtime, run_id: int) -> tuple[Path, float]:
    """A finished run's best checkpoint and the seconds its training job ran."""
    with rt.sessions() as s:
        job = s.get(Job, s.get(TrainingRun, run_id).job_id)
        seconds = (job.finished_at - job.started_at).total_seconds()
    return training.run_dir(rt.settings.runs_dir, run_id) / "checkpoints" / "best.pt", seconds


def _score(pairs: list[StereoSample], methods: dict[str, Predict]) -> dict[str, dict[str, dict[str, float]]]:
    """EPE (px) and bad-2 (%) per method and region of REGIONS, mean over ``pairs``."""
    report = evaluate(pairs, methods, EvalOptions(regions=REGIONS))
    if report["failed"]:
        raise RuntimeError(f"benchmark evaluation failed on {report['failed'][:3]}")
    return {m: {r: {k: d["regions"][r][k] for k in ("epe", "bad2")} for r in REGIONS}
            for m, d in report["methods"].items()}


def _aggregate(per_seed: list[dict[str, Any]]) -> dict[str, Any]:
    """Mean over seeds of each figure, with the spread (population standard deviation) beside it."""
    out: dict[str, Any] = {}
    for method in per_seed[0]:
        out[method] = {}
        for region in per_seed[0][method]:
            out[method][region] = {}
            for key in per_seed[0][method][region]:
                values = [run[method][region][key] for run in per_seed]
                out[method][region][key] = round(statistics.fmean(values), 3)
                if len(values) > 1:
                    out[method][region][f"{key}_spread"] = round(statistics.pstdev(values), 3)
    return out
