"""MoCha-Stereo's network (model/stereo/mocha_stereo.py) against the reference's own output
(tests/fixtures/mocha_stereo/, made by its make_golden.py), weights loaded key for key."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pytest
import torch

from model.selective_igev_import import to_ours
from model.stereo.mocha_stereo import MochaConfig, MochaStereo, predict_disparity
from tests.mocha_golden import fixture_state, load_fixture

# Tensors the reference saves that test mode never reads: the training-only upsampling of the initial
# disparity and MCCV's 1/4 volume, which nothing reads.
NEVER_RUN = ("spx.", "spx_2.", "spx_4.", "mccv.sw_4x.", "mccv.Conv3d_layer_4x.")


def network_from_state(state: Mapping[str, torch.Tensor], config: MochaConfig = MochaConfig()) -> MochaStereo:
    """Our network with a published-layout state dict (``module.`` optional) loaded, eval mode."""
    network = MochaStereo(config)
    ours = {}
    for key, value in state.items():
        key = key.removeprefix("module.")
        if key.startswith(NEVER_RUN) or (key.startswith("cnet.") and ".norm3." in key):
            continue  # norm3: the same module as the block's downsample.1, saved twice
        ours[to_ours(key)] = value
    network.load_state_dict(ours, strict=True)
    return network.eval()


@pytest.fixture(scope="module")
def golden() -> dict:
    torch.set_num_threads(1)
    fixture = load_fixture("default")
    fixture["network"] = network_from_state(fixture_state(fixture))
    return fixture


def _error(golden: dict, **kwargs: int) -> float:
    out = predict_disparity(golden["network"], golden["left"], golden["right"], **kwargs)
    tolerance = 1e-3 + 1e-4 * np.abs(golden["disparity"])
    excess = np.abs(out - golden["disparity"]) - tolerance
    return float(excess.max())


def test_matches_the_reference(golden: dict) -> None:
    out = predict_disparity(golden["network"], golden["left"], golden["right"], iters=golden["iters"])
    assert out.shape == golden["disparity"].shape
    assert np.abs(out - golden["disparity"]).max() <= 1e-3 + 1e-4 * np.abs(golden["disparity"]).max()
    assert (np.abs(out - golden["disparity"]) <= 1e-3 + 1e-4 * np.abs(golden["disparity"])).all()
