"""The fusion network's stages, presets, loss, gradients, determinism, checkpoints and predictor
on the lite preset (weight-free backends, tiny tensors)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from model.checkpoint import load_checkpoint, load_network, save_checkpoint  # noqa: E402
from model.confidence import ConfidenceHead  # noqa: E402
from model.fusion import GlobalFusion, blend, refine_affine  # noqa: E402
from model.losses import confidence_target, confidence_terms, focal_terms, fusion_loss, sequence_gamma  # noqa: E402
from model.network import FusionNetwork, FusionOutput  # noqa: E402
from model.predictor import Predictor  # noqa: E402
from model.presets import PRESETS, Config, load_preset  # noqa: E402
from model.stereo.corr import CorrPyramid1D  # noqa: E402
from model.stereo.upsample import convex_upsample  # noqa: E402
from tests.model_pairs import random_dot_pair  # noqa: E402

SMALL = {"hidden_dims": [16, 16, 16], "motion_dim": 16, "feature_dim": 32, "vlm_dim": 32, "flow_dim": 32,
         "confidence_dim": 16, "fusion_dim": 16, "vlm_eye_weights": "random"}
# The paper's design where a test is about it (lite turns on the gate, cross-entropy and a deterministic flow).
PAPER_DESIGN = {"fusion_gate": False, "confidence_loss": "focal", "flow_noise": True, "confidence_target": "threshold",
                "confidence_sees_mono": False, "fusion_mask_from_stereo": False}


def _tensors(height: int = 64, width: int = 128, d: float = 4.0, seed: int = 0):
    left, right, gt = random_dot_pair(height, width, d, seed)
    to = lambda a: torch.from_numpy(a).permute(2, 0, 1)[None].float()
    mono = torch.from_numpy(gt)[None, None] + torch.linspace(0, 1, width).view(1, 1, 1, -1)
    return to(left), to(right), mono, torch.from_numpy(gt)[None, None]


def test_presets_load_override_and_round_trip() -> None:
    assert PRESETS == ("lite", "paper")
    paper = load_preset("paper")
    assert paper.model.n_downsample == 2 and paper.model.hidden_dims == (128, 128, 128)
    assert (paper.model.corr_levels, paper.model.corr_radius) == (4, 4)
    assert paper.train.crop == (320, 736) and paper.train.lr == 2e-4 and paper.train.max_disparity == 700
    lite = load_preset("lite", {"train.steps": 7, "use_vlm": False, "crop": [64, 96]})
    assert lite.train.steps == 7 and not lite.model.use_vlm and lite.train.crop == (64, 96)
    assert max(lite.model.hidden_dims) <= 64 and lite.model.n_downsample == 3
    assert Config.from_dict(lite.to_dict()) == lite
    assert load_preset("lite", {"steps": "9", "use_vlm": "false", "lr": "1e-3"}).train.lr == 1e-3
    for overrides, message in (({"nope": 1}, "unknown config key 'nope'"), ({"train.steps": "x"}, "train.steps"),
                               ({"fusion_rule": "avg"}, "model.fusion_rule"), ({"crop": [1]}, "train.crop")):
        with pytest.raises(ValueError, match=message):
            load_preset("lite", overrides)
    with pytest.raises(ValueError, match="unknown model preset"):
        load_preset("huge")


def test_correlation_peaks_at_the_true_disparity_and_upsampling_scales_values() -> None:
    torch.manual_seed(0)
    features = torch.randn(1, 256, 4, 32)
    right = torch.roll(features, shifts=-3, dims=3)  # left x matches right x − 3
    corr = CorrPyramid1D(features, right, levels=2, radius=4)
    looked = corr.lookup(torch.zeros(1, 1, 4, 32))
    assert looked.shape == (1, corr.channels, 4, 32) == (1, 18, 4, 32)
    # level 0 window is offsets −4…4 around x − 0: the peak sits at offset −3 (index 1)
    assert (looked[0, :9, :, 8:].argmax(dim=0) == 1).all()
    at_truth = corr.lookup(torch.full((1, 1, 4, 32), 3.0))
    assert (at_truth[0, :9, :, 8:].argmax(dim=0) == 4).all()
    disparity = torch.full((1, 1, 3, 5), 2.0)
    up = convex_upsample(disparity, torch.randn(1, 9 * 16, 3, 5), 4)
    # values × factor everywhere: past the border the 3×3 window repeats the edge value
    assert up.shape == (1, 1, 12, 20) and torch.allclose(up, torch.full((1, 1, 12, 20), 8.0))


def test_every_stage_has_its_shape_and_units() -> None:
    config = load_preset("lite", SMALL)
    torch.manual_seed(0)
    network = FusionNetwork(config.model).train()
    assert network.size_multiple == 32
    left, right, mono, _ = _tensors()
    out = network(left, right, mono, iters=3, noise=torch.Generator().manual_seed(0))
    assert isinstance(out, FusionOutput)
    for full in (out.disparity, out.stereo, out.mono_aligned, out.mono, *out.stereo_iterates):
        assert full.shape == (1, 1, 64, 128) and torch.isfinite(full).all()
    assert len(out.stereo_iterates) == 3 and out.stereo is out.stereo_iterates[-1]
    assert out.confidence.shape == out.confidence_logits.shape == (1, 1, 8, 16)
    assert ((out.confidence > 0) & (out.confidence < 1)).all()
    assert torch.allclose(out.confidence, torch.sigmoid(out.confidence_logits))
    network.eval()
    with torch.no_grad():
        evaluated = network(left, right, mono, iters=3, noise=torch.Generator().manual_seed(0))
    assert len(evaluated.stereo_iterates) == 1
    with pytest.raises(ValueError, match="multiples of 32"):
        network(left[..., :100], right[..., :100], None, iters=2)
    with pytest.raises(ValueError, match="needs mono"):
        network(left, right, None, iters=2)
    with pytest.raises(ValueError, match="B×1×H×W"):
        network(left, right, mono[..., :64], iters=2)


def test_refining_affine_parameters_pools_confident_neighbours() -> None:
    params = torch.tensor([[[[1.0, 9.0, 3.0, 5.0]]]])
    confidence = torch.tensor([[[[0.9, 0.1, 0.6, 0.2]]]])
    local = refine_affine(params, confidence, kernel=3)
    # pixel 1: neighbours 0 and 2 are confident, weighted 0.9 and 0.6; pixel 3: only pixel 2
    assert torch.allclose(local, torch.tensor([[[[1.0, (0.9 * 1 + 0.6 * 3) / 1.5, 3.0, 3.0]]]]))
    glob = refine_affine(params, confidence, kernel=None)
    mean = (0.9 * 1 + 0.6 * 3) / 1.5
    assert torch.allclose(glob, torch.tensor([[[[1.0, mean, 3.0, mean]]]]))


@pytest.mark.parametrize(("target", "expected"), [("threshold", [1.0, 0.0, 0.0]), ("closer", [1.0, 1.0, 1.0]),
                                                  ("closer-fit", [1.0, 1.0, 0.0])])
def test_the_confidence_target_trusts_the_stereo_where_it_is_closer_than_the_mono(target: str,
                                                                                 expected: list[float]) -> None:
    """Three 2×2 blocks (one confidence pixel each): the stereo misses by 1, 2, 2 px; the aligned mono
    copies the stereo (its per-pixel affine can), the mono fitted per image misses by 3, 3, 1 px. The
    authors' threshold trusts the first block alone; "closer" all three, since the copy is never closer;
    "closer-fit" the first two, as the fitted mono is better on the third."""
    cfg = load_preset("lite", {**PAPER_DESIGN, "confidence_target": target}).train
    gt = torch.full((1, 1, 2, 6), 10.0)
    stereo = gt + torch.tensor([1.0, 1.0, 2.0, 2.0, 2.0, 2.0])
    fitted = gt - torch.tensor([3.0, 3.0, 3.0, 3.0, 1.0, 1.0])
    valid = torch.ones_like(gt, dtype=torch.bool)
    logits = torch.full((1, 1, 1, 3), 2.0)
    out = FusionOutput(gt, [stereo], stereo, stereo.clone(), torch.sigmoid(logits), logits, gt, mono_fitted=fitted)
    _, parts = fusion_loss(out, gt, valid, cfg)
    focal = focal_terms(logits, torch.tensor(expected).view(1, 1, 1, 3), cfg.focal_alpha, cfg.focal_gamma)
    assert math.isclose(parts["confidence"], float(focal.sum()) / (12 * 3 / 12), rel_tol=1e-5)
    low, low_valid = confidence_target((gt - stereo).abs(), valid, (1, 3), (gt - fitted).abs())
    assert low.flatten().tolist() == [1.0, 1.0, 0.0] and bool(low_valid.all())
    assert load_preset("paper").train.confidence_target == "threshold"  # the authors' target stays the paper's


def test_the_fitted_target_needs_the_fitted_mono() -> None:
    cfg = load_preset("lite", {**PAPER_DESIGN, "confidence_target": "closer-fit"}).train
    gt = torch.full((1, 1, 2, 2), 10.0)
    logits = torch.zeros(1, 1, 1, 1)
    out = FusionOutput(gt, [gt], gt, gt, torch.sigmoid(logits), logits, gt)
    with pytest.raises(ValueError, match="fitted mono"):
        fusion_loss(out, gt, torch.ones_like(gt, dtype=torch.bool), cfg)


def test_the_loss_equals_a_hand_computation() -> None:
    cfg = load_preset("lite", PAPER_DESIGN).train
    gt = torch.tensor([[[[1.0, 2.0, 800.0, 4.0]] * 2]])  # 1×1×2×4; 800 > max_disparity: ignored
    valid = torch.ones_like(gt, dtype=torch.bool)
    valid[0, 0, 1, 3] = False
    iterates = [gt + 2.0, gt + 1.0]
    logits = torch.tensor([[[[0.5, -1.0]]]])  # 1×1×1×2
    out = FusionOutput(gt + 0.5, iterates, iterates[-1], gt - 3.0, torch.sigmoid(logits), logits, gt)
    loss, parts = fusion_loss(out, gt, valid, cfg)
    n = 5  # 8 pixels − 2 over the maximum − 1 invalid
    g = cfg.loss_gamma ** (15 / 1)
    stereo = g**3 * 2.0 + g**2 * 1.0
    expected_d = stereo + g * 3.0 + 0.5
    # confidence targets: |gt − D_s^T| = 1 < 1.25 on valid pixels → 1 where the low-res pixel is valid
    bce = torch.nn.functional.binary_cross_entropy_with_logits(logits, torch.ones_like(logits), reduction="none")
    focal = cfg.focal_alpha * (1 - torch.exp(-bce)) ** cfg.focal_gamma * bce
    # low-res pixel 0 covers columns 0–1 (all valid), pixel 1 columns 2–3 (2 over max + 1 invalid → invalid)
    expected_c = float(focal[0, 0, 0, 0]) / (n * 2 / 8)
    assert math.isclose(parts["final"], 0.5, rel_tol=1e-6)
    assert math.isclose(parts["stereo"], stereo, rel_tol=1e-5)
    assert math.isclose(parts["confidence"], expected_c, rel_tol=1e-5)
    assert math.isclose(float(loss), expected_d + expected_c, rel_tol=1e-5)
    halved, _ = fusion_loss(out, gt, valid, cfg, valid_total=torch.tensor(2 * n))
    assert math.isclose(float(halved), float(loss) / 2, rel_tol=1e-6)
    assert sequence_gamma(0.9, 1) == 0.9 and math.isclose(sequence_gamma(0.9, 16), 0.9)


def test_the_gate_takes_stereo_or_mono_whole_with_the_blends_gradient() -> None:
    """Stereo 10 px, mono 4 px: the soft blend mixes them, the gate takes one whole by c ≥ 0.5; the
    gradients reaching c (straight-through) are the soft blend's, D_s − D̃_m per pixel, and each branch
    gets gradient only where it was taken."""
    soft_c = torch.tensor([[[[0.2, 0.5, 0.9]]]], requires_grad=True)
    hard_c = soft_c.detach().clone().requires_grad_(True)
    branches = []
    for c, gate in ((soft_c, False), (hard_c, True)):
        stereo = torch.full((1, 1, 1, 3), 10.0, requires_grad=True)
        aligned = torch.full((1, 1, 1, 3), 4.0, requires_grad=True)
        out = blend(stereo, aligned, c, gate=gate)
        out.sum().backward()
        branches.append((out.detach(), stereo.grad.flatten().tolist(), aligned.grad.flatten().tolist()))
    assert torch.allclose(branches[0][0], torch.tensor([[[[5.2, 7.0, 9.4]]]]))
    assert branches[1][0].flatten().tolist() == [4.0, 10.0, 10.0]
    assert torch.equal(soft_c.grad, hard_c.grad) and torch.allclose(hard_c.grad, torch.full_like(hard_c, 6.0))
    assert branches[1][1:] == ([0.0, 1.0, 1.0], [1.0, 0.0, 0.0])
    assert branches[0][1] == pytest.approx([0.2, 0.5, 0.9])


def test_the_network_gates_only_when_asked() -> None:
    """The released rule upsamples the blend itself: with fusion_gate each low-resolution pixel is the
    stereo's or the aligned mono's, as the confidence says; without it, a mix."""
    generator = torch.Generator().manual_seed(0)
    mono, stereo = torch.rand(1, 1, 4, 6, generator=generator), 5 + 10 * torch.rand(1, 1, 4, 6, generator=generator)
    confidence = torch.rand(1, 1, 4, 6, generator=generator)
    hidden, mask = torch.zeros(1, 16, 4, 6), torch.randn(1, 9 * 64, 4, 6, generator=generator)
    for gate in (True, False):
        config = load_preset("lite", {**SMALL, "fusion_rule": "released", "fusion_gate": gate}).model
        torch.manual_seed(0)
        result = GlobalFusion(config, 16)(mono, stereo, confidence, hidden, mask)
        aligned = result.scale * mono + result.shift
        mixed = torch.where(confidence >= 0.5, stereo, aligned) if gate else confidence * stereo + (1 - confidence) * aligned
        assert torch.allclose(result.disparity, convex_upsample(mixed, mask, 8, config.upsample_border), atol=1e-4), gate


def test_the_fused_upsampling_starts_as_the_stereo_branchs() -> None:
    """With fusion_mask_from_stereo, a fully confident gate and no residual give exactly the stereo map
    upsampled with the stereo branch's own mask; a fresh upsampler (the paper's) does not."""
    generator = torch.Generator().manual_seed(0)
    mono, stereo = torch.rand(1, 1, 4, 6, generator=generator), 5 + 10 * torch.rand(1, 1, 4, 6, generator=generator)
    hidden, mask = torch.randn(1, 16, 4, 6, generator=generator), torch.randn(1, 9 * 64, 4, 6, generator=generator)
    confident = torch.ones(1, 1, 4, 6)
    expected = convex_upsample(stereo, mask, 8, "edge")
    errors = {}
    for from_stereo in (True, False):
        config = load_preset("lite", {**SMALL, "fusion_mask_from_stereo": from_stereo}).model
        torch.manual_seed(0)
        fusion = GlobalFusion(config, 16)
        torch.nn.init.zeros_(fusion.residual.weight)
        if from_stereo:
            torch.nn.init.zeros_(fusion.mask.net[-1].weight)
        with torch.no_grad():
            errors[from_stereo] = float((fusion(mono, stereo, confident, hidden, mask).disparity - expected).abs().max())
    assert errors[True] < 1e-4 < errors[False]


def test_the_confidence_sees_the_mono_only_when_asked() -> None:
    """The no-VLM confidence head reads the stereo, the mono fitted to it and their difference
    (confidence_sees_mono): a fitted mono that disagrees changes its logits; without the option it never
    reads them, and with it a missing fitted mono is an error, not a silent zero."""
    generator = torch.Generator().manual_seed(0)
    cost, features = torch.randn(1, 36, 4, 6, generator=generator), torch.randn(1, 32, 4, 6, generator=generator)
    stereo = 5 + 10 * torch.rand(1, 1, 4, 6, generator=generator)
    logits = {}
    for sees in (True, False):
        config = load_preset("lite", {**SMALL, "use_vlm": False, "confidence_sees_mono": sees}).model
        torch.manual_seed(0)
        head = ConfidenceHead(config, 0)
        with torch.no_grad():
            logits[sees] = [head(cost, features=features, disparities=(stereo, fitted))
                            for fitted in (stereo.clone(), stereo.flip(-1))]
    assert not torch.allclose(*logits[True]) and torch.equal(*logits[False])
    with pytest.raises(ValueError, match="fitted mono"):
        head = ConfidenceHead(load_preset("lite", {**SMALL, "use_vlm": False}).model, 0)
        head(cost, features=features)


def test_the_cross_entropy_confidence_loss_is_the_weighted_bce() -> None:
    """Same batch as the hand computation's below: with confidence_loss "ce" the term is ce_weight·L_b
    over the valid low-resolution pixel, whose gradient at c ≈ 0.84 is ~55× the focal term's."""
    cfg = load_preset("lite", {"confidence_loss": "ce", "ce_weight": 3.0}).train
    gt = torch.tensor([[[[1.0, 2.0, 800.0, 4.0]] * 2]])
    valid = torch.ones_like(gt, dtype=torch.bool)
    valid[0, 0, 1, 3] = False
    logits = torch.tensor([[[[math.log(0.84 / 0.16), -1.0]]]])
    out = FusionOutput(gt + 0.5, [gt + 1.0], gt + 1.0, gt - 3.0, torch.sigmoid(logits), logits, gt,
                       mono_fitted=gt - 3.0)
    _, parts = fusion_loss(out, gt, valid, cfg)
    bce = -math.log(0.84)
    assert math.isclose(parts["confidence"], 3.0 * bce / (5 * 2 / 8), rel_tol=1e-5)
    pushes = []
    for loss in ("ce", "focal"):
        logit = logits[..., :1].clone().requires_grad_(True)
        cfg = load_preset("lite", {"confidence_loss": loss, "ce_weight": 1.0}).train
        confidence_terms(logit, torch.ones_like(logit), cfg).sum().backward()
        pushes.append(float(logit.grad))
    assert 50 < pushes[0] / pushes[1] < 60
    with pytest.raises(ValueError, match="train.ce_weight"):
        load_preset("lite", {"ce_weight": -1})


def _seeded_outputs(network: FusionNetwork, seeds: tuple[int, ...]) -> list[FusionOutput]:
    """The network's eval outputs on the test pair, one per flow-noise seed."""
    left, right, mono, _ = _tensors()
    with torch.no_grad():
        return [network(left, right, mono, iters=2, noise=torch.Generator().manual_seed(s)) for s in seeds]


def test_a_deterministic_flow_ignores_the_noise() -> None:
    config = load_preset("lite", {**SMALL, "flow_noise": False})
    torch.manual_seed(0)
    network = FusionNetwork(config.model).eval()
    first, second = (out.confidence for out in _seeded_outputs(network, (1, 2)))
    assert torch.equal(first, second)
    noisy = FusionNetwork(load_preset("lite", {**SMALL, "flow_noise": True}).model).eval()
    noisy.load_trainable_state_dict(network.trainable_state_dict())
    first, second = (out.confidence for out in _seeded_outputs(noisy, (1, 2)))
    assert not torch.equal(first, second)


@pytest.mark.parametrize("overrides", [{}, {"use_vlm": False}, {"confidence_image_features": False},
                                       {"fusion_rule": "released"},
                                       {"fusion_gate": True, "flow_noise": False, "confidence_loss": "ce"},
                                       {"confidence_sees_mono": False, "fusion_mask_from_stereo": False},
                                       {"vlm_eye": "efficientnet-lite0", "vlm_eye_weights": "random"}])
def test_gradients_reach_every_trainable_parameter(overrides: dict) -> None:
    config = load_preset("lite", {**SMALL, **overrides})
    torch.manual_seed(0)
    network = FusionNetwork(config.model).train()
    left, right, mono, gt = _tensors()
    out = network(left, right, mono, iters=2, noise=torch.Generator().manual_seed(1))
    loss, _ = fusion_loss(out, gt, torch.ones_like(gt, dtype=torch.bool), config.train)
    loss.backward()
    trained = [(n, p) for n, p in network.named_parameters() if p.requires_grad]
    assert {n.split(".")[1] for n, p in network.named_parameters() if not p.requires_grad} <= {"backbone"}
    missing = [n for n, p in trained if p.grad is None or not p.grad.abs().sum() > 0]
    assert missing == []
    assert network.frozen_state_hashes() == {}


def test_the_same_seed_gives_the_same_output() -> None:
    config = load_preset("lite", {**SMALL, "flow_noise": True})
    torch.manual_seed(0)
    network = FusionNetwork(config.model).eval()
    left, right, mono, _ = _tensors()
    runs = _seeded_outputs(network, (5, 5, 6))
    assert torch.equal(runs[0].confidence, runs[1].confidence) and torch.equal(runs[0].disparity, runs[1].disparity)
    assert not torch.equal(runs[0].confidence, runs[2].confidence)
    batch = torch.cat([left, left]), torch.cat([right, right]), torch.cat([mono, mono])
    with torch.no_grad():
        per_sample = network(*batch, iters=2, noise=[torch.Generator().manual_seed(5), torch.Generator().manual_seed(5)])
    assert torch.allclose(per_sample.confidence[1:], runs[0].confidence, atol=1e-5)


def test_checkpoint_round_trip_and_predictor(tmp_path: Path) -> None:
    config = load_preset("lite", SMALL)
    torch.manual_seed(0)
    network = FusionNetwork(config.model)
    path = tmp_path / "run.pt"
    save_checkpoint(path, network, config, step=3, extra={"note": "x"})
    payload = load_checkpoint(path)
    assert payload["step"] == 3 and payload["extra"] == {"note": "x"} and payload["config"] == config.to_dict()
    loaded, loaded_config, _ = load_network(path)
    assert loaded_config == config and not loaded.training
    left, right, gt = random_dot_pair(50, 90, 3)  # odd size: padded and cropped back
    mono = gt[::2, ::2] + 1
    first = Predictor(loaded, loaded_config).predict(left, right, mono, iters=2, seed=1)
    again = Predictor(network, config).predict(left, right, mono, iters=2, seed=1)
    for name in ("disparity", "stereo", "mono_align", "confidence"):
        value = getattr(first, name)
        assert value.shape == (50, 90) and value.dtype == np.float32 and np.isfinite(value).all()
        assert np.allclose(value, getattr(again, name), atol=1e-5)
    predictor = Predictor(loaded, loaded_config)
    with pytest.raises(ValueError, match="differ in size"):
        predictor.predict(left, right[:40])
    with pytest.raises(ValueError, match="RGB uint8"):
        predictor.predict(left[..., 0], right)
    with pytest.raises(ValueError, match="needs mono"):
        predictor.predict(left, right)
    (tmp_path / "junk.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match="not a readable checkpoint"):
        load_checkpoint(tmp_path / "junk.pt")
    with pytest.raises(ValueError, match="does not exist"):
        load_checkpoint(tmp_path / "missing.pt")


@pytest.mark.slow
def test_150_steps_on_one_pair_cut_its_epe_fivefold() -> None:
    config = load_preset("lite", {**SMALL, "flow_steps": 1, "flow_depth": 1, "hidden_dims": [8, 8, 8],
                                  "motion_dim": 8, "feature_dim": 16, "encoder_dims": [8, 16, 16]})
    torch.manual_seed(0)
    network = FusionNetwork(config.model).train()
    left, right, mono, gt = _tensors(32, 64, 3.0)
    valid = torch.ones_like(gt, dtype=torch.bool)
    optimizer = torch.optim.AdamW(network.trainable_parameters(), lr=2e-3)

    def epe() -> float:
        with torch.no_grad():
            return float((network(left, right, mono, iters=3, noise=torch.Generator()).disparity - gt).abs().mean())

    before = epe()
    for step in range(150):
        out = network(left, right, mono, iters=3, noise=torch.Generator().manual_seed(step))
        loss, _ = fusion_loss(out, gt, valid, config.train)
        optimizer.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(network.parameters(), 1.0)
        optimizer.step()
    assert epe() * 5 <= before
