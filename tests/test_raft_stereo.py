"""The `raft-stereo` network: its preset and config rules, what its options build,
zero-padded convex upsampling, training with frozen batch norm, its memory figures, and lite/paper
left as they were."""

from __future__ import annotations

import pytest

torch = pytest.importorskip("torch")

from model.losses import fusion_loss  # noqa: E402
from model.network import FusionNetwork  # noqa: E402
from model.presets import ALL_PRESETS, PRESETS, Config, load_preset  # noqa: E402
from model.runs.capacity import estimate_memory  # noqa: E402
from model.stereo.upsample import convex_upsample  # noqa: E402
from tests.model_pairs import random_dot_pair  # noqa: E402

# A small RAFT-Stereo (its motion encoder and heads keep their fixed widths).
TINY = {"encoder_dims": [8, 8, 16], "encoder_blocks": [1, 1, 1], "stem_kernel": 3, "feature_dim": 16,
        "hidden_dims": [16, 16, 16]}


def test_the_preset_loads_and_the_fusion_presets_keep_todays_behaviour() -> None:
    assert PRESETS == ("lite", "paper") and ALL_PRESETS == ("lite", "paper", "raft-stereo")
    raft = load_preset("raft-stereo")
    model = raft.model
    assert (model.architecture, model.n_downsample, model.gru_levels, model.hidden_dims) == ("raft-stereo", 2, 3,
                                                                                             (128, 128, 128))
    assert (model.context_norm, model.upsample_border, model.use_mono, model.use_vlm) == ("batch", "zeros", False, False)
    assert (raft.train.crop, raft.train.train_iters, raft.train.test_iters) == ((320, 720), 22, 32)
    assert model.size_multiple == 16 and model.inference_padding == (32, True)
    assert Config.from_dict(raft.to_dict()) == raft
    for name in PRESETS:
        fusion = load_preset(name).model
        assert (fusion.architecture, fusion.upsample_border, fusion.gru_levels) == ("fusion", "edge", 3)
        assert fusion.inference_padding == (fusion.size_multiple, False)
    # a checkpoint written before these fields existed loads as the fusion network it was
    stored = load_preset("lite").to_dict()
    for field in ("architecture", "context_norm", "gru_levels", "shared_backbone", "slow_fast_gru", "upsample_border"):
        del stored["model"][field]
    assert Config.from_dict(stored) == load_preset("lite")


@pytest.mark.parametrize(("preset", "overrides", "message"), [
    ("lite", {"gru_levels": 2}, "need model.architecture = 'raft-stereo'"),
    ("paper", {"shared_backbone": True}, "need model.architecture = 'raft-stereo'"),
    ("lite", {"slow_fast_gru": True}, "need model.architecture = 'raft-stereo'"),
    ("raft-stereo", {"use_mono": True}, "is stereo only"),
    ("raft-stereo", {"gru_levels": 4}, "model.gru_levels must be 1, 2 or 3"),
    ("raft-stereo", {"context_norm": "layer"}, "model.context_norm must be one of"),
    ("raft-stereo", {"upsample_border": "reflect"}, "model.upsample_border must be one of"),
])
def test_config_rules(preset: str, overrides: dict, message: str) -> None:  # type: ignore[type-arg]
    with pytest.raises(ValueError, match=message):
        load_preset(preset, overrides)


@pytest.mark.parametrize(("overrides", "modules", "absent"), [
    ({}, ["stereo_branch.features", "stereo_branch.cnet.down.1", "stereo_branch.update.grus.2"],
     ["mono", "vlm", "confidence", "fusion", "stereo_branch.match_head"]),
    ({"shared_backbone": True, "n_downsample": 3, "gru_levels": 2, "slow_fast_gru": True},
     ["stereo_branch.match_head", "stereo_branch.cnet.down.0", "stereo_branch.update.grus.1"],
     ["stereo_branch.features", "stereo_branch.cnet.down.1", "stereo_branch.update.grus.2"]),
    ({"gru_levels": 1, "context_norm": "none"}, ["stereo_branch.update.grus.0"],
     ["stereo_branch.cnet.down.0", "stereo_branch.update.grus.1"]),
])
def test_options_build_what_they_name_and_train_with_frozen_batch_norm(overrides: dict, modules: list[str],  # type: ignore[type-arg]
                                                                       absent: list[str]) -> None:
    config = load_preset("raft-stereo", {**TINY, **overrides})
    torch.manual_seed(0)
    network = FusionNetwork(config.model).train()
    names = dict(network.named_modules())
    assert all(name in names for name in modules) and not any(name in names for name in absent)
    height, width = 32, 64  # a multiple of the size multiple (2**(n_downsample + levels − 1))
    assert height % config.model.size_multiple == 0
    left, right, gt = (torch.from_numpy(a) for a in random_dot_pair(height, width, 3))
    left, right = (t.permute(2, 0, 1)[None].float() for t in (left, right))
    norms = [m for m in network.modules() if isinstance(m, torch.nn.BatchNorm2d)]
    before = [m.running_mean.clone() for m in norms]
    out = network(left, right, iters=3)
    assert out.stereo_only and len(out.stereo_iterates) == 3 and out.disparity.shape == (1, 1, height, width)
    assert all(not m.training for m in norms)  # as RAFT-Stereo trains: running statistics stay
    assert all(torch.equal(m.running_mean, b) for m, b in zip(norms, before, strict=True))
    loss, _ = fusion_loss(out, gt[None, None], torch.ones(1, 1, height, width, dtype=torch.bool), config.train)
    loss.backward()
    assert all(p.grad is not None for p in network.parameters())  # DDP: every parameter takes part


def test_zero_padded_upsampling_pulls_the_border_towards_zero_and_edge_does_not() -> None:
    disparity, mask = torch.full((1, 1, 3, 5), 2.0), torch.randn(1, 9 * 16, 3, 5)
    edge, zeros = convex_upsample(disparity, mask, 4, "edge"), convex_upsample(disparity, mask, 4, "zeros")
    assert torch.allclose(edge, torch.full_like(edge, 8.0))
    assert torch.allclose(zeros[..., 4:-4, 4:-4], edge[..., 4:-4, 4:-4])  # inside: the same
    assert (zeros[..., 0, :] < 8.0 - 1e-3).all() and (zeros[..., :, -1] < 8.0 - 1e-3).all()


# The trainer's peak MB (one rank, CPU) at (H, W, iterations), measured on the 2-core development
# machine with `run_memory_bench("raft-stereo", …)` (/work/notes/raft.md): what model/runs/capacity.py's figures fit.
MEASURED = {(128, 256, 4): 1403.7, (128, 256, 8): 1476.9, (192, 320, 8): 2261.1, (256, 384, 8): 2982.2,
            (256, 384, 12): 3287.8}


def test_memory_estimates_follow_raft_stereos_measured_peaks_not_lites() -> None:
    for (height, width, iters), peak in MEASURED.items():
        config = load_preset("raft-stereo", {"crop": [height, width], "train_iters": iters, "batch_size": 1})
        assert abs(estimate_memory(config, nproc=1, device="cpu").per_rank_mb - peak) <= 100
    raft = load_preset("raft-stereo")
    as_lite = load_preset("lite", {"crop": list(raft.train.crop), "train_iters": raft.train.train_iters})
    for device in ("cpu", "cuda"):  # a GPU borrows the preset's CPU figures until it has its own
        ratio = (estimate_memory(raft, nproc=1, device=device).per_rank_mb
                 / estimate_memory(as_lite, nproc=1, device=device).per_rank_mb)
        assert ratio > 5
