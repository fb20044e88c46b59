"""The synthetic illusion benchmark: the paper's protocol in miniature, with exact ground truth.

Training data, made by the product itself: (a) synthetic videos ingested, approved, annotated from
their true masks, generated and accepted — as ``demo`` does — and (b) rendered stereo pairs of
other seeds imported as captures, whose raytraced right views show stereo fooled by mirrors (the
generated samples never do: their right views are warped from the rectified disparity). Short
``lite`` runs train on them through the real training job, from scratch or fine-tuned from the
pre-trained trunk of ``bench pretrain`` (``benchmarks.pretrain``).

The training data shows the test's conditions, not its seeds (protocol 2): each capture
video is rendered at a baseline drawn for it from TRAIN_BASELINE_M, a range covering the held-out
pairs' disparities (so its mirrors fool stereo as much as theirs do), and each generated sample's
monocular input is an independent realistic draw (``dataset.synthetic.mono``'s estimator, another
one than the map its ground truth was made from), not that map itself — in the benchmark only: the
product's generation keeps deriving the ground truth from the monocular map, as the paper does.

The held-out pairs are frozen: rendered pairs of seeds never seen in training, 100 scenes of
HELD_OUT_FRAMES frames per set (protocol 3: enough scenes that an interval over scenes can decide), at
the constant baseline HELD_OUT_BASELINE_M, whatever the training data holds, with their realistic monocular
disparity as the monocular input; the JSON records their baseline and a hash of their pixels. The
test pairs (TEST_SEEDS) are scored once; the validation pairs (VAL_SEEDS, ``split="val"``) are what
the model's decisions are made on. Every figure is kept per frame and region
(``benchmarks.fusion_stats``), every comparison gets a 95 % interval from a bootstrap over scenes and
seeds, and a decision is made only where the interval excludes 0. A third set, ``mono="warp"``, asks
whether fusion learnt to weigh a monocular map against stereo or only the realistic estimator's errors: pairs of seeds of its own
(CORRUPTION_SEEDS), rendered alike, whose monocular input is of another family than the one training
shows (``dataset.synthetic.corruptions.warped_mono``: a smooth warp of the scene's mono-fooled
disparity, blur, noise and an unknown affine). Every method is scored densely over the same valid pixels.

The record is paired: the train/val split of the training data is the same for every benchmark
seed (SPLIT_SEED's), so a seed changes only the training (initialisation, order, augmentation);
every seed's figures are kept, and fusion's differences against each other method are taken seed
by seed. ``ablations`` trains, per seed, the no-VLM and stereo-only networks beside fusion
(ABLATIONS). ``run_mono_bench`` scores mono-gt-align alone, without training.

Preparing the data is cached in the work folder, and so is every network trained (TRAINED): a network
is trained again only when its config, launch seed, starting trunk or the model package's code differ
(:func:`network_key`), so scoring the test pairs after deciding on the validation ones trains nothing,
and a benchmark stopped half way resumes. Preparing, rendering the held-out pairs, each network's
training and each scoring are timed apart.
"""

from __future__ import annotations

import hashlib
import json
import statistics
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

import model
from benchmarks import fusion_stats as stats
from benchmarks.provenance import provenance_block, source_commit
from benchmarks.trunk import Trunk, compose_init, load_trunk
from core.atomic import atomic_write_bytes
from dataset.capture.synthetic import import_rendered_video
from dataset.db import transaction
from dataset.media import MediaStore
from dataset.readers import StereoSample
from dataset.readers.synthetic import frame_sample
from dataset.readers.version import VersionReader, pin_dataset_version
from dataset.samples import load_output, mask_name, store_outputs
from dataset.services import jobs as job_service
from dataset.services import pipeline, training
from dataset.services import users as user_service
from dataset.services.demo import accept_generated_samples, seed_reviews_and_annotations
from dataset.services.ingest import ingest_params
from dataset.services.review import review_frame
from dataset.services.sample_review import review_sample
from dataset.synthetic import SyntheticVideo, render_video, write_synthetic_dataset
from dataset.synthetic.corruptions import warped_mono
from dataset.synthetic.io import FORMAT as SYNTHETIC_FORMAT
from dataset.synthetic.mono import realistic_mono, sample_mono_model
from dataset.tables import Frame, FrameState, Job, JobState, Role, RunState, Sample, SampleState, TrainingRun, User, Video
from model.evaluate import EvalOptions, sample_metrics
from model.methods import Predict, build_methods
from model.presets import load_preset
from webapp.cli.workspace import init_workspace
from webapp.jobs import runs as run_control
from webapp.jobs.handlers import HANDLERS
from webapp.runtime import Runtime

# 1: pairs at a baseline from the training data, a split per seed; 2: frozen held-out pairs, one split;
# 3: 100 held-out scenes per set, per-frame records and intervals over scenes and seeds; 4: 96 capture
# videos (a stereo branch that cannot learn a few dozen scenes' glass by heart), one split seed for all
PROTOCOL = 4
SIZE = (320, 192)  # W x H of every rendered frame
FRAMES = 6  # per video
GENERATED_VIDEOS = 6  # seeds 0..5 through the pipeline
# Imported as captures: enough scenes that their mirrors fool stereo as much as the held-out ones do.
RENDERED_SEEDS = tuple(range(40, 136))
TEST_SEEDS = tuple(range(1_000, 1_100))  # held out: never in training or validation; scored once, at the end
VAL_SEEDS = tuple(range(2_000, 2_100))  # held out as well, rendered alike: the model's decisions are made on these
HELD_OUT_FRAMES = 2  # per held-out scene: frames of one scene are alike, so scenes rather than frames
# Every scene of protocol 3 (training, pre-training, held out) is of the scene families
# (dataset.synthetic.layout): frames of one distribution for every kind, large mirrors, textureless and
# repetitive walls, estimators that read a mirror as a surface beside ones it fools.
SCENE_FAMILIES = True
# The ground truth a capture carries: "surface", the first surface met (a mirror's glass) — the product's
# truth; or "matcher", what a stereo matcher finds (a mirror's reflection, as deep as the scene it shows).
# Pre-training on the matcher's truth stands for the paper's SceneFlow pre-training: data that never
# teaches a network where glass is, so that it reports reflections, as published stereo networks do.
Truth = Literal["surface", "matcher"]
TRUTHS: tuple[Truth, ...] = ("surface", "matcher")
SPLITS: dict[str, tuple[int, ...]] = {"test": TEST_SEEDS, "val": VAL_SEEDS}  # the realistic mono's held-out pairs
CORRUPTION_SEEDS = tuple(range(3_000, 3_100))  # held out as well, rendered alike: the warp mono's pairs, no split
MONO_FAMILIES = ("realistic", "warp")  # the held-out pairs' monocular input: the training estimator's family, or not
HELD_OUT_BASELINE_M = 0.63  # frozen: the baseline protocol 1 derived for the test pairs (0.6279 m), now a constant
# Per capture video, log-uniform: the held-out pairs at 0.63 m span about 19-51 px (1st-99th percentile)
# and their mirrors fool stereo by 8-17 px; scenes at 0.35-1.0 m span about 10-83 px and 5-29 px.
TRAIN_BASELINE_M = (0.35, 1.0)
_BASELINE_STREAM = 0x62617365  # "base": the capture baselines' random numbers, apart from the scenes'
GENERATED_MONO_SEED = 1_000_000  # + a generated video's seed: the estimator of its samples' mono input
REGIONS = ("all", "illusion", "picture", "mirror", "non_illusion")  # illusion: pictures and mirrors together
BASELINES = ("mono_gt_align", "sgbm")  # untrained: scored once per benchmark, not per seed
TRAIN_OVERRIDES: dict[str, Any] = {"train.batch_size": 2, "train.crop": (160, 288), "train.val_every": 200,
                                   "train.checkpoint_every": 200}
HEADROOM_PX = 1.0  # the oracle gate's gain inside illusions below which the networks have nothing to decide
DEFAULT_STEPS = 1500  # from scratch
FINETUNE_STEPS = 500  # from the pre-trained trunk: the paper fine-tunes briefly on illusions after pre-training
SPLIT = "train=0.85,val=0.15"
SPLIT_SEED = 0  # every benchmark seed trains on the train/val split this seed deals
PREPARED = "prepared.json"  # in a workspace: the recipe it was prepared with and the conditions its data shows
TRAINED = "trained.json"  # in a workspace: {network_key: run id} of every network launched there


@dataclass(frozen=True)
class Network:
    """A network each benchmark seed trains: ``lite`` with TRAIN_OVERRIDES and ``overrides``, scored as
    ``methods`` ({report key: method of model.methods})."""

    name: str
    overrides: Mapping[str, Any]
    methods: Mapping[str, str]


FUSION = Network("fusion", {}, {"fusion": "fusion", "stereo": "stereo"})
# --ablations, the paper's in miniature. no_vlm: the confidence from image features alone (the PF
# ablation), its own stereo branch scored too. stereo_only: the stereo branch alone (model.use_mono off:
# its context encoder is fed a constant instead of the mono input, no confidence or fusion, RAFT-Stereo's
# sequence loss), trained the same way on the same data, except that it is all trunk, so it always
# fine-tunes whole (train.freeze_trunk off; with --set train.freeze_trunk=true the other two hold their
# trunk). Fine-tuned from the fusion networks' trunk it starts handicapped: that trunk's context encoder
# learnt with the mono input, which stereo_only replaces by a constant (--stereo-only-pretrained).
ABLATIONS = (Network("no_vlm", {"model.use_vlm": False}, {"fusion_no_vlm": "fusion", "stereo_no_vlm": "stereo"}),
             Network("stereo_only", {"model.use_vlm": False, "model.use_mono": False, "train.freeze_trunk": False},
                     {"stereo_only": "stereo"}))
# Scored, never trained: the trunk composed as the no-VLM network (its fresh confidence and fusion heads
# from the seed), at 0 steps. What fine-tuning adds is measured against it.
TRUNK_AT_0 = Network("trunk_0", {"model.use_vlm": False}, {"trunk_0": "fusion", "trunk_0_stereo": "stereo"})
# Scored, never trained, with a stereo-only trunk of its own (--stereo-only-pretrained): the stereo-only
# network at 0 steps, a stereo branch pre-trained without the mono.
STEREO_ONLY_AT_0 = Network("stereo_only_0", ABLATIONS[1].overrides, {"stereo_only_0": "stereo"})
UNTRAINED = (TRUNK_AT_0, STEREO_ONLY_AT_0)


def run_fusion_bench(work_dir: Path, *, seeds: int = 1, steps: int = DEFAULT_STEPS, ablations: bool = False,
                     split: str | None = None, mono: str = "realistic", workers: int = 1,
                     pretrained: Path | None = None, stereo_only_pretrained: Path | None = None,
                     overrides: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Prepare (or reuse) the data in ``work_dir``, train per seed the fusion network (and, with
    ``ablations``, the no-VLM and stereo-only ones) — ``lite`` with ``overrides`` on every network, each
    fine-tuned from the trunk file ``pretrained`` when one is given (the stereo-only one from
    ``stereo_only_pretrained``, a trunk that never read the mono, when given), each reused when the
    workspace has trained it already —, ``workers`` trainings at a time, and score every method on the held-out pairs
    of ``split`` and ``mono`` (:func:`held_out_seeds`; which pairs are scored changes no network's key).
    Returns per method and region the mean (and spread over seeds) of EPE and bad-2, every seed's
    figures, fusion's paired differences against every other method, the conditions (mirror fooling,
    aligned mono error) of training and of the pairs, the disparity ranges, and the timings (seconds; a
    network's training time is its job's, from start to end)."""
    overrides = dict(overrides or {})
    check_overrides(overrides, (FUSION, *ABLATIONS) if ablations else (FUSION,))
    started = time.perf_counter()
    trunk = load_trunk(pretrained) if pretrained is not None else None
    stereo_only_trunk = load_stereo_only_trunk(stereo_only_pretrained, ablations)
    rt, cached, train_conditions = prepared_workspace(work_dir / "workspace")
    prepare_s = time.perf_counter() - started
    train_range = training_disparity_range(rt)
    pairs, render_s, info = _held_out(split, mono)
    networks = (FUSION, *ABLATIONS) if ablations else (FUSION,)
    untrained = (*((TRUNK_AT_0,) if trunk else ()), *((STEREO_ONLY_AT_0,) if stereo_only_trunk else ()))
    # Taken before anything trains: the code that trains is the checkout's now, whatever lands meanwhile.
    provenance = provenance_block("lite", {n.name: network_overrides(n, steps, overrides)
                                           for n in (*networks, *untrained)})
    trunks = {n.name: stereo_only_trunk if stereo_only_trunk and n.overrides == ABLATIONS[1].overrides else trunk
              for n in (*networks, *untrained)}
    timed = time.perf_counter()
    baseline_scores = score_frames(pairs, build_methods(list(BASELINES), checkpoint=None, predictions=None,
                                                        mono_dir=None), oracles=["sgbm"])
    baselines = baseline_scores.means()
    baselines_s = time.perf_counter() - timed
    train_seeds = training_seeds(seeds)
    inits, init_report = _inits(rt, trunks, (*networks, *untrained), train_seeds, steps, overrides)
    ledger, fingerprint = rt.settings.home / TRAINED, model_fingerprint()
    launched: dict[tuple[int, str], int] = {}
    reused: list[int] = []
    for k, seed in enumerate(train_seeds):
        for network in networks:
            config = network_overrides(network, steps, overrides)
            key = network_key(config, seed, trunks[network.name], fingerprint)
            run_id = finished_run(rt, ledger, key)
            if run_id is None:
                run_id = launch_run(rt, seed, config, init=inits.get((k, network.name)))
                record_run(ledger, key, run_id)
            else:
                reused.append(run_id)
            launched[k, network.name] = run_id
    timed = time.perf_counter()
    run_jobs(rt, workers, launched.values())
    train_wall_s = time.perf_counter() - timed
    scored = (*networks, *untrained)
    runs = [_seed_scores(rt, k, pairs, scored, launched, inits) for k in range(seeds)]
    rt.close()
    record = held_out_record(pairs, [r["scores"] for r in runs], baseline_scores)
    return {
        "protocol": PROTOCOL,
        "provenance": provenance,
        "methods": {**_aggregate([r["methods"] for r in runs]), **_aggregate([baselines])},
        "paired": paired_differences([{**r["methods"], **baselines} for r in runs], "fusion"),
        "intervals": intervals(record, "fusion"),
        "per_frame": record,
        "per_seed": [{"seed": k, "train_seed": seed, "runs": runs[k]["runs"], "methods": _rounded(runs[k]["methods"])}
                     for k, seed in enumerate(train_seeds)],
        "seeds": seeds, "split_seed": SPLIT_SEED, "train_seeds": train_seeds, "steps": steps, "preset": "lite",
        "overrides": overrides, "size": f"{SIZE[0]}x{SIZE[1]}", "workers": workers, "reused_runs": reused,
        "networks": {n.name: {"overrides": dict(n.overrides), "methods": list(n.methods), "trained": n not in UNTRAINED}
                     for n in scored},
        "pretrained": None if trunk is None else {"file": trunk.name, "sha256": trunk.sha256, "recipe": trunk.recipe,
                                                  "init": init_report},
        "stereo_only_pretrained": None if stereo_only_trunk is None else {
            "file": stereo_only_trunk.name, "sha256": stereo_only_trunk.sha256, "recipe": stereo_only_trunk.recipe},
        "conditions": {"training": train_conditions, "held_out": condition_ranges(condition_values(pairs))},
        "train_disparity_px": train_range, "pairs": info, "prepare_cached": cached,
        "timings_s": {"prepare": round(prepare_s, 1), "render_pairs": round(render_s, 1),
                      "score_baselines": round(baselines_s, 1),
                      "train": {n.name: [r["train_s"][n.name] for r in runs] for n in networks},
                      "train_wall": round(train_wall_s, 1),
                      "score": {n.name: [r["score_s"][n.name] for r in runs] for n in scored},
                      "total": round(time.perf_counter() - started, 1)},
    }


def load_stereo_only_trunk(path: Path | None, ablations: bool) -> Trunk | None:
    """The stereo-only network's own trunk at ``path`` (None: it starts from the others' trunk); ValueError
    when it was pre-trained with the mono input or nothing trains the stereo-only network."""
    if path is None:
        return None
    if not ablations:
        raise ValueError("a stereo-only trunk starts the stereo-only network, which only --ablations trains")
    trunk = load_trunk(path)
    if trunk_network(trunk) is not ABLATIONS[1]:
        raise ValueError(f"{path.name} was pre-trained with the mono input: the stereo-only network's trunk "
                         "comes from `bench pretrain --stereo-only`")
    return trunk


def _inits(rt: Runtime, trunks: Mapping[str, Trunk | None], networks: tuple[Network, ...], train_seeds: list[int],
           steps: int, overrides: Mapping[str, Any]) -> tuple[dict[tuple[int, str], Path], dict[str, Any]]:
    """Per (seed index, network) the init checkpoint composed from the network's trunk in ``trunks`` (none
    without one), and per network what it loaded from it and what started fresh (the same names for
    every seed)."""
    paths: dict[tuple[int, str], Path] = {}
    report: dict[str, Any] = {}
    for network in networks:
        trunk = trunks[network.name]
        if trunk is None:
            continue
        config = load_preset("lite", network_overrides(network, steps, overrides))
        name = hashlib.sha256(json.dumps(config.to_dict(), sort_keys=True).encode()).hexdigest()[:12]
        for k, seed in enumerate(train_seeds):
            path = rt.settings.home / "inits" / f"{network.name}-{name}-seed{seed}-{trunk.sha256[:12]}.pt"
            report[network.name] = compose_init(trunk, config, seed, path)
            paths[k, network.name] = path
    return paths, report


def held_out_seeds(split: str | None, mono: str) -> tuple[int, ...]:
    """The seeds of the held-out pairs with monocular input ``mono`` (MONO_FAMILIES): the realistic
    one's pairs of ``split`` (SPLITS; None: test), the warp one's CORRUPTION_SEEDS, which take no split.
    ValueError naming what does not fit."""
    if mono not in MONO_FAMILIES:
        raise ValueError(f"unknown mono {mono!r}; choose {' or '.join(MONO_FAMILIES)}")
    if mono == "warp":
        if split is not None:
            raise ValueError("the warp mono's pairs have seeds of their own (CORRUPTION_SEEDS): no split")
        return CORRUPTION_SEEDS
    if (split or "test") not in SPLITS:
        raise ValueError(f"unknown split {split!r}; choose {' or '.join(SPLITS)}")
    return SPLITS[split or "test"]


def _held_out(split: str | None, mono: str = "realistic") -> tuple[list[StereoSample], float, dict[str, Any]]:
    """The pairs of ``split`` and ``mono`` (:func:`held_out_seeds`), the seconds rendering them took, and
    what describes them (``split`` None with the warp mono)."""
    seeds = held_out_seeds(split, mono)
    started = time.perf_counter()
    pairs = held_out_samples(seeds, mono=mono)
    values = np.concatenate([s.disparity[np.isfinite(s.disparity)] for s in pairs])
    info = {"split": (split or "test") if mono == "realistic" else None, "mono": mono, "seeds": list(seeds),
            "samples": len(pairs), "disparity_px": _range(values), "baseline_m": HELD_OUT_BASELINE_M,
            "sha256": pairs_digest(pairs)}
    return pairs, time.perf_counter() - started, info


def held_out_samples(seeds: Iterable[int], frames: int = HELD_OUT_FRAMES, *, mono: str = "realistic") -> list[StereoSample]:
    """The held-out rendered pairs: ``frames`` of each seed, at SIZE and HELD_OUT_BASELINE_M, with the
    monocular input ``mono`` (see :func:`video_samples`). Nothing of the training data enters them."""
    return [sample for seed in seeds
            for sample in video_samples(render_video(seed, frames, *SIZE, baseline_m=HELD_OUT_BASELINE_M,
                                                     families=SCENE_FAMILIES), mono)]


def video_samples(video: SyntheticVideo, mono: str = "realistic") -> list[StereoSample]:
    """A rendered video's frames as samples: regions all / illusion / picture / mirror / non_illusion; mono = the
    realistic monocular disparity, or with ``mono="warp"`` the frame's :func:`warped_mono`; meta ``seed``
    and ``mirror_fooling_px`` (frames with mirror pixels)."""
    samples = []
    for frame in video.frames:
        sample = frame_sample(video.name, video.seed, frame, mono=None if mono == "realistic"
                              else warped_mono(frame.mono_ideal, video.seed, frame.index))
        mirror = sample.regions.get("mirror", np.zeros(frame.disparity.shape, bool))
        if mirror.any():  # how far a matcher that finds the reflection is from the glass: what a mirror does to stereo
            sample.meta["mirror_fooling_px"] = float(np.mean(np.abs(frame.stereo_disparity[mirror] - frame.disparity[mirror])))
        samples.append(sample)
    return samples


def pairs_digest(samples: Iterable[StereoSample]) -> str:
    """sha256 over every sample's name, images, ground truth and mono input: equal digests, identical pairs."""
    digest = hashlib.sha256()
    for sample in samples:
        digest.update(sample.name.encode())
        for array in (sample.left, sample.right, sample.disparity, sample.mono):
            digest.update(np.ascontiguousarray(array).tobytes())
    return digest.hexdigest()


def capture_video(seed: int, frames: int, families: bool = SCENE_FAMILIES, truth: Truth = "surface") -> SyntheticVideo:
    """Capture video ``seed`` as the benchmark (and its pre-training) imports it: ``frames`` frames at SIZE
    and its :func:`capture_baseline`; ``truth`` (see TRUTHS) the disparity it carries as ground truth."""
    video = render_video(seed, frames, *SIZE, baseline_m=capture_baseline(seed), families=families)
    if truth == "matcher":
        video = replace(video, frames=[replace(frame, disparity=frame.stereo_disparity) for frame in video.frames])
    return video


def capture_baseline(seed: int) -> float:
    """The stereo baseline (m) capture video ``seed`` is rendered at: log-uniform over TRAIN_BASELINE_M."""
    rng = np.random.default_rng([_BASELINE_STREAM, seed])
    return float(np.exp(rng.uniform(*np.log(TRAIN_BASELINE_M))))


def condition_values(samples: Iterable[StereoSample]) -> dict[str, list[float]]:
    """Per sample, what the network meets: how far mirrors fool stereo (``mirror_fooling_px`` of the
    samples that record it) and mono-gt-align's EPE on non-illusion pixels (the monocular input's
    error once the affine is undone)."""
    align = build_methods(["mono_gt_align"], checkpoint=None, predictions=None, mono_dir=None)["mono_gt_align"]
    options = EvalOptions(regions=("non_illusion",))
    values: dict[str, list[float]] = {"mirror_fooling_px": [], "aligned_mono_epe_px": []}
    for sample in samples:
        if "mirror_fooling_px" in sample.meta:
            values["mirror_fooling_px"].append(float(sample.meta["mirror_fooling_px"]))
        values["aligned_mono_epe_px"].append(sample_metrics(align(sample), sample, options)["non_illusion"]["epe"])
    return values


def condition_ranges(values: Mapping[str, list[float]]) -> dict[str, dict[str, float]]:
    """Each list of :func:`condition_values` as its count (``frames``), min, median and max."""
    return {key: {"frames": len(v), **({"min": round(min(v), 3), "median": round(statistics.median(v), 3),
                                        "max": round(max(v), 3)} if v else {})}
            for key, v in values.items()}


def redrawn_mono(disparity: np.ndarray, source: np.ndarray, scale: float, masks: Mapping[str, np.ndarray],
                 seed: int, index: int) -> np.ndarray:
    """A generated sample's monocular input drawn independently of its ground truth: the realistic
    estimator of ``dataset.synthetic.mono`` for video ``GENERATED_MONO_SEED + seed`` (another draw than
    the one ``source``, the map its ground truth ``disparity`` was made from, came from), applied to
    the sample's scene — ``disparity`` as the truth, ``scale``·``source`` (the depicted scene in
    pictures, the partly reflected one in mirrors) as what a monocular network is fooled into. ``masks``:
    the illusion masks by kind (picture, mirror). Frame ``index``'s affine is drawn too."""
    shape = disparity.shape
    picture, mirror = (np.asarray(masks.get(kind, np.zeros(shape, bool)), bool) for kind in ("picture", "mirror"))
    model_seed = GENERATED_MONO_SEED + seed
    mono, _affine = realistic_mono(sample_mono_model(model_seed, SCENE_FAMILIES), model_seed, index, _positive(disparity),
                                   _positive(scale * np.asarray(source, np.float64)), picture, mirror)
    return mono


def _positive(disparity: np.ndarray) -> np.ndarray:
    """The estimator's maps must be > 0 px: a plane fitted past the horizon is held at its smallest
    positive disparity (it is far; the estimator blurs it anyway)."""
    disparity = np.asarray(disparity, np.float64)
    good = np.isfinite(disparity) & (disparity > 0)
    return np.where(good, disparity, disparity[good].min())


def redraw_generated_mono(session: Session, media: MediaStore) -> int:
    """Replace the monocular input of every generated (not yet accepted) sample by :func:`redrawn_mono`;
    the ground truth stays. Illusion kinds come from the synthetic video's own pairs. Returns the count."""
    samples = session.scalars(select(Sample).where(Sample.state == SampleState.generated).order_by(Sample.id)).all()
    for sample in samples:
        frame = session.get(Frame, sample.frame_id)
        video = session.get(Video, frame.video_id)
        kinds = {mask_name("illusion", pair["pair"]): pair["kind"] for pair in video.meta["pairs"]}
        masks = {kinds[name]: load_output(media, key, "mask") for name, key in sample.files["masks"].items()
                 if name in kinds}
        mono = redrawn_mono(load_output(media, sample.files["disparity"], "disparity"),
                            load_output(media, sample.files["disparity_mono"], "disparity_mono"),
                            float(sample.params["scale"]), masks, int(video.meta["seed"]), frame.index)
        sample.files = {**sample.files, **store_outputs(media, {"disparity_mono": mono})}
        sample.provenance = {**sample.provenance, "mono_input": f"independent draw: dataset.synthetic.mono estimator "
                                                                f"{GENERATED_MONO_SEED + int(video.meta['seed'])}"}
    return len(samples)


def bench_workspace(home: Path, recipe: Mapping[str, Any]) -> tuple[Runtime, dict[str, Any] | None]:
    """The workspace in ``home`` and, when it was prepared with ``recipe``, the conditions stored with it
    (None: still to prepare). A workspace prepared with another recipe, or whose preparation did not
    finish, is refused rather than added to: its data would mix with the recipe's."""
    marker = home / PREPARED
    stored = json.loads(marker.read_text()) if marker.is_file() else None
    if stored is not None and stored.get("recipe") != json.loads(json.dumps(recipe)):
        was = (stored.get("recipe") or {}).get("protocol", 1)
        raise RuntimeError(f"{home} was prepared with another recipe (protocol {was}, now {recipe.get('protocol')}): "
                           "remove it, or pass another --work-dir")
    if stored is None and home.is_dir() and any(home.iterdir()):
        raise RuntimeError(f"{home} holds an unfinished preparation: remove it, or pass another --work-dir")
    rt = Runtime(init_workspace(home))
    if stored is not None:
        return rt, stored["conditions"]
    with transaction(rt.sessions) as s:
        for role in Role:
            if s.scalar(select(User).where(User.name == f"bench-{role.value}")) is None:
                user_service.create_user(s, f"bench-{role.value}", role, f"bench-{role.value}-password")
    return rt, None


def finish_workspace(home: Path, recipe: Mapping[str, Any], conditions: dict[str, Any]) -> dict[str, Any]:
    """Mark the workspace in ``home`` prepared with ``recipe``; returns ``conditions``, stored beside it."""
    (home / PREPARED).write_text(json.dumps({"recipe": recipe, "conditions": conditions}))
    return conditions


def prepared_workspace(home: Path) -> tuple[Runtime, bool, dict[str, Any]]:
    """The benchmark's workspace: every synthetic frame generated (its mono input redrawn) and accepted,
    and the rendered captures imported and accepted; whether it was cached, and the conditions its
    generated samples and captures show (:func:`condition_ranges`). Built once."""
    recipe = {"protocol": PROTOCOL, "size": SIZE, "frames": FRAMES, "generated": GENERATED_VIDEOS,
              "rendered": RENDERED_SEEDS, "synthetic": SYNTHETIC_FORMAT, "capture_baselines_m": TRAIN_BASELINE_M,
              "generated_mono_seed": GENERATED_MONO_SEED, "families": SCENE_FAMILIES}
    rt, conditions = bench_workspace(home, recipe)
    if conditions is not None:
        return rt, True, conditions
    videos = write_synthetic_dataset(home / "synthetic", videos=GENERATED_VIDEOS, seed=0, n_frames=FRAMES,
                                     width=SIZE[0], height=SIZE[1], families=SCENE_FAMILIES)
    with transaction(rt.sessions) as s:
        for path in videos:
            rt.submit(s, "ingest", ingest_params(str(path), dedup_hamming=None, prefilter=True), None)
    run_jobs(rt)
    with transaction(rt.sessions) as s:
        curator, annotator = (s.scalar(select(User).where(User.name == f"bench-{role}")) for role in ("curator", "annotator"))
        # Every frame joins, whatever the prefilter said: the benchmark measures the model, not the filter.
        for frame_id in s.scalars(select(Frame.id).where(Frame.state.in_((FrameState.prefiltered, FrameState.rejected)))):
            review_frame(s, frame_id, curator, "approve")
        for frame_id in seed_reviews_and_annotations(s, rt.media, curator, annotator, approve=FRAMES, annotate=FRAMES):
            pipeline.submitted(s, rt.submit, pipeline.GenerateParams(frame_id), annotator)
    run_jobs(rt)
    with transaction(rt.sessions) as s:
        redraw_generated_mono(s, rt.media)
        accept_generated_samples(s, s.scalar(select(User).where(User.name == "bench-curator")))
    with rt.sessions() as s:
        generated = pin_dataset_version(s, rt.media, kinds=["synthesized"])
    reader = VersionReader(generated, rt.settings.media_root)
    conditions = {"generated": condition_ranges(condition_values(reader[i] for i in range(len(reader)))),
                  "captures": import_captures(rt, RENDERED_SEEDS, FRAMES)}
    return rt, False, finish_workspace(home, recipe, conditions)


def import_captures(rt: Runtime, seeds: Iterable[int], frames: int, truth: Truth = "surface") -> dict[str, Any]:
    """Render ``frames`` frames of each seed at its :func:`capture_baseline`, import them as captures (with
    ``truth`` as their ground truth) and accept them (one transaction per video); the conditions they show
    (:func:`condition_ranges`)."""
    values: dict[str, list[float]] = {"mirror_fooling_px": [], "aligned_mono_epe_px": []}
    for seed in seeds:
        video = capture_video(seed, frames, truth=truth)
        with transaction(rt.sessions) as s:
            curator = s.scalar(select(User).where(User.name == "bench-curator"))
            for sample_id in import_rendered_video(s, rt.media, video):
                review_sample(s, sample_id, curator, "accept")
        for key, found in condition_values(video_samples(video)).items():
            values[key] += found
    return condition_ranges(values)


def run_jobs(rt: Runtime, workers: int = 1, runs: Iterable[int] | None = None) -> None:
    """The queued jobs of the workspace — with ``runs``, only those training runs' (another benchmark
    on the same work dir keeps its own) — ``workers`` at a time; RuntimeError naming those that failed."""
    only = None
    if runs is not None:
        with rt.sessions() as s:
            only = set(s.scalars(select(TrainingRun.job_id).where(TrainingRun.id.in_(list(runs)))))
    ran = job_service.run_queued_jobs(HANDLERS, rt, workers=workers, only=only)
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


def training_seeds(count: int) -> list[int]:
    """The launch seeds of the benchmark's ``count`` seeds: 0, 1, … Every one trains on SPLIT_SEED's split
    (:func:`launch_run`), so a seed changes the initialisation, the order and the augmentation only."""
    return list(range(count))


def run_mono_bench(*, split: str | None = None, mono: str = "realistic", work_dir: Path | None = None,
                   pretrained: Path | None = None) -> dict[str, Any]:
    """No training: mono-gt-align on the held-out pairs of ``split`` and ``mono`` (:func:`held_out_seeds`) —
    EPE and bad-2 per region, the non-illusion bad-2 (the monocular model's calibration figure) on top — and
    the oracle gate's headroom per region (per pixel the better of a stereo map and the aligned mono,
    against the stereo map alone, with its interval over scenes) for SGBM and, given the trunk file
    ``pretrained``, for the trunk's stereo branch at 0 steps (its init written under ``work_dir``). A gate
    can only learn what the oracle gains: ``headroom_ok`` says whether it is at least HEADROOM_PX inside
    illusions for the stereo map the networks start from (the trunk's, else SGBM's)."""
    started = time.perf_counter()
    pairs, _render_s, info = _held_out(split, mono)
    methods = build_methods(["mono_gt_align", *BASELINES[1:]], checkpoint=None, predictions=None, mono_dir=None)
    trunk = load_trunk(pretrained) if pretrained is not None else None
    if trunk is not None:
        config = load_preset("lite", network_overrides(trunk_network(trunk), FINETUNE_STEPS))
        init = (work_dir or Path(".")) / "inits" / f"trunk_0-{trunk.sha256[:12]}.pt"
        compose_init(trunk, config, SPLIT_SEED, init)
        methods["trunk_0_stereo"] = build_methods(["stereo"], checkpoint=init, predictions=None, mono_dir=None)["stereo"]
    stereos = ["sgbm", *(["trunk_0_stereo"] if trunk is not None else [])]
    scores = score_frames(pairs, methods, oracles=stereos)
    figures = {m: {r: {k: round(v, 3) for k, v in f.items()} for r, f in regions.items()}
               for m, regions in scores.means().items()}
    oracle = intervals(held_out_record(pairs, [], scores), "mono_gt_align")["oracle"]
    inside = oracle[stereos[-1]]["illusion"]["value"]
    return {"non_illusion_bad2": figures["mono_gt_align"]["non_illusion"]["bad2"], "methods": figures,
            "oracle_headroom_px": oracle, "headroom_ok": {"stereo": stereos[-1], "illusion_px": round(inside, 3),
                                                          "needed_px": HEADROOM_PX, "ok": inside >= HEADROOM_PX},
            "size": f"{SIZE[0]}x{SIZE[1]}", "pairs": info, "provenance": {"commit": source_commit()},
            "pretrained": None if trunk is None else {"file": trunk.name, "sha256": trunk.sha256},
            "conditions": {"held_out": condition_ranges(condition_values(pairs))},
            "seconds": round(time.perf_counter() - started, 1)}


def trunk_network(trunk: Trunk) -> Network:
    """The network a trunk is scored as at 0 steps: the stereo-only one for a trunk pre-trained without the
    mono input (``bench pretrain --stereo-only``), else TRUNK_AT_0 (the no-VLM network)."""
    if trunk.recipe.get("overrides", {}).get("model.use_mono") is False:
        return ABLATIONS[1]
    return TRUNK_AT_0


def mono_figures(samples: list[StereoSample]) -> dict[str, dict[str, float]]:
    """mono-gt-align's EPE (px) and bad-2 (%) per region of REGIONS, mean over ``samples``."""
    figures = _score(samples, build_methods(["mono_gt_align"], checkpoint=None, predictions=None, mono_dir=None))
    return {r: {k: round(v, 3) for k, v in f.items()} for r, f in figures["mono_gt_align"].items()}


def _seed_scores(rt: Runtime, k: int, pairs: list[StereoSample], networks: tuple[Network, ...],
                 launched: Mapping[tuple[int, str], int], inits: Mapping[tuple[int, str], Path]) -> dict[str, Any]:
    """Each of ``networks`` of benchmark seed ``k`` scored on ``pairs`` frame by frame (one pass): its
    trained best checkpoint (its run id in ``launched``), or for the UNTRAINED its init checkpoint in
    ``inits``, untrained. Returns the FrameScores (each fusion method's gate over its own stereo branch,
    each stereo branch's oracle), the mean figures by report key, and per network its run id (trained
    ones), the seconds its training and its scoring took."""
    methods: dict[str, Predict] = {}
    runs: dict[str, int] = {}
    train_s: dict[str, float] = {}
    for network in networks:
        if network in UNTRAINED:
            checkpoint, seconds = inits[k, network.name], 0.0
        else:
            run_id = launched[k, network.name]
            checkpoint, seconds = trained_checkpoint(rt, run_id)
            runs[network.name] = run_id
        train_s[network.name] = round(seconds, 1)
        built = build_methods(sorted(set(network.methods.values())), checkpoint=checkpoint, predictions=None,
                              mono_dir=None)
        methods.update({key: built[method] for key, method in network.methods.items()})
    gates = {fused: stereo for network in networks for fused, stereo in _gate_of(network)}
    stereos = [key for network in networks for key, method in network.methods.items() if method == "stereo"]
    scores = score_frames(pairs, methods, gates=gates, oracles=stereos)
    score_s = {network.name: round(sum(scores.seconds[key] for key in network.methods), 1) for network in networks}
    return {"scores": scores, "methods": scores.means(), "runs": runs, "train_s": train_s, "score_s": score_s}


def _gate_of(network: Network) -> list[tuple[str, str]]:
    """(fused report key, its own stereo branch's report key) of a network that fuses; none otherwise."""
    fused = [key for key, method in network.methods.items() if method == "fusion"]
    stereo = [key for key, method in network.methods.items() if method == "stereo"]
    return list(zip(fused, stereo, strict=True)) if fused and stereo else []


def held_out_record(pairs: list[StereoSample], per_seed: list[FrameScores], baselines: FrameScores) -> dict[str, Any]:
    """The per-frame record of a benchmark (JSON): the frames (sample name, scene seed), each region's
    pixel count per frame, per method and region each seed's per-frame EPE and bad-2 (the untrained
    baselines: one row), and per gate its per-frame sums (``fusion_stats.gate_sums``), likewise."""
    def rows(values: list[float]) -> list[float | None]:
        return [None if not np.isfinite(v) else round(float(v), 4) for v in values]

    runs = [r for r in ([*per_seed], [baselines]) if r]
    methods: dict[str, Any] = {}
    for scores_of_seeds in runs:
        for method in scores_of_seeds[0].figures:
            methods[method] = {r: {k: [rows(s.figures[method][r][k]) for s in scores_of_seeds] for k in ("epe", "bad2")}
                               for r in REGIONS}
    gates: dict[str, Any] = {}
    for scores_of_seeds in runs:
        for gate in scores_of_seeds[0].gates:
            gates[gate] = {r: {k: [rows(s.gates[gate][r][k]) for s in scores_of_seeds]
                               for k in scores_of_seeds[0].gates[gate][r]} for r in REGIONS}
    return {"frames": [{"sample": p.name, "scene": int(p.meta["seed"])} for p in pairs],
            "pixels": baselines.pixels, "methods": methods, "gates": gates}


def _seed_rows(record: Mapping[str, Any], method: str, region: str, key: str, seeds: int) -> np.ndarray:
    """(seeds, frames) of a method's per-frame ``key`` in ``region`` (a baseline's one row repeated)."""
    values = np.array(record["methods"][method][region][key], dtype=np.float64)
    return np.repeat(values, seeds, axis=0) if len(values) == 1 else values


def intervals(record: Mapping[str, Any], reference: str) -> dict[str, Any]:
    """From a :func:`held_out_record`, 95 % intervals over scenes and seeds (``fusion_stats``):
    ``methods`` each method's EPE and bad-2 per region; ``against`` ``reference`` minus every other method,
    per region, with ``decided`` (lower / higher / undecided); ``isolation`` each fused method minus its own
    stereo branch; ``oracle`` per stereo method its oracle gate's headroom (its EPE minus the oracle's,
    px); ``capture`` per gate the share of its stereo branch's oracle headroom it takes,
    Σ(e_stereo - e_fused) / Σ max(0, e_stereo - e_mono)."""
    scenes = [f["scene"] for f in record["frames"]]
    seeds = max(len(v["all"]["epe"]) for v in record["methods"].values())

    def rows(method: str, region: str, key: str) -> np.ndarray:
        return _seed_rows(record, method, region, key, seeds)

    def difference(a: str, b: str, region: str, key: str) -> dict[str, Any]:
        found = stats.mean_interval(rows(a, region, key) - rows(b, region, key), scenes)
        return {**stats.rounded(found), "decided": stats.decided(found)}

    methods = list(record["methods"])
    pairs = {fused: stereo for fused, stereo in _gates_in(record)}
    out: dict[str, Any] = {
        "level": stats.LEVEL, "replicates": stats.REPLICATES, "scenes": len(set(scenes)), "seeds": seeds,
        "methods": {m: {r: {k: stats.rounded(stats.mean_interval(rows(m, r, k), scenes)) for k in ("epe", "bad2")}
                        for r in REGIONS} for m in methods},
        "against": {m: {r: {k: difference(reference, m, r, k) for k in ("epe", "bad2")} for r in REGIONS}
                    for m in methods if m != reference and reference in methods},
        "isolation": {f"{fused} - {stereo}": {r: {"epe": difference(fused, stereo, r, "epe")} for r in REGIONS}
                      for fused, stereo in pairs.items()},
        "oracle": {}, "capture": {}}
    pixels = np.array([record["pixels"][r] for r in REGIONS], dtype=np.float64)
    for gate, regions in record["gates"].items():
        for region_index, region in enumerate(REGIONS):
            sums = {k: np.repeat(np.array(v, np.float64), seeds, axis=0) if len(v) == 1 else np.array(v, np.float64)
                    for k, v in regions[region].items()}
            if gate.startswith("oracle:"):
                stereo = gate.partition(":")[2]
                per_pixel = np.where(pixels[region_index] > 0, pixels[region_index], np.nan)
                headroom = rows(stereo, region, "epe") - sums["oracle"] / per_pixel
                out["oracle"].setdefault(stereo, {})[region] = stats.rounded(stats.mean_interval(headroom, scenes))
            else:
                out["capture"].setdefault(gate, {})[region] = stats.rounded(
                    stats.bootstrap_ratio(sums["gain"], sums["headroom"], scenes))
    return out


def _gates_in(record: Mapping[str, Any]) -> list[tuple[str, str]]:
    """(fused, stereo) of every gate of a record: the networks' report keys (``FUSION`` and ABLATIONS'
    and TRUNK_AT_0's) whose fused method has a gate."""
    keys = [k for k in record["gates"] if not k.startswith("oracle:")]
    return [(fused, stereo) for network in (FUSION, *ABLATIONS, TRUNK_AT_0) for fused, stereo in _gate_of(network)
            if fused in keys]


def network_overrides(network: Network, steps: int, overrides: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The overrides of ``lite`` that ``network`` is trained with for ``steps`` steps, the benchmark's
    ``overrides`` on top of TRAIN_OVERRIDES (the network's own win: an ablation stays one)."""
    return {**TRAIN_OVERRIDES, "train.steps": steps, **(overrides or {}), **network.overrides}


# What the benchmark itself sets on every run: `--steps` and the launch seeds (TRAIN_OVERRIDES too).
OWNED_KEYS = ("steps", "seed")


def check_overrides(overrides: Mapping[str, Any], networks: Iterable[Network]) -> None:
    """ValueError naming the first of ``overrides`` that the benchmark sets itself (OWNED_KEYS) or that
    does not fit ``lite`` as one of ``networks`` trains it."""
    for key in overrides:
        if key.rpartition(".")[2] in OWNED_KEYS:
            raise ValueError(f"{key} is the benchmark's own (--steps, --seeds): it cannot be overridden")
    for network in networks:
        try:
            load_preset("lite", network_overrides(network, DEFAULT_STEPS, overrides))
        except ValueError as exc:
            raise ValueError(f"the {network.name} network: {exc}") from None


def model_fingerprint() -> str:
    """sha256 over the ``model`` package's source files (names and bytes): what a trained network's
    behaviour depends on besides its config (which :func:`network_key` holds resolved, so a preset
    file's edit matters only where it changes the config), seed and starting weights."""
    root = Path(model.__file__).parent
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        digest.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()


# Config fields (by prefix) of what a network does not build: without the VLM (model.use_vlm off) its
# VLM and flow; stereo only (model.use_mono off) also its confidence and fusion, and their losses.
UNBUILT_FIELDS: dict[str, dict[str, tuple[str, ...]]] = {
    "use_vlm": {"model": ("vlm_", "lora_", "flow_")},
    "use_mono": {"model": ("vlm_", "lora_", "flow_", "confidence_", "fusion_"),
                 "train": ("focal_", "confidence_", "ce_weight")}}


def network_key(overrides: Mapping[str, Any], seed: int, trunk: Trunk | None, fingerprint: str) -> str:
    """What makes a benchmark network, hashed: ``lite``'s resolved config under ``overrides`` (less the
    fields of what it does not build, UNBUILT_FIELDS), the launch seed, the trunk it starts from and the
    model code's :func:`model_fingerprint`."""
    config = load_preset("lite", overrides).to_dict()
    for switch, unbuilt in UNBUILT_FIELDS.items():
        if not config["model"][switch]:
            config = {**config, **{section: {k: v for k, v in config[section].items() if not k.startswith(prefixes)}
                                   for section, prefixes in unbuilt.items()}}
    made = {"config": config, "seed": seed, "trunk": None if trunk is None else trunk.sha256, "model": fingerprint}
    return hashlib.sha256(json.dumps(made, sort_keys=True).encode()).hexdigest()


def finished_run(rt: Runtime, ledger: Path, key: str) -> int | None:
    """The run the workspace's ``ledger`` (TRAINED) holds for ``key`` when it succeeded with its best
    checkpoint, or is still queued (a benchmark stopped before it ran: this one runs it); None: the
    network is still to train (never launched, or its run failed or was cut off while running)."""
    runs = json.loads(ledger.read_text()) if ledger.is_file() else {}
    run_id = runs.get(key)
    if run_id is None:
        return None
    with rt.sessions() as s:
        run = s.get(TrainingRun, run_id)
        state = None if run is None else run.state
    if state == RunState.queued or (state == RunState.succeeded and trained_checkpoint_path(rt, run_id).is_file()):
        return run_id
    return None


def record_run(ledger: Path, key: str, run_id: int) -> None:
    """Add ``key`` → ``run_id`` to the workspace's ``ledger`` (atomically)."""
    runs = json.loads(ledger.read_text()) if ledger.is_file() else {}
    atomic_write_bytes(ledger, (json.dumps({**runs, key: run_id}, indent=1) + "\n").encode())


def launch_run(rt: Runtime, seed: int, overrides: Mapping[str, Any], *, split: str = SPLIT,
               init: Path | None = None) -> int:
    """Queue a ``lite`` training with ``overrides`` and launch ``seed`` over every accepted sample, split by
    video in the shares of ``split`` as SPLIT_SEED deals them (whatever ``seed``), starting from the
    checkpoint ``init`` if given, through the product's training job: its run id."""
    with transaction(rt.sessions) as s:
        admin = s.scalar(select(User).where(User.name == "bench-admin"))
        run = run_control.launch(
            rt, s, preset="lite", overrides=dict(overrides), selection=training.DataSelection(),
            launch=training.Launch(split=training.parse_split(split), seed=seed, split_seed=SPLIT_SEED,
                                   init_checkpoint=None if init is None else str(init),
                                   init_label=None if init is None else init.name), user=admin)
        return run.id


def trained_checkpoint(rt: Runtime, run_id: int) -> tuple[Path, float]:
    """A finished run's best checkpoint and the seconds its training job ran."""
    with rt.sessions() as s:
        job = s.get(Job, s.get(TrainingRun, run_id).job_id)
        seconds = (job.finished_at - job.started_at).total_seconds()
    return trained_checkpoint_path(rt, run_id), seconds


def trained_checkpoint_path(rt: Runtime, run_id: int) -> Path:
    """Where run ``run_id``'s best checkpoint is."""
    return training.run_dir(rt.settings.runs_dir, run_id) / "checkpoints" / "best.pt"


@dataclass
class FrameScores:
    """The per-frame record of scoring ``methods`` on pairs (``fusion_stats``): per method and region each
    frame's ``epe`` (px) and ``bad2`` (%) (NaN: the frame has none of the region); per region each frame's
    pixel count; per gate (a fused method, or ``oracle:<stereo method>``) and region each frame's sums of
    ``fusion_stats.gate_sums``; the seconds each method's predictions took."""

    figures: dict[str, dict[str, dict[str, list[float]]]]
    pixels: dict[str, list[int]]
    gates: dict[str, dict[str, dict[str, list[float]]]]
    seconds: dict[str, float]

    def means(self) -> dict[str, dict[str, dict[str, float]]]:
        """EPE (px) and bad-2 (%) per method and region, mean over the frames holding the region."""
        return {m: {r: {k: float(np.nanmean(v)) for k, v in f.items()} for r, f in regions.items()}
                for m, regions in self.figures.items()}


def score_frames(pairs: list[StereoSample], methods: Mapping[str, Predict], *, gates: Mapping[str, str] | None = None,
                 oracles: Iterable[str] = ()) -> FrameScores:
    """Every method of ``methods`` on every pair, frame by frame and region by region of REGIONS; for each
    ``gates`` entry (fused method → the stereo method it was built on) the gate's sums, and for each stereo
    method of ``oracles`` the oracle gate's against the GT-aligned mono (``fusion_stats.gate_sums``).
    RuntimeError naming the first pair a method cannot predict."""
    gates = dict(gates or {})
    oracles = tuple(oracles)
    align = build_methods(["mono_gt_align"], checkpoint=None, predictions=None, mono_dir=None)["mono_gt_align"]
    figures: dict[str, dict[str, dict[str, list[float]]]] = {m: {r: {"epe": [], "bad2": []} for r in REGIONS}
                                                            for m in methods}
    gate_keys = [*gates, *(f"oracle:{m}" for m in oracles)]
    sums: dict[str, dict[str, dict[str, list[float]]]] = {g: {r: {} for r in REGIONS} for g in gate_keys}
    pixels: dict[str, list[int]] = {r: [] for r in REGIONS}
    seconds = dict.fromkeys(methods, 0.0)
    for sample in pairs:
        errors: dict[str, np.ndarray] = {}
        for name, predict in methods.items():
            started = time.perf_counter()
            try:
                prediction = predict(sample)
            except Exception as exc:  # a benchmark reports which pair broke, then stops
                raise RuntimeError(f"benchmark: {name} failed on {sample.name}: {exc}") from exc
            seconds[name] += time.perf_counter() - started
            errors[name] = stats.frame_errors(prediction, sample.disparity)
        mono_errors = stats.frame_errors(align(sample), sample.disparity) if gate_keys else None
        finite = np.isfinite(sample.disparity)
        for region in REGIONS:
            where = sample.regions.get(region, np.zeros(finite.shape, bool)) & finite
            for name in methods:
                found = stats.region_figures(errors[name], where)
                figures[name][region]["epe"].append(found["epe"])
                figures[name][region]["bad2"].append(found["bad2"])
            pixels[region].append(int(np.count_nonzero(where)))
            for key in gate_keys:
                fused, stereo = (None, key.partition(":")[2]) if key.startswith("oracle:") else (key, gates[key])
                found = stats.gate_sums(errors[stereo], None if fused is None else errors[fused], mono_errors, where)
                for name, value in found.items():
                    sums[key][region].setdefault(name, []).append(value)
    return FrameScores(figures, pixels, sums, {m: round(v, 1) for m, v in seconds.items()})


def _score(pairs: list[StereoSample], methods: dict[str, Predict]) -> dict[str, dict[str, dict[str, float]]]:
    """EPE (px) and bad-2 (%) per method and region of REGIONS, mean over ``pairs``."""
    return score_frames(pairs, methods).means()


def _rounded(figures: dict[str, Any]) -> dict[str, Any]:
    return {m: {r: {k: round(v, 3) for k, v in f.items()} for r, f in regions.items()} for m, regions in figures.items()}


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


def paired_differences(per_seed: list[dict[str, Any]], reference: str) -> dict[str, Any]:
    """Per method other than ``reference``: ``reference`` minus it, seed by seed, per region and figure,
    as the mean and spread over seeds (:func:`_aggregate`; < 0: ``reference`` is better) and in how
    many seeds ``reference`` was lower (``<figure>_lower``)."""
    others = [m for m in per_seed[0] if m != reference]
    differences = [{m: {r: {k: run[reference][r][k] - run[m][r][k] for k in figures} for r, figures in run[reference].items()}
                    for m in others} for run in per_seed]
    out = _aggregate(differences)
    for method, regions in out.items():
        for region, figures in regions.items():
            for key in list(per_seed[0][reference][region]):
                figures[f"{key}_lower"] = sum(run[method][region][key] < 0 for run in differences)
    return {"reference": reference, "seeds": len(per_seed), "against": out}
