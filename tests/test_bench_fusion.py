"""`bench fusion` without training: the ablation networks' configs and
what they predict, the validation split's own seeds, and the report's methods, paired record and timings."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner
from sqlalchemy import select

torch = pytest.importorskip("torch")

from benchmarks import fusion  # noqa: E402  (not its test_samples by name: pytest would collect it)
from benchmarks.trunk import save_trunk  # noqa: E402
from model.checkpoint import save_checkpoint  # noqa: E402
from model.losses import fusion_loss  # noqa: E402
from model.network import FusionNetwork  # noqa: E402
from model.presets import load_preset  # noqa: E402
from webapp.cli import main  # noqa: E402

NETWORKS = {n.name: n for n in (fusion.FUSION, *fusion.ABLATIONS)}


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
    assert NETWORKS["no_vlm"].methods == {"fusion_no_vlm": "fusion", "stereo_no_vlm": "stereo"}
    assert NETWORKS["stereo_only"].methods == {"stereo_only": "stereo"}
    with pytest.raises(ValueError, match="use_mono = false"):
        load_preset("lite", {"model.use_mono": False})  # the VLM would condition a confidence that is not there
    # a fine-tuning that holds the trunk holds the fusing networks'; the stereo-only one, all trunk, trains whole
    held = {name: load_preset("lite", fusion.network_overrides(network, 20, {"train.freeze_trunk": True}))
            for name, network in NETWORKS.items()}
    assert {name: config.train.freeze_trunk for name, config in held.items()} == {
        "fusion": True, "no_vlm": True, "stereo_only": False}
    fusion.check_overrides({"train.freeze_trunk": True}, NETWORKS.values())


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


def test_held_out_sets_are_100_scenes_of_their_own(monkeypatch: pytest.MonkeyPatch) -> None:
    from benchmarks.pretrain import PRETRAIN_FIRST_SEED, PRETRAIN_VIDEOS

    training = set(range(fusion.GENERATED_VIDEOS)) | set(fusion.RENDERED_SEEDS)
    pretraining = set(range(PRETRAIN_FIRST_SEED, PRETRAIN_FIRST_SEED + PRETRAIN_VIDEOS))
    sets = {"test": set(fusion.TEST_SEEDS), "val": set(fusion.VAL_SEEDS), "warp": set(fusion.CORRUPTION_SEEDS)}
    assert set(fusion.SPLITS) == {"test", "val"} and all(len(seeds) == 100 for seeds in sets.values())
    for name, seeds in sets.items():
        others = set().union(*(v for k, v in sets.items() if k != name))
        assert not seeds & (training | pretraining | others), name
    # rendering all 200 frames is the benchmark's business: two scenes show what each pair carries
    render = fusion.held_out_samples
    monkeypatch.setattr(fusion, "held_out_samples", lambda seeds, mono: render(seeds[:2], mono=mono))
    pairs, _render_s, info = fusion._held_out("val")
    assert info["split"] == "val" and info["seeds"] == sorted(sets["val"]) and info["samples"] == len(pairs) == 4
    assert info["baseline_m"] == fusion.HELD_OUT_BASELINE_M == 0.63 and fusion.HELD_OUT_FRAMES == 2
    assert {p.meta["seed"] for p in pairs} == set(fusion.VAL_SEEDS[:2])
    test_probe = render(fusion.TEST_SEEDS[:1], frames=1)
    assert test_probe[0].name.split("/")[0] not in {p.name.split("/")[0] for p in pairs}
    for pair in pairs:
        assert pair.mono is not None and set(pair.regions) == set(fusion.REGIONS)
        assert np.array_equal(pair.regions["illusion"], pair.regions["picture"] | pair.regions["mirror"])
    with pytest.raises(ValueError, match="unknown split"):
        fusion._held_out("train")


class _Workspace:
    """What run_fusion_bench needs of a prepared workspace when training is replaced."""

    def __init__(self, home: Path) -> None:
        self.settings = type("Settings", (), {"home": home})()

    def close(self) -> None:
        pass


CONDITIONS = {"mirror_fooling_px": {"frames": 2, "min": 5.0, "median": 6.0, "max": 7.0},
              "aligned_mono_epe_px": {"frames": 2, "min": 1.0, "median": 2.0, "max": 3.0}}


def _trunk(tmp_path: Path, name: str, overrides: dict[str, Any]) -> Path:
    """A trunk file of a fresh network of ``lite`` under ``overrides`` (seed 0), its record beside it."""
    torch.manual_seed(0)
    config = load_preset("lite", overrides)
    save_checkpoint(tmp_path / "pre.pt", FusionNetwork(config.model), config, step=0)
    path = tmp_path / "pretrain" / name
    save_trunk(tmp_path / "pre.pt", path, {"steps": 0, "overrides": overrides})
    return path


def _without_training(monkeypatch: pytest.MonkeyPatch) -> tuple[list[tuple[int, str]], list[int], list[tuple[int, ...]]]:
    """run_fusion_bench with each network's init checkpoint scored in place of its training and one frame
    per seed of the first two scenes. Returns what it will fill: the (seed, network) launched, the workers
    the trainings were run with, the seeds rendered."""
    launched: list[tuple[int, str]] = []
    checkpoints: dict[int, Path] = {}
    drained: list[int] = []

    def from_init(_rt: Any, seed: int, overrides: dict[str, Any], *, init: Path | None = None) -> int:
        assert not drained, "a run launched after the trainings ran"
        assert init is not None and init.is_file()
        name = next(n for n, network in NETWORKS.items() if overrides == fusion.network_overrides(network, 20))
        launched.append((seed, name))
        checkpoints[len(launched)] = init
        return len(launched)

    rendered: list[tuple[int, ...]] = []
    render = fusion.held_out_samples

    def one_frame(seeds: tuple[int, ...], mono: str) -> Any:
        rendered.append(seeds)
        return render(seeds[:2], frames=1, mono=mono)

    monkeypatch.setattr(fusion, "prepared_workspace",
                        lambda home: (_Workspace(home), True, {"captures": CONDITIONS, "generated": CONDITIONS}))
    monkeypatch.setattr(fusion, "training_disparity_range", lambda _rt: [3.0, 44.0])
    monkeypatch.setattr(fusion, "launch_run", from_init)
    monkeypatch.setattr(fusion, "run_jobs", lambda _rt, workers, runs: drained.append(workers))
    monkeypatch.setattr(fusion, "trained_checkpoint", lambda _rt, run_id: (checkpoints[run_id], 0.5 * run_id))
    monkeypatch.setattr(fusion, "held_out_samples", one_frame)
    return launched, drained, rendered


def test_report_carries_every_method_the_paired_record_and_the_timings(tmp_path: Path,
                                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """run_fusion_bench end to end, fine-tuning from a trunk, with each network's init checkpoint (the
    trunk's tensors and fresh ones) scored in place of its training and one frame per seed: every run
    launched before any trains, from its init, the trainings run by ``workers`` at once."""
    trunk_file = _trunk(tmp_path, "trunk.safetensors", {"model.use_vlm": False})
    launched, drained, rendered = _without_training(monkeypatch)
    trained_before_provenance: list[int] = []
    provenance_block = fusion.provenance_block
    monkeypatch.setattr(fusion, "provenance_block",
                        lambda *a, **kw: trained_before_provenance.append(len(drained)) or provenance_block(*a, **kw))
    report = fusion.run_fusion_bench(tmp_path, seeds=2, steps=20, ablations=True, split="val", workers=2,
                                     pretrained=trunk_file)
    assert trained_before_provenance == [0]  # the commit and sources are the code that trains, taken first
    assert rendered == [fusion.VAL_SEEDS]
    assert launched == [(s, n) for s in (0, 1) for n in ("fusion", "no_vlm", "stereo_only")]
    assert drained == [2] and report["workers"] == 2
    methods = report["methods"]
    trained = ["fusion", "stereo", "fusion_no_vlm", "stereo_no_vlm", "stereo_only"]
    scored = [*trained, "trunk_0", "trunk_0_stereo"]  # the trunk at 0 steps: scored, never trained
    assert list(methods) == [*scored, "mono_gt_align", "sgbm"]
    for method, regions in methods.items():
        assert set(regions) == set(fusion.REGIONS)
        for figures in regions.values():
            trained_method = method not in fusion.BASELINES
            assert set(figures) == ({"epe", "bad2", "epe_spread", "bad2_spread"} if trained_method else {"epe", "bad2"})
            assert all(np.isfinite(v) and v >= 0 for v in figures.values())
    # the fresh heads of two seeds differ; the stereo-only network is all trunk, so its seeds start alike
    assert methods["fusion"]["all"]["epe_spread"] > 0 and methods["stereo_only"]["all"]["epe_spread"] == 0
    # the paired record: every seed's figures, and fusion against every other method
    assert [(r["seed"], r["train_seed"]) for r in report["per_seed"]] == [(0, 0), (1, 1)]
    assert report["train_seeds"] == [0, 1] and report["split_seed"] == fusion.SPLIT_SEED
    for k, record in enumerate(report["per_seed"]):
        assert list(record["methods"]) == scored and record["runs"] == {"fusion": 3 * k + 1, "no_vlm": 3 * k + 2,
                                                                        "stereo_only": 3 * k + 3}
    paired = report["paired"]
    assert paired["reference"] == "fusion" and paired["seeds"] == 2
    assert list(paired["against"]) == [*scored[1:], "mono_gt_align", "sgbm"]
    runs = report["per_seed"]
    mean = (runs[0]["methods"]["fusion"]["mirror"]["epe"] - runs[0]["methods"]["stereo_no_vlm"]["mirror"]["epe"]
            + runs[1]["methods"]["fusion"]["mirror"]["epe"] - runs[1]["methods"]["stereo_no_vlm"]["mirror"]["epe"]) / 2
    assert paired["against"]["stereo_no_vlm"]["mirror"]["epe"] == pytest.approx(mean, abs=2e-3)
    # what each network took from the trunk, and what started fresh
    init = report["pretrained"]["init"]
    assert report["pretrained"]["sha256"] == json.loads((trunk_file.with_suffix(".json")).read_text())["sha256"]
    assert {name: init[name]["loaded"] for name in init} == {"fusion": 126, "no_vlm": 126, "stereo_only": 126,
                                                            "trunk_0": 126}
    assert {n.split(".")[0] for n in init["fusion"]["fresh"]} == {"vlm", "confidence", "fusion"}
    assert {n.split(".")[0] for n in init["no_vlm"]["fresh"]} == {"confidence", "fusion"}
    assert init["stereo_only"]["fresh"] == [] and all(not i["unused"] for i in init.values())
    assert report["conditions"]["training"] == {"captures": CONDITIONS, "generated": CONDITIONS}
    assert set(report["conditions"]["held_out"]) == {"mirror_fooling_px", "aligned_mono_epe_px"}
    timings = report["timings_s"]
    assert set(timings) == {"prepare", "render_pairs", "score_baselines", "train", "train_wall", "score", "total"}
    assert timings["train"] == {"fusion": [0.5, 2.0], "no_vlm": [1.0, 2.5], "stereo_only": [1.5, 3.0]}
    assert set(timings["score"]) == {"fusion", "no_vlm", "stereo_only", "trunk_0"}
    assert all(len(v) == 2 and min(v) > 0 for v in timings["score"].values())
    assert report["pairs"]["split"] == "val" and report["pairs"]["seeds"] == list(fusion.VAL_SEEDS)
    assert report["pairs"]["baseline_m"] == 0.63 and report["protocol"] == fusion.PROTOCOL == 4
    assert report["networks"]["stereo_only"]["overrides"] == {"model.use_vlm": False, "model.use_mono": False,
                                                              "train.freeze_trunk": False}
    provenance = report["provenance"]
    assert len(provenance["commit"]["commit"]) == 40 and len(provenance["sources"]["sha256"]) == 64
    assert set(provenance["resolved_configs"]) == {"fusion", "no_vlm", "stereo_only", "trunk_0"}
    assert provenance["resolved_configs"]["stereo_only"]["model"]["use_mono"] is False
    assert report["networks"]["trunk_0"]["trained"] is False and report["networks"]["fusion"]["trained"] is True
    # the per-frame record: every frame and region, each seed's row (the baselines: one), and the gates' sums
    frames = report["per_frame"]
    assert [f["scene"] for f in frames["frames"]] == list(fusion.VAL_SEEDS[:2])
    assert set(frames["pixels"]) == set(fusion.REGIONS) and frames["pixels"]["all"][0] > 0
    assert [len(frames["methods"][m]["all"]["epe"]) for m in ("fusion", "sgbm")] == [2, 1]
    for seed in range(2):  # the record's frames give back the figures
        assert np.mean(frames["methods"]["fusion"]["mirror"]["epe"][seed]) == pytest.approx(
            report["per_seed"][seed]["methods"]["fusion"]["mirror"]["epe"], abs=1e-3)
    assert set(frames["gates"]) == {"fusion", "fusion_no_vlm", "trunk_0", "oracle:sgbm", "oracle:stereo",
                                    "oracle:stereo_no_vlm", "oracle:stereo_only", "oracle:trunk_0_stereo"}
    # the intervals: every difference decided or not, the isolation rows, the oracle and each gate's capture
    found = report["intervals"]
    assert found["scenes"] == 2 and found["seeds"] == 2 and found["level"] == 0.95
    for method, regions in found["against"].items():
        for region, figures in regions.items():
            epe = figures["epe"]
            assert epe["low"] <= epe["value"] <= epe["high"] and epe["decided"] in ("lower", "higher", "undecided")
            assert epe["value"] == pytest.approx(report["paired"]["against"][method][region]["epe"], abs=2e-3)
    assert set(found["isolation"]) == {"fusion - stereo", "fusion_no_vlm - stereo_no_vlm", "trunk_0 - trunk_0_stereo"}
    assert set(found["oracle"]) == {"sgbm", "stereo", "stereo_no_vlm", "stereo_only", "trunk_0_stereo"}
    assert all(v["all"]["value"] >= 0 for v in found["oracle"].values())  # the oracle is never worse than its stereo
    assert set(found["capture"]) == {"fusion", "fusion_no_vlm", "trunk_0"}
    assert report["stereo_only_pretrained"] is None
    json.dumps(report, allow_nan=False)


def test_the_stereo_only_network_starts_from_a_trunk_of_its_own(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """--stereo-only-pretrained: the stereo-only network fine-tunes from a trunk that never read the mono,
    is scored at 0 steps from it as well, and its key names that trunk; a trunk with the mono is refused."""
    trunk_file = _trunk(tmp_path, "trunk.safetensors", {"model.use_vlm": False})
    own = _trunk(tmp_path, "trunk-stereo-only.safetensors", dict(fusion.ABLATIONS[1].overrides))
    launched, _, _ = _without_training(monkeypatch)
    report = fusion.run_fusion_bench(tmp_path, seeds=1, steps=20, ablations=True, split="val",
                                     pretrained=trunk_file, stereo_only_pretrained=own)
    assert launched == [(0, "fusion"), (0, "no_vlm"), (0, "stereo_only")]
    assert list(report["methods"])[-4:] == ["trunk_0_stereo", "stereo_only_0", "mono_gt_align", "sgbm"]
    assert report["stereo_only_pretrained"]["sha256"] == json.loads(own.with_suffix(".json").read_text())["sha256"]
    assert report["networks"]["stereo_only_0"]["trained"] is False
    init = report["pretrained"]["init"]
    assert init["stereo_only"]["fresh"] == [] and init["stereo_only_0"]["loaded"] == init["stereo_only"]["loaded"]
    # a network trained from the untrained trunk at 0 steps scores as that trunk: both are its init
    assert report["methods"]["stereo_only"] == report["methods"]["stereo_only_0"]
    assert "oracle:stereo_only_0" in report["per_frame"]["gates"]
    with pytest.raises(ValueError, match="pre-trained with the mono input"):
        fusion.load_stereo_only_trunk(trunk_file, True)
    with pytest.raises(ValueError, match="--ablations"):
        fusion.load_stereo_only_trunk(own, False)


def test_aggregate_gives_mean_and_spread_over_seeds() -> None:
    runs = [{"fusion_no_vlm": {"all": {"epe": 1.0, "bad2": 10.0}}}, {"fusion_no_vlm": {"all": {"epe": 3.0, "bad2": 20.0}}}]
    assert fusion._aggregate(runs) == {"fusion_no_vlm": {"all": {"epe": 2.0, "epe_spread": 1.0, "bad2": 15.0,
                                                                 "bad2_spread": 5.0}}}
    assert fusion._aggregate(runs[:1]) == {"fusion_no_vlm": {"all": {"epe": 1.0, "bad2": 10.0}}}


def test_cli_passes_ablations_split_and_the_trunk(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[dict[str, Any]] = []
    monkeypatch.setattr(fusion, "run_fusion_bench", lambda work_dir, **kw: calls.append(kw) or {"ok": 1})
    work = ["--work-dir", str(tmp_path)]
    result = CliRunner().invoke(main, ["bench", "fusion", "--json", "--ablations", "--split", "val", "--steps", "20", *work])
    assert result.exit_code == 0, result.output
    assert calls == [{"seeds": 1, "steps": 20, "ablations": True, "split": "val", "mono": "realistic", "workers": 1,
                      "pretrained": None, "stereo_only_pretrained": None, "overrides": {}}]
    calls.clear()
    result = CliRunner().invoke(main, ["bench", "fusion", "--json", "--set", "model.fusion_gate=false", "--set",
                                       "confidence_loss = focal", *work])
    assert result.exit_code == 0, result.output
    assert calls[0]["overrides"] == {"model.fusion_gate": "false", "confidence_loss": "focal"}
    for bad, message in ((["--set", "fusion_gate"], "KEY=VALUE"), (["--set", "model.fusion_gate=maybe"], "true or false"),
                         (["--set", "model.nope=1"], "unknown config key"), (["--set", "train.steps=5"], "--steps"),
                         (["--set", "seed=3"], "benchmark's own"),
                         (["--ablations", "--set", "mono_backend=depth-anything-v2"], "the stereo_only network")):
        result = CliRunner().invoke(main, ["bench", "fusion", *bad, *work])
        assert result.exit_code == 2 and message in result.output, bad
    trunk = tmp_path / "pretrain" / "trunk.safetensors"
    trunk.parent.mkdir()
    trunk.write_bytes(b"")
    for flags, expected in (([], trunk), (["--scratch"], None), (["--pretrained", str(tmp_path / "other")], None)):
        (tmp_path / "other").write_bytes(b"")
        calls.clear()
        result = CliRunner().invoke(main, ["bench", "fusion", "--json", *work, *flags])
        assert result.exit_code == 0, result.output
        assert calls[0]["pretrained"] == (expected if flags[:1] != ["--pretrained"] else tmp_path / "other"), flags
        # fine-tuning from a trunk is short; from scratch the benchmark trains longer
        assert calls[0]["steps"] == (fusion.DEFAULT_STEPS if flags == ["--scratch"] else fusion.FINETUNE_STEPS), flags
    for flags in (["--ablations"], ["--workers", "2"], ["--set", "fusion_gate=true"],
                  ["--stereo-only-pretrained", str(trunk)]):
        result = CliRunner().invoke(main, ["bench", "fusion", "--mono-only", *flags])
        assert result.exit_code == 2 and "--mono-only" in result.output, flags
    # --mono-only's oracle uses the trunk's stereo branch at 0 steps: the trunk is found as for training
    mono_calls: list[dict[str, Any]] = []
    monkeypatch.setattr(fusion, "run_mono_bench", lambda **kw: mono_calls.append(kw) or {"ok": 1})
    for flags, expected in (([], trunk), (["--scratch"], None), (["--pretrained", str(tmp_path / "other")],
                                                                 tmp_path / "other")):
        result = CliRunner().invoke(main, ["bench", "fusion", "--mono-only", "--json", *work, *flags])
        assert result.exit_code == 0 and mono_calls[-1]["pretrained"] == expected, (flags, result.output)
    result = CliRunner().invoke(main, ["bench", "fusion", "--scratch", "--pretrained", str(trunk)])
    assert result.exit_code == 2 and "--scratch" in result.output
    assert CliRunner().invoke(main, ["bench", "fusion", "--split", "train"]).exit_code == 2


def test_a_trained_network_is_reused_only_when_everything_that_makes_it_is_equal(tmp_path: Path) -> None:
    """The workspace's ledger: the same config (however its overrides are spelled), seed, trunk and model
    code find the run once it succeeded with its best checkpoint; any of them changed trains anew."""
    from dataset.db import transaction
    from dataset.tables import RunState, TrainingRun
    from webapp.cli.workspace import init_workspace
    from webapp.runtime import Runtime

    config = fusion.network_overrides(fusion.FUSION, 20, {"model.fusion_gate": "false"})
    key = fusion.network_key(config, 7, None, "code")
    assert key == fusion.network_key({**config, "model.fusion_gate": False}, 7, None, "code")
    others = [fusion.network_key(fusion.network_overrides(fusion.FUSION, 20), 7, None, "code"),
              fusion.network_key(config, 8, None, "code"), fusion.network_key(config, 7, None, "other code"),
              fusion.network_key(fusion.network_overrides(fusion.ABLATIONS[0], 20, {"model.use_vlm": True}), 7, None, "code")]
    assert len({key, *others}) == 5
    stereo_only = [fusion.network_key(fusion.network_overrides(fusion.ABLATIONS[1], 20, design), 7, None, "code")
                   for design in ({}, {"model.fusion_gate": False, "train.confidence_loss": "focal", "model.flow_noise": True})]
    assert stereo_only[0] == stereo_only[1]  # the fusion-only fields do not make a stereo-only network
    no_vlm = [fusion.network_key(fusion.network_overrides(fusion.ABLATIONS[0], 20, design), 7, None, "code")
              for design in ({}, {"model.flow_noise": True, "model.vlm_eye": "patches"},
                             {"model.fusion_gate": False})]
    assert no_vlm[0] == no_vlm[1] != no_vlm[2]  # nor the VLM's a no-VLM one; its fusion's do
    assert fusion.network_key(fusion.network_overrides(fusion.ABLATIONS[1], 20, {"model.token_downsample": 4}),
                              7, None, "code") != stereo_only[0]  # the token grid sets its size multiple
    assert stereo_only[0] != fusion.network_key(fusion.network_overrides(fusion.ABLATIONS[1], 20, {"train.lr": 1e-3}),
                                                7, None, "code")
    assert len(fusion.model_fingerprint()) == 64
    rt = Runtime(init_workspace(tmp_path / "ws"))
    ledger = rt.settings.home / fusion.TRAINED
    with transaction(rt.sessions) as s:
        run = TrainingRun(preset="lite", config={}, dataset_id="ab" * 32, dataset={}, state=RunState.running)
        s.add(run)
        s.flush()
        run_id = run.id
    fusion.record_run(ledger, key, run_id)
    fusion.record_run(ledger, others[0], run_id + 1)
    assert json.loads(ledger.read_text()) == {key: run_id, others[0]: run_id + 1}
    assert fusion.finished_run(rt, ledger, key) is None  # cut off while running: trained anew
    with transaction(rt.sessions) as s:
        s.get(TrainingRun, run_id).state = RunState.queued
    assert fusion.finished_run(rt, ledger, key) == run_id  # launched, not yet run: this benchmark runs it
    with transaction(rt.sessions) as s:
        s.get(TrainingRun, run_id).state = RunState.succeeded
    assert fusion.finished_run(rt, ledger, key) is None  # no best checkpoint
    best = fusion.trained_checkpoint_path(rt, run_id)
    best.parent.mkdir(parents=True)
    best.write_bytes(b"weights")
    assert fusion.finished_run(rt, ledger, key) == run_id
    assert fusion.finished_run(rt, ledger, others[1]) is None and fusion.finished_run(rt, ledger, others[0]) is None
    rt.close()


def test_a_benchmark_runs_only_the_jobs_of_the_runs_it_launched(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Two benchmarks on one work dir share its queue: each drains only its own runs' jobs."""
    from dataset.db import transaction
    from dataset.services import jobs as job_service
    from dataset.tables import Job, JobState, RunState, TrainingRun
    from webapp.cli.workspace import init_workspace
    from webapp.runtime import Runtime

    rt = Runtime(init_workspace(tmp_path / "ws"))
    with transaction(rt.sessions) as s:
        jobs = [Job(kind="noop", params={}) for _ in range(3)]
        s.add_all(jobs)
        s.flush()
        runs = [TrainingRun(preset="lite", config={}, dataset_id="ab" * 32, dataset={}, state=RunState.queued,
                            job_id=job.id) for job in jobs]
        s.add_all(runs)
        s.flush()
        job_ids, run_ids = [job.id for job in jobs], [run.id for run in runs]
    ran: list[int] = []
    handlers = {"noop": lambda ctx: ran.append(ctx.job_id) or {}}
    assert job_service.run_queued_jobs(handlers, rt, only={job_ids[1]}) == [(job_ids[1], JobState.succeeded)]
    with rt.sessions() as s:
        run_ids_of = {job_id: s.scalar(select(TrainingRun.id).where(TrainingRun.job_id == job_id)) for job_id in job_ids}
    assert run_ids_of[job_ids[1]] == run_ids[1]
    monkeypatch.setattr(fusion, "HANDLERS", handlers)  # the real queue and claim, a trivial job's work
    fusion.run_jobs(rt, 2, [run_ids[2]])
    assert ran == [job_ids[1], job_ids[2]]
    with rt.sessions() as s:
        assert s.get(Job, job_ids[0]).state == JobState.queued  # another benchmark's: left alone
    rt.close()
