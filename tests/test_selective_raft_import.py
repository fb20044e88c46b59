"""Selective-RAFT's published checkpoints imported and run output-identical: seeded full-width weights
(batch norm far from identity) in the layout of its published files — DataParallel state dicts, keys
under ``module.`` — go through `checkpoints import --from selective-raft` and `predict` (its default
iterations, no --iters), and must give what Selective-RAFT's own code gave for them, demo-style, on the
Middlebury Motorcycle (tests/fixtures/selective_raft/, made by make_golden.py there): |ours − reference|
≤ 1e-3 px + 1e-4·|reference| at every pixel. Deliberate bugs (sign, padding, attention, statistics,
border) are shown to break that comparison; files that are not such checkpoints are one-line errors;
flags the tensors settle or the network never reads are refused."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from model.checkpoint import load_checkpoint  # noqa: E402
from model.predictor import Predictor  # noqa: E402
from model.raft_import import Flags, strip_module  # noqa: E402
from model.selective_raft_import import NotSelectiveRaft, convert, infer_architecture  # noqa: E402
from model.stereo import selective_raft  # noqa: E402
from tests.golden_cli import PADDING_BUGS, Patch, assert_accounted, assert_evaluated_beside, excess, patched, predict_cli  # noqa: E402
from tests.golden_cli import cli as _cli  # noqa: E402
from tests.raft_golden import fixture_state, load_fixture  # noqa: E402

FIXTURES = Path(__file__).parent / "fixtures" / "selective_raft"
# architecture → (tensors in the file, tensors of the network, norm3 duplicates, never-run tensors)
COUNTS = {"default": (352, 332, 20, 0), "twolevel": (340, 281, 20, 39)}
ARCHITECTURES = {
    "default": {"n_downsample": 2, "gru_levels": 3, "hidden": 128, "feature_dim": 256, "context_norm": "batch",
                "corr_levels": 4, "corr_radius": 4, "iterations": 32, "given": []},
    "twolevel": {"n_downsample": 3, "gru_levels": 2, "hidden": 128, "published": None, "iterations": 32,
                 "given": ["corr_levels", "corr_radius"]},
}
TWO_LEVEL_FLAGS = ("--corr-levels", "4", "--corr-radius", "4")


@pytest.fixture(scope="module")
def fixtures() -> dict[str, dict[str, Any]]:
    return {name: load_fixture(name, FIXTURES) for name in COUNTS}


@pytest.fixture()
def home(tmp_path: Path) -> Path:
    (tmp_path / "ws").mkdir()
    return tmp_path / "ws"


@pytest.mark.parametrize("name", sorted(COUNTS))
def test_imported_checkpoint_predicts_what_selective_raft_does(name: str, fixtures, home: Path,  # type: ignore[no-untyped-def]
                                                               tmp_path: Path) -> None:
    fixture = fixtures[name]
    left, right = fixture["left"], fixture["right"]
    assert hashlib.sha256(left.tobytes() + right.tobytes()).hexdigest() == fixture["pair_sha256"]  # the same pair
    published = tmp_path / f"{name}.pth"
    torch.save(fixture_state(fixture), published)
    flags = TWO_LEVEL_FLAGS if name == "twolevel" else ()
    imported = _cli(home, "checkpoints", "import", "--from", "selective-raft", str(published), "--name",
                    f"sr-{name}", "--json", *flags)
    assert imported.exit_code == 0, imported.output
    doc = json.loads(imported.output)
    assert_accounted(doc, f"imported:sr-{name}", COUNTS[name], ARCHITECTURES[name])
    payload = load_checkpoint(home / "checkpoints" / "imported" / f"sr-{name}.pt")
    assert payload["config"]["preset"] == "selective-raft" and payload["config"]["model"]["upsample_border"] == "zeros"
    assert payload["source"]["from"] == "selective-raft" and not payload["config"]["train"]["amp"]

    height, width = fixture["shape"]
    assert height % 32 and width % 32 and left.shape[:2] == (height, width)
    ours = predict_cli(home, tmp_path, fixture, doc["checkpoint"])  # no --iters: the demo's 32 are the default
    reference = fixture["disparity"]
    assert ours.shape == reference.shape == (height, width)
    assert excess(ours, reference) <= 0, f"{name}: off by up to {np.abs(ours - reference).max():.2e} px"


# Deliberate bugs, each a change a port could make: the comparison above must catch every one.
def _update_reads_plus_d(self, net, context, attention, corr, disp, *, with_mask):  # type: ignore[no-untyped-def]
    return _UPDATE(self, net, context, attention, corr, -disp, with_mask=with_mask)


def _attention_swapped(self, attention, h, *x):  # type: ignore[no-untyped-def]
    return self.small(h, None, *x) * (1 - attention) + self.large(h, None, *x) * attention


_UPDATE = selective_raft.SelectiveUpdate.forward
BUGS: dict[str, Patch] = {
    "motion encoder reads +d": patched(selective_raft.SelectiveUpdate, "forward", _update_reads_plus_d),
    "attention maps swapped": patched(selective_raft.SelectiveGRU, "forward", _attention_swapped),
    "no channel attention": patched(selective_raft.ChannelAttention, "forward",
                                    lambda self, x: torch.ones_like(x[:, :, :1, :1])),
    **PADDING_BUGS,
}


@pytest.fixture(scope="module")
def twolevel() -> tuple[Predictor, dict[str, Any]]:
    fixture = load_fixture("twolevel", FIXTURES)
    conversion = convert(fixture_state(fixture), Flags(corr_levels=4, corr_radius=4))
    return Predictor(conversion.network, conversion.config), fixture


def test_the_comparison_holds_for_the_port_and_fails_for_each_deliberate_bug(twolevel) -> None:  # type: ignore[no-untyped-def]
    predictor, fixture = twolevel
    torch.set_num_threads(1)

    def predict() -> np.ndarray:
        return predictor.predict(fixture["left"], fixture["right"]).disparity

    reference = fixture["disparity"]
    ours = predict()
    assert excess(ours, reference) <= 0
    assert excess(-ours, reference) > 0  # the demo's sign: disparity = −output
    for bug, patch in BUGS.items():
        with patch():
            assert excess(predict(), reference) > 0, f"{bug} went unnoticed"
    network = predictor.network
    border = network.stereo_branch.border
    network.stereo_branch.border = "edge"  # RAFT's zero-padded convex upsampling is what the files know
    try:
        assert excess(predict(), reference) > 0, "edge-padded upsampling went unnoticed"
    finally:
        network.stereo_branch.border = border
    saved = {k: v.clone() for k, v in network.state_dict().items() if "running_" in k}
    with torch.no_grad():  # batch-norm statistics at identity: the fixture's are far from it
        for module in network.modules():
            if isinstance(module, torch.nn.BatchNorm2d):
                module.reset_running_stats()
    try:
        assert excess(predict(), reference) > 0, "batch-norm statistics ignored went unnoticed"
    finally:
        network.load_state_dict(saved, strict=False)
    assert excess(predict(), reference) <= 0  # and nothing above left the network changed


def test_architecture_is_read_from_the_tensors_and_unsettled_layouts_are_refused(fixtures) -> None:  # type: ignore[no-untyped-def]
    default = strip_module(fixture_state(fixtures["default"]))
    assert infer_architecture(default).items() >= ARCHITECTURES["default"].items()
    assert infer_architecture(default)["published"]
    two = strip_module(fixture_state(fixtures["twolevel"]))
    with pytest.raises(NotSelectiveRaft, match="do not settle how its 36 correlation planes split: give "
                                               "--corr-levels and --corr-radius"):
        infer_architecture(two)
    arch = infer_architecture(two, Flags(corr_levels=4, corr_radius=4, iterations=20))
    assert arch.items() >= {"n_downsample": 3, "gru_levels": 2, "iterations": 20}.items()
    with pytest.raises(NotSelectiveRaft, match="is not the 36 correlation planes"):
        infer_architecture(default, Flags(corr_levels=4, corr_radius=3))
    with pytest.raises(NotSelectiveRaft, match="--slow-fast-gru: not an option of Selective-RAFT"):
        infer_architecture(default, Flags(slow_fast_gru=True))


@pytest.fixture(scope="module")
def default_state(fixtures) -> dict[str, torch.Tensor]:  # type: ignore[no-untyped-def]
    return fixture_state(fixtures["default"])


@pytest.mark.parametrize(("edit", "message"), [
    (lambda s: {"conv.weight": torch.zeros(1)}, "not a Selective-RAFT checkpoint: no update_block.mask.2.weight"),
    (lambda s: {k: v for k, v in s.items() if "gru16.large_gru.convq.bias" not in k},
     "missing update_block.gru16.large_gru.convq.bias"),
    (lambda s: {k: v for k, v in s.items() if "gru16" not in k and "gru08" not in k}, "one GRU level"),
    (lambda s: {k: v for k, v in s.items() if "gru08" not in k}, "not the finest levels first"),
    (lambda s: {k: v for k, v in s.items() if "cnet.norm1.running" not in k}, "builds it with batch norm only"),
    (lambda s: {**s, "module.extra.weight": torch.zeros(1)}, "unknown extra.weight"),
    (lambda s: {**s, "module.cam.fc.0.weight": torch.zeros(4, 128, 1, 1)}, "cam.fc.0.weight has shape (4, 128, 1, 1)"),
    (lambda s: {**s, "module.update_block.mask.2.weight": torch.zeros(36, 256, 1, 1)}, "has 36 rows: not 9·f²"),
    (lambda s: {**s, "module.sam.samconv.weight": torch.full((1, 2, 7, 7), np.nan)}, "not finite"),
    (lambda s: {**s, "module.cnet.conv1.weight": [1, 2]}, "not a state dict of tensors"),
])
def test_files_that_are_not_selective_raft_name_what_is_wrong(default_state, edit, message: str) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(NotSelectiveRaft, match=message.replace("(", r"\(").replace(")", r"\)")):
        convert(edit(default_state))


def test_the_cli_refuses_in_one_line_and_a_half_precision_file_imports(home: Path, tmp_path: Path,  # type: ignore[no-untyped-def]
                                                                        fixtures) -> None:
    raft_file, two_file = tmp_path / "raft.pth", tmp_path / "two.pth"
    torch.save(fixture_state(load_fixture("rvc")), raft_file)  # a RAFT-Stereo file is not a Selective-RAFT one
    torch.save(fixture_state(fixtures["twolevel"]), two_file)
    for args, words in (((str(raft_file),), "not a Selective-RAFT checkpoint: no update_block.gru04"),
                        ((str(two_file),), "give --corr-levels and --corr-radius"),
                        ((str(two_file), "--slow-fast"), "--slow-fast: not an option of selective-raft files"),
                        ((str(two_file), "--context-norm", "batch"), "--context-norm: not an option")):
        result = _cli(home, "checkpoints", "import", "--from", "selective-raft", *args)
        assert result.exit_code == 1 and words in result.output, result.output
        assert result.output.count("\n") == 1 and "Traceback" not in result.output
    assert not (home / "checkpoints" / "imported").exists() or not any((home / "checkpoints" / "imported").iterdir())
    # A float16 copy of the published file (as some labs keep them) imports as float32 weights, the same values.
    state = fixture_state(fixtures["default"])
    half = tmp_path / "half.pth"
    torch.save({k: v.half() if v.is_floating_point() else v for k, v in state.items()}, half)
    result = _cli(home, "checkpoints", "import", "--from", "selective-raft", str(half))
    assert result.exit_code == 0, result.output
    assert result.output.startswith("imported:half: Selective-RAFT (the published layout"), result.output
    weights = load_checkpoint(home / "checkpoints" / "imported" / "half.pt")["state"]
    mask = next(v for k, v in weights.items() if k.endswith("update.mask.net.2.weight"))
    assert mask.dtype == torch.float32
    assert torch.equal(mask, state["module.update_block.mask.2.weight"].half().float())


def test_evaluate_scores_selective_raft_beside_the_others_in_one_report(tmp_path: Path, fixtures) -> None:  # type: ignore[no-untyped-def]
    from tests.test_raft_baseline import import_default

    home = tmp_path / "evaluated"
    assert _cli(home, "init").exit_code == 0

    published = tmp_path / "sceneflow.pth"
    torch.save(fixture_state(fixtures["default"]), published)
    imported = _cli(home, "checkpoints", "import", "--from", "selective-raft", str(published), "--json")
    assert imported.exit_code == 0, imported.output
    selective = json.loads(imported.output)["checkpoint"]
    raft = import_default(home, tmp_path)
    assert_evaluated_beside(home, tmp_path, "selective-raft", selective, "raft-stereo", raft, "Selective-RAFT")


def test_the_preset_is_import_only_and_the_network_trains_with_frozen_batch_norm() -> None:
    from model.losses import fusion_loss
    from model.network import FusionNetwork
    from model.presets import ALL_PRESETS, load_preset
    from tests.model_pairs import random_dot_pair

    preset = load_preset("selective-raft")
    assert "selective-raft" not in ALL_PRESETS  # no `train --preset selective-raft`: only imports fill it
    assert (preset.model.architecture, preset.train.test_iters, preset.train.amp) == ("selective-raft", 32, False)
    assert preset.model.size_multiple == 16 and preset.model.inference_padding == (32, True)  # the demo's
    with pytest.raises(ValueError, match="'selective-raft' is stereo only"):
        load_preset("selective-raft", {"use_mono": True})
    tiny = {"encoder_dims": [8, 8, 16], "encoder_blocks": [1, 1, 1], "stem_kernel": 3, "feature_dim": 16,
            "hidden_dims": [16, 16, 16]}
    with pytest.raises(ValueError, match="needs 2 or 3 GRU levels"):
        FusionNetwork(load_preset("selective-raft", {**tiny, "gru_levels": 1}).model)
    config = load_preset("selective-raft", tiny)
    torch.manual_seed(0)
    network = FusionNetwork(config.model).train()
    left, right, gt = (torch.from_numpy(a) for a in random_dot_pair(32, 64, 3))
    left, right = (t.permute(2, 0, 1)[None].float() for t in (left, right))
    norms = [m for m in network.modules() if isinstance(m, torch.nn.BatchNorm2d)]
    before = [m.running_mean.clone() for m in norms]
    out = network(left, right, iters=3)
    assert out.stereo_only and len(out.stereo_iterates) == 3 and out.disparity.shape == (1, 1, 32, 64)
    assert norms and all(torch.equal(m.running_mean, b) for m, b in zip(norms, before, strict=True))
    loss, _ = fusion_loss(out, gt[None, None], torch.ones(1, 1, 32, 64, dtype=torch.bool), config.train)
    loss.backward()
    assert all(p.grad is not None for p in network.parameters())  # every module of the network takes part
