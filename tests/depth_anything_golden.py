"""Weights in the layout of Depth Anything V2's original ``.pth`` files, regenerated from a seed.

The golden fixture (tests/fixtures/depth_anything/) stores the original model's key/shape list and a
seed rather than 100 MB of weights; :func:`original_state` turns them back into the state dict the
fixture's reference output was computed with. Scales keep the untrained network's output varied and
mostly positive (its last activation is a ReLU): layers kaiming-like (std √(1/fan-in)), norm scales
near 1, layer scales near 0.1, position embeddings of unit-ish size (so that how they are
interpolated shows in the output), and a positive bias on the last convolution.

Only torch is needed: the project holds none of Depth Anything V2's code.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

FIXTURES = Path(__file__).parent / "fixtures" / "depth_anything"
LAST_BIAS = 1.0  # output_conv2.2's: keeps most of the untrained output above the final ReLU's zero


def original_state(keys: Sequence[tuple[str, Sequence[int]]], seed: int) -> dict[str, torch.Tensor]:
    """The state dict for ``keys`` ((name, shape) in the file's order) and ``seed``."""
    generator = torch.Generator().manual_seed(seed)

    def normal(shape: Sequence[int], std: float, mean: float = 0.0) -> torch.Tensor:
        return mean + std * torch.randn(tuple(shape), generator=generator, dtype=torch.float32)

    state: dict[str, torch.Tensor] = {}
    for name, shape in keys:
        leaf = name.rsplit(".", 1)[-1]
        if name == "pretrained.pos_embed":
            value = normal(shape, 0.5)
        elif name in ("pretrained.cls_token", "pretrained.mask_token"):
            value = normal(shape, 0.02)
        elif leaf == "gamma":  # layer scale
            value = normal(shape, 0.02, 0.1)
        elif len(shape) >= 2:
            fan_in = int(np.prod(shape[1:]))
            value = normal(shape, (1.0 / fan_in) ** 0.5)
        elif leaf == "weight":  # a layer norm's scale
            value = normal(shape, 0.1, 1.0)
        elif name == "depth_head.scratch.output_conv2.2.bias":
            value = normal(shape, 0.02, LAST_BIAS)
        else:
            value = normal(shape, 0.02)
        state[name] = value
    return state


def load_fixture(name: str = "vits") -> dict[str, Any]:
    """The fixture's JSON (encoder, seed, keys, input size) with ``depth`` (float32 H×W, the reference's
    output) added, and the path of its ``image`` (PNG)."""
    with open(FIXTURES / f"{name}.json", encoding="utf-8") as handle:
        fixture = json.load(handle)
    fixture["depth"] = np.load(FIXTURES / f"{name}_depth.npy")
    fixture["image"] = FIXTURES / fixture["image"]
    return fixture


def fixture_state(fixture: dict[str, Any]) -> dict[str, torch.Tensor]:
    """The fixture's weights, keys as in an original file."""
    return original_state([(key, shape) for key, shape in fixture["keys"]], fixture["seed"])


def import_golden(home: Path, name: str, fixture: dict[str, Any], state: dict[str, torch.Tensor] | None = None) -> dict[str, Any]:
    """Import the fixture's weights into workspace ``home`` as ``imported:NAME`` the way a user does
    (an original-layout ``.pth`` through `checkpoints import --from depth-anything-v2`); the command's
    JSON answer. The ``.pth`` (100 MB for vits) is deleted once imported."""
    from click.testing import CliRunner

    from webapp.cli import main

    home.mkdir(parents=True, exist_ok=True)
    original = home.parent / f"depth_anything_v2_{fixture['encoder']}.pth"
    torch.save(fixture_state(fixture) if state is None else state, original)
    try:
        result = CliRunner().invoke(main, ["--data-dir", str(home), "checkpoints", "import", "--from",
                                           "depth-anything-v2", str(original), "--name", name, "--json"])
    finally:
        original.unlink()
    assert result.exit_code == 0, result.output
    return json.loads(result.output)
