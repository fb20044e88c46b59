"""`bench fusion` (issue 22, items 2 and 5) without training: the ablation networks' configs and what
they predict, the validation split's own seeds, and the report's methods and timings."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner

torch = pytest.importorskip("torch")

from model.checkpoint import save_checkpoint  # noqa: E402
from model.losses import fusion_loss  # noqa: E402
from model.network import FusionNetwork  # noqa: E402
from model.presets import load_preset  # noqa: E402
from webapp.benchmarks import fusion  # noqa: E402  (not its test_samples by name: pytest would collect it)
from webapp.cli import main  # noqa: E402

NETWORKS = {n.name: n for n in (fusion.FUSION, *fusion.ABLATIONS)}
TRAIN_P99_PX = 43.87  # as tests/test_synthetic_mono.py: the prepared data's, fixes the pairs' baseline


def _config(name: str):
    return load_preset("lite", fusion.network_overrides(NETWORKS[name], 20))


def _pair(seed: int = 0, height: int = 64, width: int = 96) -> tuple[Any, Any]:
    generator = torch.Generator().manual_seed(seed)
    left = torch.rand(1, 3, height, width, generator=generator) * 255
    return left, torch.roll(left, shifts=-3, dims=3)


def test_ablation_configs_differ_from_fusion_only_where_intended() -> None:
    configs = {name: _config(name) for name in NETWORKS}
    assert set(configs) == {"fusion", "no_vlm", "stereo_only"}
    assert (configs["fusion"].model.use_vlm, configs["fusion"].model.use_mono) == (True, True)
    assert (configs["no_vlm"].model.use_vlm, configs["no_vlm"].model.use_mono) == (False, True)
    assert (configs["stereo_only"].model.use_vlm, configs["stereo_only"].model.use_mono) == (False, False)
    for config in configs.values():  # trained the same way: same steps, crop, batch, schedule
        assert config.train == configs["fusion"].train
        assert config.train.steps == 20 and config.train.crop == (160, 288)
    assert NETWORKS["no_vlm"].methods == {"fusion_no_vlm": "fusion"}
    assert NETWORKS["stereo_only"].methods == {"stereo_only": "stereo"}
    with pytest.raises(ValueError, match="use_mono = false"):
        load_preset("lite", {"model.use_mono": False})  # the VLM would condition a confidence that is not there


def test_stereo_only_predicts_its_stereo_branch_never_sees_mono_and_trains_every_parameter() -> None:
    torch.manual_seed(0)
    config = _config("stereo_only")
    network = FusionNetwork(config.model)
    assert network.confidence is None and network.fusion is None and network.vlm is None
    left, right = _pair()
    mono = torch.linspace(1, 5, 96).view(1, 1, 1, -1).expand(1, 1, 64, 96).contiguous()
    network.eval()
    with torch.no_grad():
        outs = [network(left, right, m, iters=3) for m in (mono, 7 - mono, None)]
    assert outs[0].stereo_only and torch.equal(outs[0].disparity, outs[0].stereo)
    assert torch.equal(outs[0].disparity, outs[1].disparity) and torch.equal(outs[0].disparity, outs[2].disparity)
    assert (outs[0].confidence == 1).all()
    network.train()
    out = network(left, right, mono, iters=3)
    gt = torch.full((1, 1, 64, 96), 3.0)
    loss, parts = fusion_loss(out, gt, torch.ones_like(gt, dtype=torch.bool), config.train)
    assert parts["mono_aligned"] == parts["final"] == parts["confidence"] == 0 and parts["total"] == parts["stereo"]
    loss.backward()
    # DDP (find_unused_parameters off) stops a run whose parameter gets no gradient
    assert [n for n, p in network.named_parameters() if p.requires_grad and p.grad is None] == []


def test_fusion_networks_fuse_and_use_the_mono_input() -> None:
    torch.manual_seed(0)
    for name in ("fusion", "no_vlm"):
        network = FusionNetwork(_config(name).model).eval()
        assert network.confidence is not None and network.fusion is not None
        left, right = _pair(height=64, width=128)
        mono = torch.linspace(1, 5, 128).view(1, 1, 1, -1).expand(1, 1, 64, 128).contiguous()
        with torch.no_grad():
            a, b = network(left, right, mono, iters=2), network(left, right, 7 - mono, iters=2)
        assert not a.stereo_only and not torch.equal(a.disparity, a.stereo)
        assert not torch.equal(a.stereo, b.stereo)  # the mono input reaches the stereo branch's context


def test_validation_split_has_seeds_of_its_own() -> None:
    training_seeds = set(range(fusion.GENERATED_VIDEOS)) | set(fusion.RENDERED_SEEDS)
    assert set(fusion.SPLITS) == {"test", "val"} and fusion.SPLITS["test"] == tuple(range(100, 104))
    val = set(fusion.SPLITS["val"])
    assert len(val) == 4 and not val & (training_seeds | set(fusion.TEST_SEEDS))
    pairs, _render_s, info = fusion._held_out([0.0, TRAIN_P99_PX], "val")
    assert info["split"] == "val" and info["seeds"] == sorted(val) and info["samples"] == len(pairs) == 4 * fusion.FRAMES
    assert {p.meta["seed"] for p in pairs} == val
    test_probe, _ = fusion.test_samples([0.0, TRAIN_P99_PX], seeds=fusion.TEST_SEEDS[:1], frames=1)
    assert test_probe[0].name.split("/")[0] not in {p.name.split("/")[0] for p in pairs}
    assert all(p.mono is not None and {"picture", "mirror", "non_illusion"} <= set(p.regions) for p in pairs)
    with pytest.raises(ValueError, match="unknown split"):
        fusion._held_out([0.0, TRAIN_P99_PX], "train")


class _Closed:
    def close(self) -> None:
        pass


def test_report_carries_every_method_and_the_timings(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """run_fusion_bench end to end with untrained networks in place of training and one frame per seed:
    every run launched before any trains, the trainings run by ``workers`` at once."""
    launched: list[tuple[int, str]] = []
    checkpoints: dict[int, Path] = {}
    drained: list[int] = []

    def untrained(_rt: Any, seed: int, steps: int, network: fusion.Network) -> int:
        assert not drained, "a run launched after the trainings ran"
        torch.manual_seed(seed)
        config = load_preset("lite", fusion.network_overrides(network, steps))
        path = tmp_path / f"{network.name}-{seed}.pt"
        save_checkpoint(path, FusionNetwork(config.model), config, step=0)
        launched.append((seed, network.name))
        checkpoints[len(launched)] = path
        return len(launched)

    rendered: list[tuple[int, ...]] = []
    render = fusion.test_samples

    def one_frame(train_range: list[float], seeds: tuple[int, ...]) -> Any:
        rendered.append(seeds)
        return render(train_range, seeds=seeds[:2], frames=1)

    monkeypatch.setattr(fusion, "prepared_workspace", lambda _home: (_Closed(), True))
    monkeypatch.setattr(fusion, "training_disparity_range", lambda _rt: [0.0, TRAIN_P99_PX])
    monkeypatch.setattr(fusion, "_launch", untrained)
    monkeypatch.setattr(fusion, "_run_jobs", lambda _rt, workers: drained.append(workers))
    monkeypatch.setattr(fusion, "_trained", lambda _rt, run_id: (checkpoints[run_id], 0.5 * run_id))
    monkeypatch.setattr(fusion, "test_samples", one_frame)
    report = fusion.run_fusion_bench(tmp_path, seeds=2, steps=20, ablations=True, split="val", workers=2)
    assert rendered == [fusion.VAL_SEEDS]
    assert launched == [(s, n) for s in (0, 1) for n in ("fusion", "no_vlm", "stereo_only")]
    assert drained == [2] and report["workers"] == 2
    methods = report["methods"]
    assert list(methods) == ["fusion", "stereo", "fusion_no_vlm", "stereo_only", "mono_gt_align", "sgbm"]
    for method, regions in methods.items():
        assert set(regions) == set(fusion.REGIONS)
        for figures in regions.values():
            trained_method = method not in fusion.BASELINES
            assert set(figures) == ({"epe", "bad2", "epe_spread", "bad2_spread"} if trained_method else {"epe", "bad2"})
            assert all(np.isfinite(v) and v >= 0 for v in figures.values())
    # two seeds of fresh networks differ; the untrained baselines are scored once
    assert methods["fusion"]["all"]["epe_spread"] > 0
    timings = report["timings_s"]
    assert set(timings) == {"prepare", "render_pairs", "score_baselines", "train", "train_wall", "score", "total"}
    assert timings["train"] == {"fusion": [0.5, 2.0], "no_vlm": [1.0, 2.5], "stereo_only": [1.5, 3.0]}
    assert all(len(v) == 2 and min(v) > 0 for v in timings["score"].values())
    assert report["pairs"]["split"] == "val" and report["pairs"]["seeds"] == list(fusion.VAL_SEEDS)
    assert report["runs"] == [{"seed": 0, "fusion": 1, "no_vlm": 2, "stereo_only": 3},
                              {"seed": 1, "fusion": 4, "no_vlm": 5, "stereo_only": 6}]
    assert report["networks"]["stereo_only"]["overrides"] == {"model.use_vlm": False, "model.use_mono": False}
    json.dumps(report, allow_nan=False)


def test_aggregate_gives_mean_and_spread_over_seeds() -> None:
    runs = [{"fusion_no_vlm": {"all": {"epe": 1.0, "bad2": 10.0}}}, {"fusion_no_vlm": {"all": {"epe": 3.0, "bad2": 20.0}}}]
    assert fusion._aggregate(runs) == {"fusion_no_vlm": {"all": {"epe": 2.0, "epe_spread": 1.0, "bad2": 15.0,
                                                                 "bad2_spread": 5.0}}}
    assert fusion._aggregate(runs[:1]) == {"fusion_no_vlm": {"all": {"epe": 1.0, "bad2": 10.0}}}


def test_cli_passes_ablations_and_split(monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[dict[str, Any]] = []
    monkeypatch.setattr(fusion, "run_fusion_bench", lambda work_dir, **kw: calls.append(kw) or {"ok": 1})
    result = CliRunner().invoke(main, ["bench", "fusion", "--json", "--ablations", "--split", "val", "--steps", "20"])
    assert result.exit_code == 0, result.output
    assert calls == [{"seeds": 1, "steps": 20, "ablations": True, "split": "val", "workers": 1}]
    for flags in (["--ablations"], ["--workers", "2"]):
        result = CliRunner().invoke(main, ["bench", "fusion", "--mono-only", *flags])
        assert result.exit_code == 2 and "--mono-only" in result.output, flags
    assert CliRunner().invoke(main, ["bench", "fusion", "--split", "train"]).exit_code == 2
