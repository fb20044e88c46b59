"""The ``paper`` preset's real backbones, loaded by the real code from tiny random checkpoints:
Depth Anything V2 (frozen, DPT features) and Qwen2-VL (frozen, LoRA on its last layer).
Forward + backward, no gradient into frozen weights, and a checkpoint round trip that stores
no backbone weights and refuses a changed backbone."""

from __future__ import annotations

from pathlib import Path

import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("transformers")
pytest.importorskip("peft")

from model.checkpoint import load_network, save_checkpoint  # noqa: E402
from model.losses import fusion_loss  # noqa: E402
from model.network import FusionNetwork  # noqa: E402
from model.presets import load_preset  # noqa: E402
from tests.test_depth_backends import _save_tiny as save_tiny_depth_anything  # noqa: E402
from tests.test_vlm_transformers import save_tiny_qwen2_vl  # noqa: E402

TINY = {"encoder_dims": [8, 16, 16], "encoder_blocks": [1, 1, 1], "feature_dim": 32, "hidden_dims": [16, 16, 16],
        "motion_dim": 16, "flow_dim": 32, "flow_heads": 4, "flow_depth": 1, "flow_steps": 2, "confidence_dim": 16,
        "fusion_dim": 16, "mono_input_size": 70, "vlm_max_pixels": 112 * 112}


@pytest.fixture(scope="module")
def backbones(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("paper-backbones")
    return {"mono": save_tiny_depth_anything(root / "da"), "vlm": save_tiny_qwen2_vl(root / "qwen")}


@pytest.mark.slow
def test_paper_preset_trains_lora_and_adapters_but_not_backbones(backbones: dict[str, Path], tmp_path: Path) -> None:
    config = load_preset("paper", {**TINY, "mono_model_path": str(backbones["mono"]),
                                   "vlm_model_path": str(backbones["vlm"])})
    assert config.model.mono_backend == "depth-anything-v2" and config.model.vlm_backend == "qwen2-vl"
    torch.manual_seed(0)
    network = FusionNetwork(config.model).train()
    assert network.size_multiple == 16
    left = torch.rand(1, 3, 64, 96) * 255
    right = torch.roll(left, -2, dims=3)
    out = network(left, right, None, iters=2, noise=torch.Generator().manual_seed(0))  # mono from Depth Anything
    assert out.disparity.shape == out.mono.shape == (1, 1, 64, 96)
    assert out.confidence.shape == (1, 1, 16, 24)
    gt = torch.full((1, 1, 64, 96), 2.0)
    loss, _ = fusion_loss(out, gt, torch.ones_like(gt, dtype=torch.bool), config.train)
    loss.backward()
    frozen = [(n, p) for n, p in network.named_parameters() if n.startswith(("mono.backbone.", "vlm.backbone."))]
    lora = [(n, p) for n, p in frozen if "lora_" in n]
    assert lora and all(p.requires_grad for _, p in lora)
    assert any(p.grad is not None and p.grad.abs().sum() > 0 for n, p in lora if "lora_A" in n or "lora_B" in n)
    assert all(p.grad is None for n, p in frozen if "lora_" not in n)
    trainable = [n for n, p in network.named_parameters() if p.requires_grad and not n.startswith(("mono.", "vlm."))]
    assert all(dict(network.named_parameters())[n].grad is not None for n in trainable)

    hashes = network.frozen_state_hashes()
    assert set(hashes) == {"mono", "vlm"}
    path = tmp_path / "paper.pt"
    save_checkpoint(path, network, config, step=1)
    state = torch.load(path, weights_only=False)["state"]
    assert not any(k.startswith(("mono.backbone.", "vlm.backbone.")) and "lora_" not in k for k in state)
    loaded, _, _ = load_network(path)
    assert loaded.frozen_state_hashes() == hashes
    # a different backbone in the same directory is refused, naming it
    from transformers import DepthAnythingForDepthEstimation

    changed = DepthAnythingForDepthEstimation.from_pretrained(backbones["mono"])
    with torch.no_grad():
        changed.head.conv3.bias += 1.0
    changed.save_pretrained(backbones["mono"])
    with pytest.raises(ValueError, match=f"mono backbone in {backbones['mono']}"):
        load_network(path)
