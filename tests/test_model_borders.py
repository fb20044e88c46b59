"""Predictions stay right up to the image border: the convex upsampling's
3×3 window and the predictor's padding to the size multiple must not pull the outer pixels of a
side towards 0 (they made stripes one working-resolution pixel, 8 px for ``lite``, wide)."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from model.network import FusionNetwork  # noqa: E402
from model.predictor import Predictor  # noqa: E402
from model.presets import load_preset  # noqa: E402
from model.stereo.upsample import convex_upsample  # noqa: E402
from tests.model_pairs import random_dot_pair  # noqa: E402

SMALL = {"hidden_dims": [16, 16, 16], "motion_dim": 16, "feature_dim": 32, "vlm_dim": 32, "flow_dim": 32,
         "confidence_dim": 16, "fusion_dim": 16, "test_iters": 1}
BAND = 8  # px: one working-resolution pixel of lite (n_downsample 3)


def _outward_masks(height: int, width: int, factor: int) -> list[torch.Tensor]:
    """Upsampling logits B×(9·f²)×h×w: random ones, and ones putting nearly all weight on one
    neighbour of the 3×3 window (each of the 9 in turn), the worst case at a border."""
    masks = [torch.randn(1, 9 * factor * factor, height, width, generator=torch.Generator().manual_seed(0))]
    for k in range(9):
        logits = torch.zeros(1, 9, factor * factor, height, width)
        logits[:, k] = 20.0
        masks.append(logits.view(1, -1, height, width))
    return masks


def test_convex_upsampling_keeps_a_constant_field_constant_up_to_the_border() -> None:
    factor = 8
    disparity = torch.full((1, 1, 4, 6), 1.5)
    for mask in _outward_masks(4, 6, factor):
        up = convex_upsample(disparity, mask, factor)
        assert up.shape == (1, 1, 32, 48)
        assert torch.allclose(up, torch.full_like(up, 12.0), atol=1e-5)


def test_convex_upsampling_stays_a_convex_mix_of_in_image_neighbours() -> None:
    factor = 4
    ramp = torch.arange(30, dtype=torch.float32).view(1, 1, 5, 6)
    for mask in _outward_masks(5, 6, factor):
        up = convex_upsample(ramp, mask, factor)
        windows = torch.nn.functional.pad(ramp, (1, 1, 1, 1), mode="replicate").unfold(2, 3, 1).unfold(3, 3, 1)
        lo = factor * windows.amin(dim=(-2, -1)).repeat_interleave(factor, 2).repeat_interleave(factor, 3)
        hi = factor * windows.amax(dim=(-2, -1)).repeat_interleave(factor, 2).repeat_interleave(factor, 3)
        assert ((up >= lo - 1e-4) & (up <= hi + 1e-4)).all()


def _constant_disparity_network(d: float) -> tuple[FusionNetwork, object]:
    """An untrained lite network whose GRU sets the working-resolution disparity to exactly ``d``
    (full-resolution px) in its first iteration: whatever the output gets wrong is the way from
    the working resolution to the input's pixels (padding, upsampling, fusion)."""
    config = load_preset("lite", SMALL)
    torch.manual_seed(0)
    network = FusionNetwork(config.model).eval()
    head = network.stereo_branch.update.disp_head[-1]
    with torch.no_grad():
        head.weight.zero_()
        head.bias.fill_(d / network.factor)
    return network, config


@pytest.mark.parametrize("size", [(96, 160), (100, 170)])  # a multiple of 32, and one the predictor pads
def test_the_border_bands_are_no_worse_than_the_interior_on_a_fronto_parallel_pair(size: tuple[int, int]) -> None:
    height, width = size
    d = 6
    left, right, gt = random_dot_pair(height, width, d, seed=1)
    network, config = _constant_disparity_network(d)
    prediction = Predictor(network, config).predict(left, right, np.ones((height, width), np.float32))
    for name, estimate in (("disparity", prediction.disparity), ("stereo", prediction.stereo)):
        error = np.abs(estimate - gt)
        inner = (slice(2 * BAND, height - 2 * BAND), slice(d + 2 * BAND, width - 2 * BAND))
        # the left band u < d has no match in the right view: the left border band starts at d
        bands = {"top": error[:BAND, d:], "bottom": error[-BAND:, d:], "left": error[:, d:d + BAND],
                 "right": error[:, -BAND:]}
        interior = float(error[inner].mean())
        worst = {side: round(float(band.mean()), 3) for side, band in bands.items()}
        assert max(worst.values()) <= interior + 0.05, f"{name}: border bands {worst} px vs interior {interior:.3f} px"
