"""Weights in the layout of MoCha-Stereo's published checkpoint, regenerated from a seed.

The golden fixture (tests/fixtures/mocha_stereo/) stores a key/shape list and a seed rather than the
network's ~100 M weights; :func:`fixture_state` turns them back into the state dict the fixture's
reference output was computed with, by Selective-IGEV's value rules (tests/selective_igev_golden.py:
kaiming-like convolutions, depthwise ones by their own fan-in, batch norms far from the identity —
scales 0.5–1.5, shifts ±0.3, running means ±0.5, variances 0.3–3).

Only torch is needed: the project holds none of MoCha-Stereo's code.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from tests import raft_golden
from tests.selective_igev_golden import igev_state

FIXTURES = Path(__file__).parent / "fixtures" / "mocha_stereo"


def load_fixture(name: str) -> dict[str, Any]:
    """The fixture ``name``: its JSON (flags, seed, keys, iterations, crop) with the npz arrays (``left``,
    ``right`` uint8 H×W×3, ``disparity`` float32 H×W, the reference's output) added."""
    return raft_golden.load_fixture(name, FIXTURES)


def fixture_state(fixture: dict[str, Any]) -> dict[str, torch.Tensor]:
    """The fixture's weights, keys as in a published file (``module.`` prefixed, as demo.py's DataParallel
    saves and loads them)."""
    return igev_state([(key, shape) for key, shape in fixture["keys"]], fixture["seed"])
