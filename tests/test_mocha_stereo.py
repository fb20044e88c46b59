"""MoCha-Stereo's network (model/stereo/mocha_stereo.py) and importer (model/mocha_import.py) against the
reference's own output (tests/fixtures/mocha_stereo/, made by its make_golden.py from MoCha-Stereo's code
and timm 0.6.5, neither in the project): seeded weights of the published layout, a 77×109 Middlebury
crop, the demo's padding and 32 iterations — |ours − reference| ≤ 1e-3 px + 1e-4·|reference| at every
pixel; deliberate bugs (sign, padding, a batch norm in training mode, an iteration short, the refinement
skipped, symmetric instead of TensorFlow padding) break the comparison."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

torch = pytest.importorskip("torch")

import torch.nn.functional as F  # noqa: E402

from model.mocha_import import Flags, NotMochaStereo, convert, infer_architecture, network_for, read_published  # noqa: E402
from model.stereo import efficientnet_features, inputs  # noqa: E402
from model.stereo.mocha_stereo import MochaStereo, high_pass, predict_disparity  # noqa: E402
from tests.golden_cli import excess  # noqa: E402
from tests.mocha_golden import fixture_state, load_fixture  # noqa: E402

# (tensors in the published layout, tensors of the network, norm3 duplicates, never run in test mode)
COUNTS = (2090, 2062, 20, 8)
PUBLISHED = Flags(max_disp=192)


@pytest.fixture(scope="module")
def fixture() -> dict[str, Any]:
    torch.set_num_threads(1)
    return load_fixture("default")


@pytest.fixture(scope="module")
def state(fixture: dict[str, Any]) -> dict[str, Any]:
    return fixture_state(fixture)


@pytest.fixture(scope="module")
def conversion(state: dict[str, Any]) -> Any:
    """The published layout converted once: a conversion takes seconds, and every test below reads the same."""
    return convert(state, PUBLISHED)


@pytest.fixture(scope="module")
def network(conversion: Any) -> MochaStereo:
    return conversion.network.stereo_branch  # type: ignore[no-any-return]


@pytest.fixture(scope="module")
def prediction(fixture: dict[str, Any], network: MochaStereo) -> np.ndarray:
    """The port's output for the fixture's pair, computed once (the comparison and the sign bug read it)."""
    return predict_disparity(network, fixture["left"], fixture["right"])


def test_the_published_layout_imports_and_predicts_what_mocha_stereo_does(fixture: dict[str, Any], conversion: Any,
                                                                           prediction: np.ndarray) -> None:
    height, width = fixture["left"].shape[:2]
    assert height % 32 and width % 32  # the padding is exercised, on both axes
    in_file, loaded, duplicates, unused = COUNTS
    keys_loaded = len(conversion.network.state_dict())
    assert (conversion.tensors_in_file, keys_loaded, conversion.duplicates, len(conversion.unused)) == COUNTS
    assert in_file == loaded + duplicates + unused  # every tensor of the file has its place or its reason
    assert sorted(conversion.unused) == sorted(
        ["spx.0.weight", "spx.0.bias", "spx_2.conv1.conv.weight", "spx_2.conv2.conv.weight", "spx_4.0.conv.weight",
         "spx_4.1.weight", "mccv.sw_4x.weight", "mccv.Conv3d_layer_4x.conv.weight"])
    assert conversion.architecture == {"n_gru_layers": 3, "corr_levels": 2, "corr_radius": 4, "max_disp": 192,
                                       "iterations": 32, "dtype": "float32", "given": ["max_disp"]}
    assert not conversion.network.training
    network_for(conversion.architecture).load_state_dict(conversion.network.state_dict(), strict=True)
    ours = prediction
    assert ours.dtype == np.float32 and ours.shape == (height, width)
    reference = fixture["disparity"]
    assert np.ptp(reference) > 20  # a disparity that varies, not a constant the network cannot miss
    assert excess(ours, reference) <= 0, f"max |error| {np.abs(ours - reference).max():.3g} px"


def _bn_stuck_in_training(network: MochaStereo) -> Any:
    norm = network.feature.bn1  # the EfficientNet stem's batch norm
    norm.train(True)
    norm.train = lambda mode=True: norm  # type: ignore[method-assign]  # eval() no longer reaches it
    return norm


def _bottom_right_padding(height: int, width: int, multiple: int = 32) -> tuple[int, int, int, int]:
    return 0, -width % multiple, 0, -height % multiple


@pytest.mark.parametrize("bug", ["sign", "padding", "batch_norm", "iterations", "no_refinement", "symmetric_same"])
def test_the_comparison_catches_deliberate_bugs(bug: str, fixture: dict, network: MochaStereo,
                                                monkeypatch: pytest.MonkeyPatch, request: pytest.FixtureRequest) -> None:
    if bug == "sign":  # the output negated: the port's own output serves, computed once for the module
        assert excess(-request.getfixturevalue("prediction"), fixture["disparity"]) > 0
        return
    iters = 32
    if bug == "padding":
        monkeypatch.setattr(inputs, "centred_padding", _bottom_right_padding)
    elif bug == "batch_norm":
        norm = _bn_stuck_in_training(network)
    elif bug == "iterations":
        iters = 31
    elif bug == "no_refinement":
        monkeypatch.setattr(network.REMP, "forward", lambda disparity, left, right: torch.zeros_like(disparity))
    elif bug == "symmetric_same":  # padding=1 on every side, as a plain nn.Conv2d port would
        monkeypatch.setattr(efficientnet_features.SameConv2d, "forward",
                            lambda self, x: F.conv2d(x, self.weight, self.bias, self.stride, 1, 1, self.groups)
                            if self.dynamic else torch.nn.Conv2d.forward(self, x))
    try:
        ours = predict_disparity(network, fixture["left"], fixture["right"], iters=iters)
    finally:
        if bug == "batch_norm":
            del norm.train  # the class's again
            network.eval()
    assert excess(ours, fixture["disparity"]) > 0


def test_the_high_pass_is_the_references_all_ones_convolution() -> None:
    x = torch.randn(1, 12, 9, 11, generator=torch.Generator().manual_seed(0))
    kernel = torch.ones(12, 12, 3, 3) / 9  # MCCV's high_frequency_sliding_window_filter
    assert torch.allclose(high_pass(x), x - F.conv2d(x, kernel, padding=1), atol=1e-5)


def test_max_disp_is_never_guessed_and_other_layouts_are_refused(state: dict) -> None:
    plain = {key.removeprefix("module."): value for key, value in state.items()}
    with pytest.raises(NotMochaStereo, match="give --max-disp 192"):
        infer_architecture(plain)
    with pytest.raises(NotMochaStereo, match="--max-disp 100: must be a positive multiple of 32"):
        infer_architecture(plain, Flags(max_disp=100))
    with pytest.raises(NotMochaStereo, match="together"):
        infer_architecture(plain, Flags(max_disp=192, corr_levels=2))
    with pytest.raises(NotMochaStereo, match="is not the 162 planes"):
        infer_architecture(plain, Flags(max_disp=192, corr_levels=3, corr_radius=2))
    two_levels = {key: value for key, value in plain.items() if not key.startswith("context_zqr_convs.2.")}
    with pytest.raises(NotMochaStereo, match="2 context_zqr_convs"):
        infer_architecture(two_levels, PUBLISHED)
    assert infer_architecture(plain, Flags(max_disp=384, iterations=80))["iterations"] == 80


def test_files_that_are_not_mocha_stereo_are_refused(state: dict, tmp_path: Path) -> None:
    from tests.selective_igev_golden import fixture_state as igev_state
    from tests.selective_igev_golden import load_fixture as igev_fixture

    with pytest.raises(NotMochaStereo, match="not a MoCha-Stereo checkpoint: no update_block.lstm04"):
        convert(igev_state(igev_fixture("default")), PUBLISHED)
    extra = dict(state, **{"module.extra.weight": torch.zeros(1)})
    with pytest.raises(NotMochaStereo, match="unknown extra.weight"):
        convert(extra, PUBLISHED)
    bad = dict(state)
    bad["module.REMP.final_conv.weight"] = torch.full_like(bad["module.REMP.final_conv.weight"], float("nan"))
    with pytest.raises(NotMochaStereo, match="not finite"):
        convert(bad, PUBLISHED)
    path = tmp_path / "list.pth"
    torch.save([1, 2], path)
    with pytest.raises(NotMochaStereo, match="not a state dict"):
        read_published(path)


def test_a_wrong_max_disp_is_another_output(fixture: dict[str, Any], state: dict) -> None:
    # max_disp shapes the output though no tensor holds it: why the import never guesses it.
    wider = convert(state, Flags(max_disp=384)).network.stereo_branch
    ours = predict_disparity(wider, fixture["left"], fixture["right"])  # type: ignore[arg-type]
    assert excess(ours, fixture["disparity"]) > 0
