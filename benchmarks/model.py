"""The fusion model's budget: the ``lite`` preset on one 1920×1080 pair, timed in a
process of its own (peak resident memory: that child's own VmHWM), beside OpenCV SGBM
on the same pair in the same run and the baselines' own networks (RAFT-Stereo's ``raft-stereo``,
Selective-RAFT's ``selective-raft``, Selective-IGEV's ``selective-igev`` and MoCha-Stereo's ``mocha-stereo``
presets at their published sizes and 32 test iterations, what an imported checkpoint runs: :data:`BASELINES`);
parameters per module; training steps/s at the lite crop. The lite VLM's EfficientNet-Lite0 eye (``vlm_eye``, lite's
default): lite on the same pair with its VLM's patches instead, the eye's own stride-16 features at
the size lite's VLM sees, and its parameters.

The networks are randomly initialised: speed and memory do not depend on the weights.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from collections.abc import Collection
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from dataset.synthetic import render_video

if TYPE_CHECKING:
    import torch

    from model.efficientnet_lite import EfficientNetLite0

# Lite budgets on this class of 2-core machine.
BUDGET_S, BUDGET_MB = 3.0, 3072.0
# lite's VLM with its image tokens from the EfficientNet-Lite0 eye (its random build: same size, no package needed)
EYE = {"vlm_eye": "efficientnet-lite0", "vlm_eye_weights": "random"}
# lite's VLM before it had an eye: image tokens from patches it learns itself
PATCHES = {"vlm_eye": "patches"}
# The baselines timed beside lite, by their keys in the JSON: the preset each runs.
BASELINES = {"raft_stereo": "raft-stereo", "selective_raft": "selective-raft", "selective_igev": "selective-igev",
             "mocha_stereo": "mocha-stereo"}


def _pair(width: int, height: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    frame = render_video(0, n_frames=1, width=width, height=height).frames[0]
    return frame.left, frame.right, frame.mono_disparity.astype(np.float32)


def sgbm_seconds(left: np.ndarray, right: np.ndarray, repeats: int) -> float:
    """Best wall time of OpenCV semi-global block matching (128 disparities, 5×5 blocks)."""
    matcher = cv2.StereoSGBM_create(minDisparity=0, numDisparities=128, blockSize=5, P1=8 * 3 * 25,
                                    P2=32 * 3 * 25, mode=cv2.STEREO_SGBM_MODE_SGBM)
    grey = [cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) for image in (left, right)]
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        matcher.compute(*grey)
        times.append(time.perf_counter() - started)
    return min(times)


def peak_mb() -> float:
    """This process's peak resident memory, MB: the VmHWM of its own address space. (getrusage's
    ru_maxrss would not do: on Linux a child's carries its parent's peak across fork and exec.)"""
    with open("/proc/self/status") as handle:
        for line in handle:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    raise RuntimeError("/proc/self/status has no VmHWM line")


def _child(pair_file: str, repeats: int, preset: str = "lite", overrides: dict[str, Any] | None = None) -> None:
    """Runs in the subprocess: ``preset``'s inference on the saved pair, prints one JSON line."""
    import torch

    from model.network import FusionNetwork
    from model.predictor import Predictor
    from model.presets import load_preset
    from model.vlm import EyeVlm

    data = np.load(pair_file)
    config = load_preset(preset, overrides)
    torch.manual_seed(0)
    network = FusionNetwork(config.model)
    shown: list[torch.Size] = []  # the left image's size as the predictor gives it to the eye
    if isinstance(network.vlm, EyeVlm):
        network.vlm.register_forward_pre_hook(lambda _module, args: shown.append(args[0].shape))
    predictor = Predictor(network, config)
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        predictor.predict(data["left"], data["right"], data["mono"])
        times.append(time.perf_counter() - started)
    result = {"seconds": min(times), "peak_mb": peak_mb(), "threads": torch.get_num_threads(),
              "iters": config.train.test_iters}
    if isinstance(network.vlm, EyeVlm):
        result["eye_s"] = eye_seconds(network.vlm.backbone, torch.rand(shown[-1]) * 2 - 1, repeats)
        result["eye_input"] = list(shown[-1][2:])
    print(json.dumps(result))


def eye_seconds(eye: EfficientNetLite0, image: torch.Tensor, repeats: int) -> float:
    """Best wall time of the EfficientNet-Lite0 ``eye``'s stride-16 features of ``image`` (B×3×H×W in [−1, 1])."""
    import torch

    from model.vlm import EYE_STRIDE

    times = []
    with torch.inference_mode():
        for _ in range(repeats):
            started = time.perf_counter()
            eye.features(image, stride=EYE_STRIDE)
            times.append(time.perf_counter() - started)
    return min(times)


def eye_parameters() -> dict[str, int]:
    """The eye's parameters: ``frozen``, all of EfficientNet-Lite0 (the package's state dict);
    ``frozen_used``, those its stride-16 features run; ``vlm_trainable``, the lite VLM's with the eye."""
    from model.efficientnet_lite import load_efficientnet_lite0
    from model.vlm import EYE_STRIDE

    eye = load_efficientnet_lite0("random")
    return {"frozen": eye.parameter_count(), "frozen_used": eye.parameter_count(EYE_STRIDE),
            "vlm_trainable": parameters_per_module(EYE)["vlm"]}


def _timed(pair_file: Path, repeats: int, preset: str, overrides: dict[str, Any] | None = None) -> dict[str, Any]:
    """``preset`` (with ``overrides``) on the pair in a process of its own: {"seconds", "peak_mb",
    "threads", "iters"}, and with the eye on {"eye_s", "eye_input"}."""
    code = (f"from benchmarks.model import _child; "
            f"_child({str(pair_file)!r}, {repeats}, {preset!r}, {overrides!r})")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"the {preset} {overrides or ''} benchmark process failed: "
                           f"{done.stderr.strip().splitlines()[-1:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def parameters_per_module(overrides: dict[str, Any] | None = None) -> dict[str, int]:
    """Trainable parameter counts of the lite network's top-level modules."""
    from model.network import FusionNetwork
    from model.presets import load_preset

    network = FusionNetwork(load_preset("lite", overrides).model)
    counts = {name: sum(p.numel() for p in module.parameters() if p.requires_grad)
              for name, module in network.named_children()}
    counts["total"] = sum(counts.values())
    return counts


def training_steps_per_s(steps: int) -> float:
    """Forward + loss + backward + AdamW steps per second at the lite crop and batch size."""
    import torch

    from model.losses import fusion_loss
    from model.network import FusionNetwork
    from model.presets import load_preset

    config = load_preset("lite")
    height, width = config.train.crop
    torch.manual_seed(0)
    network = FusionNetwork(config.model).train()
    optimizer = torch.optim.AdamW(network.trainable_parameters(), lr=config.train.lr)
    batch = config.train.batch_size
    left = torch.rand(batch, 3, height, width) * 255
    right, mono = torch.roll(left, -4, dims=3), torch.rand(batch, 1, height, width)
    gt, valid = torch.full((batch, 1, height, width), 4.0), torch.ones(batch, 1, height, width, dtype=torch.bool)
    started = 0.0
    for step in range(steps + 1):
        if step == 1:  # the first step warms up allocations
            started = time.perf_counter()
        out = network(left, right, mono, iters=config.train.train_iters, noise=torch.Generator().manual_seed(step))
        loss, _ = fusion_loss(out, gt, valid, config.train)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    return steps / (time.perf_counter() - started)


def run_model_bench(repeats: int = 2, train_steps: int = 3, skip: Collection[str] = ()) -> dict[str, Any]:
    """The JSON of ``illusion-studio bench model``: every baseline's network of :data:`BASELINES` timed
    too (once each: minutes on a 2-core CPU) but those whose keys ``skip`` names."""
    unknown = set(skip) - set(BASELINES)
    if unknown:
        raise ValueError(f"unknown baseline(s) {', '.join(sorted(unknown))}; choose from {', '.join(BASELINES)}")
    left, right, mono = _pair(1920, 1080)
    with tempfile.TemporaryDirectory() as tmp:
        pair_file = Path(tmp) / "pair.npz"
        np.savez(pair_file, left=left, right=right, mono=mono)
        child = _timed(pair_file, repeats, "lite")  # as shipped: the eye, its package's weights
        patches = _timed(pair_file, repeats, "lite", PATCHES)
        baselines = {key: _timed(pair_file, 1, preset) for key, preset in BASELINES.items() if key not in skip}
    with open("/proc/loadavg") as handle:
        load = float(handle.read().split()[0])
    return {
        "lite_1080p_s": round(child["seconds"], 3),
        "lite_1080p_peak_mb": round(child["peak_mb"], 1),
        "lite_patches_1080p_s": round(patches["seconds"], 3),
        "lite_patches_1080p_peak_mb": round(patches["peak_mb"], 1),
        "eye_features_s": round(child["eye_s"], 3),
        "eye_input": child["eye_input"],
        "eye_parameters": eye_parameters(),
        "sgbm_1080p_s": round(sgbm_seconds(left, right, repeats), 3),
        **{field: value for key, timed in baselines.items() for field, value in (
            (f"{key}_1080p_s", round(timed["seconds"], 3)), (f"{key}_1080p_peak_mb", round(timed["peak_mb"], 1)),
            (f"{key}_iters", timed["iters"]))},
        "lite_budget_s": BUDGET_S,
        "lite_budget_mb": BUDGET_MB,
        "lite_within_budget": child["seconds"] <= BUDGET_S and child["peak_mb"] <= BUDGET_MB,
        "torch_threads": child["threads"],
        "load_average_1min": load,
        "parameters": parameters_per_module(),
        "train_steps_per_s": round(training_steps_per_s(train_steps), 3),
    }
