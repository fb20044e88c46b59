"""``illusion-studio bench pretrain``: the fusion benchmark's pre-training stage (the paper pre-trains on
SceneFlow, then fine-tunes on illusions).

Many rendered scenes with exact disparity — seeds from PRETRAIN_FIRST_SEED on, a range kept apart
from every seed the benchmark trains, validates or tests on — each rendered at a baseline drawn for it
over the range that covers the held-out pairs' disparities (``fusion.capture_baseline``), imported as
captures into a workspace of their own (``<work dir>/pretrain/workspace``) and accepted; one ``lite``
run trains on them through the product's training job. The network trained is the no-VLM one, so that
its mono context encoder learns from the mono input as the fusion networks' does; only its trunk
(``benchmarks.trunk``) is kept, in ``<work dir>/pretrain/trunk.safetensors`` with
``trunk.json`` (recipe and sha256) beside it, where ``bench fusion`` finds it. The recipe holds what
rebuilds the trunk (``benchmarks.provenance``): the resolved config it trained with, a hash of its
data, the commit and a fingerprint of the sources that shape training.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from benchmarks import fusion, provenance
from benchmarks.trunk import save_trunk, trunk_file
from dataset.synthetic.io import FORMAT as SYNTHETIC_FORMAT
from dataset.tables import TrainingRun
from dataset.version import code_version

PRETRAIN_FIRST_SEED = 10_000
PRETRAIN_VIDEOS = 200
PRETRAIN_FRAMES = 4  # per video: more scenes rather than more frames of one
PRETRAIN_STEPS = 2000  # about 35 min on one core of this 2-core machine: the trunk is rebuilt within the hour
PRETRAIN_SPLIT = "train=0.95,val=0.05"  # by video, within the pre-training seeds
PRETRAIN_SEED = 0
# The no-VLM network (see the module docstring); validation and checkpoints spaced for the longer run.
PRETRAIN_OVERRIDES: dict[str, Any] = {"model.use_vlm": False, "train.val_every": 500, "train.checkpoint_every": 500}


def benchmark_seeds() -> set[int]:
    """Every scene seed the fusion benchmark trains, validates or tests on (the warp mono's pairs too)."""
    return {*range(fusion.GENERATED_VIDEOS), *fusion.RENDERED_SEEDS, *(s for seeds in fusion.SPLITS.values() for s in seeds),
            *fusion.CORRUPTION_SEEDS}


def pretrain_seeds(videos: int) -> tuple[int, ...]:
    """The scene seeds of ``videos`` pre-training videos; ValueError if any is one of the benchmark's."""
    seeds = tuple(range(PRETRAIN_FIRST_SEED, PRETRAIN_FIRST_SEED + videos))
    taken = sorted(benchmark_seeds().intersection(seeds))
    if taken:
        raise ValueError(f"pre-training seeds {seeds[0]}..{seeds[-1]} include the benchmark's seed {taken[0]}")
    return seeds


def pretrain_overrides(steps: int, stereo_only: bool = False) -> dict[str, Any]:
    """The overrides of ``lite`` the pre-training run uses for ``steps`` steps; ``stereo_only``: the
    stereo-only network (its context encoder fed a constant, never the mono input)."""
    return {**fusion.TRAIN_OVERRIDES, "train.steps": steps, **PRETRAIN_OVERRIDES,
            **({"model.use_mono": False} if stereo_only else {})}


def run_pretrain(work_dir: Path, *, videos: int = PRETRAIN_VIDEOS, frames: int = PRETRAIN_FRAMES,
                 steps: int = PRETRAIN_STEPS, stereo_only: bool = False, truth: fusion.Truth = "surface") -> dict[str, Any]:
    """Prepare (or reuse) the pre-training data under ``work_dir/pretrain``, train on it for ``steps``
    steps and write the trunk of the run's best checkpoint to ``work_dir/``:func:`trunk_file` (with
    ``stereo_only``, the stereo-only network's; with ``truth`` "matcher", trained on what a matcher finds,
    reflections and all — in a workspace of its own). Returns the trunk's record (file, sha256, recipe),
    the conditions of the pre-training data beside the test pairs', and the timings (seconds)."""
    started = time.perf_counter()
    # Taken before training, so that the record names the code the run started from.
    source_commit, sources = provenance.source_commit(), provenance.training_sources_fingerprint()
    seeds = pretrain_seeds(videos)
    data = {"protocol": fusion.PROTOCOL, "seeds": [seeds[0], seeds[-1]], "frames": frames, "size": fusion.SIZE,
            "capture_baselines_m": fusion.TRAIN_BASELINE_M, "synthetic": SYNTHETIC_FORMAT,
            "families": fusion.SCENE_FAMILIES, "truth": truth}
    home = work_dir / "pretrain" / ("workspace" if truth == "surface" else f"workspace-{truth}")
    rt, conditions = fusion.bench_workspace(home, data)
    cached = conditions is not None
    if conditions is None:
        captures = fusion.import_captures(rt, seeds, frames, truth)
        # Hashed from the same renders the import made (rendering is deterministic), once per prepared
        # workspace: a reused workspace keeps the hash of what it imported.
        digest = provenance.pretrain_data_digest(seeds, frames, truth=truth)
        conditions = fusion.finish_workspace(home, data, {"captures": captures, "data_sha256": digest})
    data_sha256 = conditions.get("data_sha256") or provenance.pretrain_data_digest(seeds, frames, truth=truth)
    prepare_s = time.perf_counter() - started
    try:
        run_id = fusion.launch_run(rt, PRETRAIN_SEED, pretrain_overrides(steps, stereo_only), split=PRETRAIN_SPLIT)
        fusion.run_jobs(rt, runs=[run_id])
        checkpoint, train_s = fusion.trained_checkpoint(rt, run_id)
        with rt.sessions() as s:
            best_step = s.get(TrainingRun, run_id).best_step
    finally:
        rt.close()
    overrides = pretrain_overrides(steps, stereo_only)
    recipe = {"preset": "lite", "overrides": overrides, "seed": PRETRAIN_SEED, "split": PRETRAIN_SPLIT,
              "data": data, "run": run_id, "best_step": best_step, "code_version": code_version(),
              "command": f"illusion-studio bench pretrain --videos {videos} --frames {frames} --steps {steps}"
                         + (" --stereo-only" if stereo_only else "") + (f" --truth {truth}" if truth != "surface" else ""),
              # The command alone does not rebuild the trunk once the preset's defaults move on.
              "resolved_config": provenance.resolved_config("lite", overrides),
              "data_sha256": data_sha256,
              "provenance": {"commit": source_commit, "sources": sources}}
    trunk = trunk_file(stereo_only, truth)
    record = save_trunk(checkpoint, work_dir / trunk, recipe)
    timed = time.perf_counter()
    held_out = fusion.condition_ranges(fusion.condition_values(fusion.held_out_samples(fusion.TEST_SEEDS)))
    return {"trunk": {**record, "file": str(trunk)},
            "conditions": {"training": conditions, "held_out": held_out}, "prepare_cached": cached,
            "timings_s": {"prepare": round(prepare_s, 1), "train": round(train_s, 1),
                          "render_pairs": round(time.perf_counter() - timed, 1),
                          "total": round(time.perf_counter() - started, 1)}}
