"""The fusion benchmark's protocol 2: frozen held-out pairs, a split fixed across seeds, the
paired record, the training data's conditions (capture baselines, an independent mono input), the
pre-training seeds, and the pre-trained trunk that every network is fine-tuned from."""

from __future__ import annotations

import contextlib
import json
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner

torch = pytest.importorskip("torch")

from benchmarks import fusion, pretrain  # noqa: E402
from benchmarks.trunk import compose_init, load_trunk, save_trunk  # noqa: E402
from benchmarks.trunk import trunk_file as trunk_path  # noqa: E402
from dataset.services import training  # noqa: E402
from dataset.synthetic import render_video  # noqa: E402
from dataset.synthetic.corruptions import warped_mono  # noqa: E402
from model.align import align  # noqa: E402
from model.checkpoint import load_network, save_checkpoint  # noqa: E402
from model.network import TRUNK_PREFIXES, FusionNetwork  # noqa: E402
from model.presets import Config, load_preset  # noqa: E402
from model.runs.handlers import resolve_config  # noqa: E402
from webapp.cli import main  # noqa: E402

NETWORKS = (fusion.FUSION, *fusion.ABLATIONS)


class _Workspace:
    def __init__(self, home: Path) -> None:
        self.settings = type("Settings", (), {"home": home})()

    def close(self) -> None:
        pass


def test_held_out_pairs_are_bit_identical_whatever_the_training_workspace_holds(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Two workspaces with other training data (disparity range, conditions): the same pairs, scored
    alike, at the frozen baseline; their hash is the one of the pairs rendered on their own."""
    scored: list[str] = []
    score = fusion.score_frames

    def recording(pairs: list[Any], methods: dict[str, Any], **kw: Any) -> Any:
        scored.append(fusion.pairs_digest(pairs))
        return score(pairs, methods, **kw)

    one_frame = fusion.held_out_samples
    monkeypatch.setattr(fusion, "held_out_samples", lambda seeds, mono: one_frame(seeds[:2], frames=1, mono=mono))
    monkeypatch.setattr(fusion, "launch_run", lambda *_a, **_k: 1)
    monkeypatch.setattr(fusion, "finished_run", lambda *_a: None)  # both workspaces train their own
    monkeypatch.setattr(fusion, "run_jobs", lambda _rt, workers, runs: None)
    monkeypatch.setattr(fusion, "score_frames", recording)
    monkeypatch.setattr(fusion, "_seed_scores", _trained)
    reports = []
    for train_range, fooling in (([3.0, 44.0], 2.1), ([10.0, 90.0], 30.0)):
        conditions = {"mirror_fooling_px": {"frames": 1, "min": fooling, "median": fooling, "max": fooling}}
        monkeypatch.setattr(fusion, "prepared_workspace", lambda home, c=conditions: (_Workspace(home), True, {"captures": c}))
        monkeypatch.setattr(fusion, "training_disparity_range", lambda _rt, r=train_range: r)
        reports.append(fusion.run_fusion_bench(tmp_path, seeds=2, steps=5, split="test"))
    expected = fusion.pairs_digest(one_frame(fusion.TEST_SEEDS[:2], frames=1))
    assert scored == [expected, expected]
    assert [r["pairs"]["sha256"] for r in reports] == [expected, expected]
    assert reports[0]["pairs"] == reports[1]["pairs"] and reports[0]["pairs"]["baseline_m"] == 0.63
    assert reports[0]["conditions"]["held_out"] == reports[1]["conditions"]["held_out"]
    assert reports[0]["train_disparity_px"] != reports[1]["train_disparity_px"]
    assert reports[0]["paired"]["against"]["sgbm"]["all"]["epe_spread"] == pytest.approx(0.5)


def _trained(_rt: Any, k: int, pairs: Any, _networks: Any, launched: Any, _inits: Any) -> dict[str, Any]:
    """Benchmark seed ``k``'s fusion network scored without a network: its figures depend on ``k`` alone."""
    frames = len(pairs)
    figures = {"fusion": {r: {"epe": [1.0 + k] * frames, "bad2": [10.0] * frames} for r in fusion.REGIONS}}
    scores = fusion.FrameScores(figures, {r: [1] * frames for r in fusion.REGIONS}, {}, {"fusion": 1.0})
    return {"scores": scores, "methods": scores.means(), "runs": {"fusion": launched[k, "fusion"]},
            "train_s": {"fusion": 1.0}, "score_s": {"fusion": 1.0}}


def test_warp_pairs_are_the_held_out_render_with_the_warp_mono() -> None:
    """The same render as the realistic mono's pairs (images, truth, regions), the monocular input only
    replaced by the frame's warped_mono of its mono-fooled disparity."""
    seed = fusion.CORRUPTION_SEEDS[0]
    (realistic,), (warp,) = (fusion.held_out_samples((seed,), frames=1, mono=mono) for mono in fusion.MONO_FAMILIES)
    frame = render_video(seed, 1, *fusion.SIZE, baseline_m=fusion.HELD_OUT_BASELINE_M,
                         families=fusion.SCENE_FAMILIES).frames[0]
    assert warp.name == realistic.name and warp.meta == realistic.meta and set(warp.regions) == set(realistic.regions)
    assert all(np.array_equal(getattr(warp, k), getattr(realistic, k)) for k in ("left", "right", "disparity"))
    assert all(np.array_equal(warp.regions[r], realistic.regions[r]) for r in warp.regions)
    assert np.array_equal(warp.mono, warped_mono(frame.mono_ideal, seed, 0)) and not np.allclose(warp.mono, realistic.mono)
    assert fusion.held_out_seeds(None, "warp") == fusion.CORRUPTION_SEEDS
    assert fusion.held_out_seeds(None, "realistic") == fusion.TEST_SEEDS == fusion.held_out_seeds("test", "realistic")
    assert fusion.held_out_seeds("val", "realistic") == fusion.VAL_SEEDS
    for split, mono, message in (("val", "warp", "no split"), (None, "ideal", "unknown mono"),
                                 ("train", "realistic", "unknown split")):
        with pytest.raises(ValueError, match=message):
            fusion.held_out_seeds(split, mono)


def test_warp_seeds_are_held_out_from_training_validation_test_and_pretraining() -> None:
    warp = set(fusion.CORRUPTION_SEEDS)
    others = {*range(fusion.GENERATED_VIDEOS), *fusion.RENDERED_SEEDS, *fusion.TEST_SEEDS, *fusion.VAL_SEEDS}
    assert len(warp) == 100 and not warp & others
    assert warp <= pretrain.benchmark_seeds() and not warp & set(pretrain.pretrain_seeds(50_000))


def test_scoring_the_warp_pairs_after_val_trains_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """`bench fusion --split val`, then `--mono warp` on the same work dir: the second run finds every
    network in the ledger (a network's key holds no held-out set) and scores the warp pairs, recorded as
    such with their own hash."""
    launched: list[int] = []

    def launch(_rt: Any, seed: int, _overrides: Any, *, init: Path | None = None) -> int:
        launched.append(seed)
        return len(launched)

    def workspace(home: Path) -> tuple[_Workspace, bool, dict[str, Any]]:
        home.mkdir(parents=True, exist_ok=True)
        return _Workspace(home), True, {"captures": {}}

    one_frame = fusion.held_out_samples
    monkeypatch.setattr(fusion, "held_out_samples", lambda seeds, mono: one_frame(seeds[:1], frames=1, mono=mono))
    monkeypatch.setattr(fusion, "prepared_workspace", workspace)
    monkeypatch.setattr(fusion, "training_disparity_range", lambda _rt: [3.0, 44.0])
    monkeypatch.setattr(fusion, "launch_run", launch)
    # the ledger's runs all succeeded (no database here)
    monkeypatch.setattr(fusion, "finished_run", lambda _rt, ledger, key: json.loads(ledger.read_text()).get(key)
                        if ledger.is_file() else None)
    monkeypatch.setattr(fusion, "run_jobs", lambda _rt, workers, runs: None)
    monkeypatch.setattr(fusion, "_seed_scores", _trained)
    val, warp = (fusion.run_fusion_bench(tmp_path, seeds=2, steps=5, **kw) for kw in ({"split": "val"}, {"mono": "warp"}))
    assert launched == [0, 1] and val["reused_runs"] == [] and warp["reused_runs"] == [1, 2]
    assert [r["runs"] for r in warp["per_seed"]] == [r["runs"] for r in val["per_seed"]]
    pairs = one_frame(fusion.CORRUPTION_SEEDS[:1], frames=1, mono="warp")
    assert {k: warp["pairs"][k] for k in ("split", "mono", "seeds", "samples", "baseline_m", "sha256")} == {
        "split": None, "mono": "warp", "seeds": list(fusion.CORRUPTION_SEEDS), "samples": 1, "baseline_m": 0.63,
        "sha256": fusion.pairs_digest(pairs)}
    assert val["pairs"]["split"] == "val" and val["pairs"]["mono"] == "realistic"
    epe = fusion.condition_values(pairs)["aligned_mono_epe_px"]
    assert warp["conditions"]["held_out"]["aligned_mono_epe_px"]["median"] == round(epe[0], 3)


def test_every_benchmark_seed_trains_on_the_same_split(monkeypatch: pytest.MonkeyPatch) -> None:
    """Seeds 0, 1, 2 launch with SPLIT_SEED dealing the videos: the seed changes the training, not the split
    (``tests/test_runs.py`` checks that a split seed keeps one split)."""
    launched: list[training.Launch] = []

    class Session:
        def scalar(self, _query: Any) -> None:
            return None

    monkeypatch.setattr(fusion, "transaction", lambda _sessions: contextlib.nullcontext(Session()))
    monkeypatch.setattr(fusion.run_control, "launch",
                        lambda *_a, launch, **_kw: launched.append(launch) or SimpleNamespace(id=len(launched)))
    seeds = fusion.training_seeds(3)
    assert seeds == [0, 1, 2]
    assert [fusion.launch_run(SimpleNamespace(sessions=None), seed, {}) for seed in seeds] == [1, 2, 3]
    assert [(launch.seed, launch.split_seed) for launch in launched] == [(0, 0), (1, 0), (2, 0)]


def test_paired_differences_of_synthetic_seeds() -> None:
    per_seed = [
        {"fusion": {"all": {"epe": 1.0, "bad2": 10.0}}, "no_vlm": {"all": {"epe": 1.5, "bad2": 8.0}},
         "sgbm": {"all": {"epe": 3.0, "bad2": 20.0}}},
        {"fusion": {"all": {"epe": 2.0, "bad2": 14.0}}, "no_vlm": {"all": {"epe": 1.5, "bad2": 10.0}},
         "sgbm": {"all": {"epe": 3.0, "bad2": 20.0}}},
        {"fusion": {"all": {"epe": 1.5, "bad2": 12.0}}, "no_vlm": {"all": {"epe": 2.5, "bad2": 9.0}},
         "sgbm": {"all": {"epe": 3.0, "bad2": 20.0}}},
    ]
    paired = fusion.paired_differences(per_seed, "fusion")
    assert paired["reference"] == "fusion" and paired["seeds"] == 3
    # fusion - no_vlm: epe -0.5, +0.5, -1.0; bad2 +2, +4, +3
    assert paired["against"]["no_vlm"]["all"] == {
        "epe": pytest.approx(-0.333, abs=1e-3), "epe_spread": pytest.approx(0.624, abs=1e-3), "epe_lower": 2,
        "bad2": 3.0, "bad2_spread": pytest.approx(0.816, abs=1e-3), "bad2_lower": 0}
    assert paired["against"]["sgbm"]["all"]["epe"] == -1.5 and paired["against"]["sgbm"]["all"]["epe_lower"] == 3
    one = fusion.paired_differences(per_seed[:1], "fusion")["against"]["no_vlm"]["all"]
    assert one == {"epe": -0.5, "epe_lower": 1, "bad2": 2.0, "bad2_lower": 0}


def test_condition_ranges_summarise_frames() -> None:
    ranges = fusion.condition_ranges({"mirror_fooling_px": [3.0, 1.0, 2.0], "aligned_mono_epe_px": []})
    assert ranges == {"mirror_fooling_px": {"frames": 3, "min": 1.0, "median": 2.0, "max": 3.0},
                      "aligned_mono_epe_px": {"frames": 0}}


def test_capture_baselines_cover_the_held_out_pairs() -> None:
    """One frame of each capture seed at its drawn baseline against one of 30 test seeds at 0.63 m: the
    captures' disparities (1st-99th percentile) span the test pairs', and their mirror fooling spans the
    test pairs' but for the 5 % at either end."""
    baselines = [fusion.capture_baseline(seed) for seed in fusion.RENDERED_SEEDS]
    assert all(fusion.TRAIN_BASELINE_M[0] <= b <= fusion.TRAIN_BASELINE_M[1] for b in baselines)
    assert len(set(baselines)) == len(baselines) and baselines == [fusion.capture_baseline(s) for s in fusion.RENDERED_SEEDS]
    captures = [s for seed in fusion.RENDERED_SEEDS for s in fusion.video_samples(fusion.capture_video(seed, 1))]
    tests = fusion.held_out_samples(fusion.TEST_SEEDS[:30], frames=1)

    def span(samples: list[Any]) -> tuple[float, float]:
        return (min(np.nanpercentile(s.disparity, 1) for s in samples), max(np.nanpercentile(s.disparity, 99) for s in samples))

    (train_lo, train_hi), (test_lo, test_hi) = span(captures), span(tests)
    assert train_lo <= test_lo and test_hi <= train_hi, (train_lo, train_hi, test_lo, test_hi)
    train_fooling = fusion.condition_values(captures)["mirror_fooling_px"]
    test_fooling = fusion.condition_values(tests)["mirror_fooling_px"]
    assert min(train_fooling) <= np.percentile(test_fooling, 5) and np.percentile(test_fooling, 95) <= max(train_fooling)
    assert min(test_fooling) > 5  # at 0.63 m a mirror fools stereo by several pixels


def test_redrawn_mono_is_an_independent_realistic_draw() -> None:
    """A generated sample's ground truth is its source map scaled (rectified inside illusions): the
    source aligns onto it exactly outside illusions; the redrawn input is as far off as a real network's
    (the test pairs' mono-gt-align: about 2 px), still fooled completely by the picture."""
    frame = render_video(3, 1, *fusion.SIZE).frames[0]
    masks = {pair.illusion_type: pair.illusion for pair in frame.regions}
    source, scale = frame.mono_disparity, 2.5
    truth = (scale * source).astype(np.float32)
    outside = ~(masks["picture"] | masks["mirror"])
    redrawn = fusion.redrawn_mono(truth, source, scale, masks, seed=3, index=0)
    assert redrawn.shape == truth.shape and redrawn.dtype == np.float32 and (redrawn > 0).all()

    def aligned_error(mono: np.ndarray) -> float:
        return float(np.mean(np.abs(align(mono, truth, outside, "lsq") - truth)[outside]))

    assert aligned_error(source) < 1e-3 and 0.5 < aligned_error(redrawn) < 6
    picture = masks["picture"]
    fit = np.polyfit(truth[picture], redrawn[picture], 1)  # the depicted scene, as painted: an affine of it
    assert np.abs(np.polyval(fit, truth[picture]) - redrawn[picture]).max() < 1e-3 * redrawn[picture].max()
    again = fusion.redrawn_mono(truth, source, scale, masks, seed=3, index=0)
    other = fusion.redrawn_mono(truth, source, scale, masks, seed=4, index=0)
    assert np.array_equal(redrawn, again) and not np.allclose(redrawn, other)


def test_pretraining_seeds_never_touch_the_benchmark_seeds(monkeypatch: pytest.MonkeyPatch) -> None:
    seeds = pretrain.pretrain_seeds(50_000)
    benchmark = pretrain.benchmark_seeds()
    assert {*fusion.TEST_SEEDS, *fusion.VAL_SEEDS, *fusion.RENDERED_SEEDS, *range(fusion.GENERATED_VIDEOS)} <= benchmark
    assert not benchmark.intersection(seeds) and min(seeds) > max(benchmark)
    # the generated samples' mono estimators come from a seed range of their own too
    assert max(seeds) < fusion.GENERATED_MONO_SEED
    monkeypatch.setattr(pretrain, "PRETRAIN_FIRST_SEED", 998)
    with pytest.raises(ValueError, match="benchmark's seed 1000"):
        pretrain.pretrain_seeds(5)
    overrides = pretrain.pretrain_overrides(30)
    assert overrides["train.steps"] == 30 and overrides["model.use_vlm"] is False
    assert load_preset("lite", overrides).model.use_mono  # its trunk learns from the mono input


@pytest.fixture(scope="module")
def trunk_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("pretrain")
    torch.manual_seed(1)
    config = load_preset("lite", pretrain.pretrain_overrides(10))
    save_checkpoint(folder / "best.pt", FusionNetwork(config.model), config, step=10)
    save_trunk(folder / "best.pt", folder / "trunk.safetensors", {"steps": 10})
    return folder / "trunk.safetensors"


def test_trunk_file_holds_the_trunk_with_its_recipe_and_hash(trunk_file: Path, tmp_path: Path) -> None:
    record = json.loads(trunk_file.with_suffix(".json").read_text())
    trunk = load_trunk(trunk_file)
    assert record["sha256"] == trunk.sha256 and record["recipe"] == trunk.recipe == {"steps": 10}
    assert record["tensors"] == len(trunk.state) == 126 and all(n.startswith(TRUNK_PREFIXES) for n in trunk.state)
    assert record["bytes"] < 4_000_000  # small enough to commit
    changed = tmp_path / "trunk.safetensors"
    data = bytearray(trunk_file.read_bytes())
    data[-1] ^= 1
    changed.write_bytes(bytes(data))
    with pytest.raises(ValueError, match="trunk.json"):
        load_trunk(changed)  # no record beside it
    changed.with_suffix(".json").write_text(json.dumps(record))
    with pytest.raises(ValueError, match="changed after pre-training"):
        load_trunk(changed)


def test_every_network_starts_from_the_trunk_and_its_own_fresh_heads(trunk_file: Path, tmp_path: Path) -> None:
    """The composed init is what the engine loads (its model config is the run's), holds the trunk's
    tensors, and elsewhere exactly what a fresh run of the same training seed starts with."""
    trunk = load_trunk(trunk_file)
    fresh_modules = {"fusion": {"vlm", "confidence", "fusion"}, "no_vlm": {"confidence", "fusion"}, "stereo_only": set()}
    for network in NETWORKS:
        overrides = fusion.network_overrides(network, 20)
        config = load_preset("lite", overrides)
        report = compose_init(trunk, config, 5, tmp_path / f"{network.name}.pt")
        assert report["loaded"] == 126 and report["unused"] == []
        assert {name.split(".")[0] for name in report["fresh"]} == fresh_modules[network.name]
        loaded, stored, _payload = load_network(tmp_path / f"{network.name}.pt")
        run_config = Config.from_dict(resolve_config("lite", {**overrides, "train.seed": 5}))
        assert stored.model == run_config.model  # the engine refuses an init whose model config differs
        torch.manual_seed(5)
        scratch = FusionNetwork(config.model).trainable_state_dict()
        state = loaded.trainable_state_dict()
        assert all(torch.equal(state[name], trunk.state[name]) for name in trunk.state)
        assert all(torch.equal(state[name], scratch[name]) for name in report["fresh"])


def test_cli_pretrain_passes_its_options_and_prints_the_conditions(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[dict[str, Any]] = []
    ranges = {"mirror_fooling_px": {"frames": 4, "min": 5.5, "median": 9.0, "max": 20.25},
              "aligned_mono_epe_px": {"frames": 8, "min": 1.0, "median": 2.0, "max": 3.0}}
    result = {"trunk": {"file": "pretrain/trunk.safetensors", "sha256": "ab" * 32, "tensors": 126, "parameters": 639296,
                        "bytes": 2_600_000, "recipe": {"run": 1, "best_step": 40, "data": {"seeds": [10000, 10002]}}},
              "conditions": {"training": {"captures": ranges}, "held_out": ranges}, "timings_s": {"total": 1.0}}
    monkeypatch.setattr(pretrain, "run_pretrain", lambda work_dir, **kw: calls.append({"work_dir": work_dir, **kw}) or result)
    out = CliRunner().invoke(main, ["bench", "pretrain", "--work-dir", str(tmp_path), "--videos", "3", "--frames", "2",
                                    "--steps", "40"])
    assert out.exit_code == 0, out.output
    assert calls == [{"work_dir": tmp_path.absolute(), "videos": 3, "frames": 2, "steps": 40, "stereo_only": False,
                      "truth": "surface"}]
    assert "4 frames: 5.50 / 9.00 / 20.25" in out.output and "pre-training captures" in out.output
    assert "test pairs" in out.output and "ab" * 32 in out.output
    out = CliRunner().invoke(main, ["bench", "pretrain", "--json", "--work-dir", str(tmp_path)])
    assert out.exit_code == 0 and json.loads(out.output) == result
    assert calls[-1] == {"work_dir": tmp_path.absolute(), "videos": pretrain.PRETRAIN_VIDEOS,
                         "frames": pretrain.PRETRAIN_FRAMES, "steps": pretrain.PRETRAIN_STEPS, "stereo_only": False,
                         "truth": "surface"}
    out = CliRunner().invoke(main, ["bench", "pretrain", "--json", "--stereo-only", "--truth", "matcher",
                                    "--work-dir", str(tmp_path)])
    assert out.exit_code == 0 and calls[-1]["stereo_only"] is True and calls[-1]["truth"] == "matcher"


def test_the_matchers_truth_is_the_reflection_inside_mirrors_and_the_surface_elsewhere() -> None:
    seed = fusion.RENDERED_SEEDS[0]
    surface, matcher = fusion.capture_video(seed, 1), fusion.capture_video(seed, 1, truth="matcher")
    (glass, seen), frame = (surface.frames[0].disparity, matcher.frames[0].disparity), surface.frames[0]
    mirror = np.any([pair.illusion for pair in frame.regions if pair.illusion_type == "mirror"], axis=0)
    assert np.array_equal(seen, frame.stereo_disparity) and np.array_equal(seen[~mirror], glass[~mirror])
    assert np.mean(glass[mirror] - seen[mirror]) > 1  # the reflection lies behind the glass
    assert np.array_equal(matcher.frames[0].left, frame.left)  # the same images: only the truth differs
    assert trunk_path(True, "matcher") == Path("pretrain/trunk-stereo-only-matcher.safetensors")
    assert trunk_path(False, "surface") == Path("pretrain/trunk.safetensors")


def _intervals() -> dict[str, Any]:
    """The intervals of a record of two scenes of two frames: fusion 1 px worse than stereo_only everywhere."""
    pairs = [SimpleNamespace(name=f"s{scene}/{frame}", meta={"seed": scene}) for scene in (0, 1) for frame in (0, 1)]
    figures = {m: {r: {"epe": [epe] * 4, "bad2": [10.0] * 4} for r in fusion.REGIONS}
               for m, epe in (("fusion", 3.0), ("stereo_only", 2.0))}
    scores = fusion.FrameScores(figures, {r: [100] * 4 for r in fusion.REGIONS}, {}, {})
    return fusion.intervals(fusion.held_out_record(pairs, [scores], scores), "fusion")


def test_cli_fusion_prints_the_conditions_the_figures_and_the_paired_record(tmp_path: Path,
                                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    ranges = {"mirror_fooling_px": {"frames": 36, "min": 5.96, "median": 16.5, "max": 19.9},
              "aligned_mono_epe_px": {"frames": 36, "min": 1.0, "median": 1.8, "max": 2.6}}
    per_seed = [{"fusion": {"mirror": {"epe": 2.0 + k, "bad2": 50.0}}, "stereo_only": {"mirror": {"epe": 2.5, "bad2": 40.0}}}
                for k in range(2)]
    results = {"pairs": {"split": "test", "mono": "realistic", "seeds": [100, 103], "samples": 24, "baseline_m": 0.63,
                         "disparity_px": [18.6, 51.0], "sha256": "c" * 64},
               "train_disparity_px": [3.0, 70.0],
               "conditions": {"training": {"captures": ranges, "generated": {**ranges, "mirror_fooling_px": {"frames": 0}}},
                              "held_out": ranges},
               "seeds": 2, "train_seeds": [0, 48], "split_seed": 0, "methods": fusion._aggregate(per_seed),
               "paired": fusion.paired_differences(per_seed, "fusion"), "pretrained": None, "timings_s": {"total": 1.0},
               "intervals": _intervals()}
    monkeypatch.setattr(fusion, "run_fusion_bench", lambda work_dir, **kw: results)
    out = CliRunner().invoke(main, ["bench", "fusion", "--work-dir", str(tmp_path)])
    assert out.exit_code == 0, out.output
    lines = out.output.splitlines()
    assert any(line.split()[:2] == ["training", "captures"] and "36 frames: 5.96 / 16.50 / 19.90" in line for line in lines)
    assert any(line.split()[:2] == ["training", "generated"] and "none" in line for line in lines)
    assert any(line.split()[:2] == ["test", "pairs"] for line in lines) and "at 0.63 m" in out.output
    assert any(line.split()[:1] == ["fusion"] and "2.50 ± 0.50 / 50.00" in line for line in lines)
    assert any(line.split()[:1] == ["stereo_only"] and "+0.00 ± 0.50 [1]" in line for line in lines)  # EPE: -0.5, +0.5
    assert any(line.split()[:1] == ["stereo_only"] and "+10.00 ± 0.00 [0]" in line for line in lines)  # bad-2
    assert "from scratch" in out.output
    # the intervals over scenes: fusion is 1 px worse than stereo_only in every frame, so that is decided
    assert any(line.split()[:3] == ["fusion", "-", "stereo_only"] and "+1.000 [+1.000, +1.000] higher" in line
               for line in lines)
    assert "oracle gate's headroom" in out.output
    assert lines[0].startswith("held-out pairs: test, mono realistic, seeds 100-103")
    results["pairs"] = {**results["pairs"], "split": None, "mono": "warp", "seeds": [300, 303]}
    out = CliRunner().invoke(main, ["bench", "fusion", "--mono", "warp", "--work-dir", str(tmp_path)])
    assert out.exit_code == 0, out.output
    lines = out.output.splitlines()
    assert lines[0].startswith("held-out pairs: warp, mono warp, seeds 300-303")
    assert any(line.split()[:2] == ["warp", "pairs"] for line in lines)


def test_cli_fusion_passes_the_mono_family(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """--mono reaches the training benchmark and --mono-only alike; --split with --mono warp is refused;
    --help names the warp pairs' seeds."""
    calls: list[tuple[str, dict[str, Any]]] = []
    monkeypatch.setattr(fusion, "run_fusion_bench", lambda work_dir, **kw: calls.append(("fusion", kw)) or {"ok": 1})
    monkeypatch.setattr(fusion, "run_mono_bench", lambda **kw: calls.append(("mono", kw)) or {"ok": 1})
    work = ["--work-dir", str(tmp_path), "--json"]
    for flags, expected in ((["--mono", "warp"], ("fusion", None, "warp")), ([], ("fusion", None, "realistic")),
                            (["--split", "val"], ("fusion", "val", "realistic")),
                            (["--mono-only", "--mono", "warp"], ("mono", None, "warp")),
                            (["--mono-only", "--split", "val"], ("mono", "val", "realistic"))):
        calls.clear()
        out = CliRunner().invoke(main, ["bench", "fusion", *work, *flags])
        assert out.exit_code == 0, (flags, out.output)
        (kind, kw), = calls
        assert (kind, kw["split"], kw["mono"]) == expected, flags
    for flags in (["--mono", "warp", "--split", "test"], ["--mono-only", "--mono", "warp", "--split", "val"]):
        out = CliRunner().invoke(main, ["bench", "fusion", *work, *flags])
        assert out.exit_code == 2 and "--split" in out.output, flags
    assert CliRunner().invoke(main, ["bench", "fusion", "--mono", "ideal"]).exit_code == 2
    seeds = fusion.CORRUPTION_SEEDS
    assert f"seeds {seeds[0]}-{seeds[-1]}" in CliRunner().invoke(main, ["bench", "fusion", "--help"]).output


def test_the_committed_trunk_is_the_one_its_record_describes() -> None:
    """docs/bench/trunk: the trunk the README's protocol-2 figures start from, with its recipe."""
    committed = Path(__file__).parents[1] / "docs" / "bench" / "trunk" / "trunk.safetensors"
    trunk = load_trunk(committed)
    assert trunk.recipe["command"].startswith("illusion-studio bench pretrain")
    assert set(trunk.recipe["data"]["seeds"]).isdisjoint(pretrain.benchmark_seeds())
    assert {name.split(".")[0] for name in trunk.state} == {"mono", "stereo_branch"}
