"""Selective-IGEV's published layout loaded and run output-identical to its own code: seeded weights in
the published files' layout (tests/selective_igev_golden.py), written as a DataParallel file and read
back by model.selective_igev_import, must give on a real pair whose sides are not multiples of 32 what
Selective-IGEV's demo gave for them (tests/fixtures/selective_igev/, made by make_golden.py there):
|ours − reference| ≤ 1e-3 px + 1e-4·|reference| at every pixel. Deliberate bugs (sign, padding, a norm
in training mode, an iteration short) must fail that comparison. Files whose architecture the tensors
do not settle are refused with the flags to give."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from model.raft_import import strip_module  # noqa: E402
from model.selective_igev_import import (  # noqa: E402
    Flags,
    NotSelectiveIGEV,
    convert,
    infer_architecture,
    load_selective_igev,
    network_for,
    to_theirs,
)
from model.stereo import inputs  # noqa: E402
from model.stereo.selective_igev import SelectiveIGEV, SelectiveIGEVConfig, predict_disparity  # noqa: E402
from tests.selective_igev_golden import fixture_state, load_fixture  # noqa: E402

PUBLISHED = Flags(max_disp=192)
# (tensors in the published layout, tensors of the network, norm3 duplicates, training-only tensors)
COUNTS = (785, 759, 20, 6)


def _within_tolerance(ours: np.ndarray, reference: np.ndarray) -> bool:
    return bool((np.abs(ours - reference) <= 1e-3 + 1e-4 * np.abs(reference)).all())


@pytest.fixture(scope="module")
def fixture() -> dict:
    torch.set_num_threads(1)
    return load_fixture("default")


@pytest.fixture(scope="module")
def state(fixture: dict) -> dict:
    return fixture_state(fixture)


@pytest.fixture()
def network(state: dict) -> SelectiveIGEV:
    return convert(state, PUBLISHED).network.stereo_branch


def test_published_file_predicts_what_selective_igev_does(fixture: dict, state: dict, tmp_path: Path) -> None:
    height, width = fixture["left"].shape[:2]
    assert height % 32 and width % 32  # the padding is exercised, on both axes
    published = tmp_path / "sceneflow.pth"
    torch.save(state, published)
    conversion = load_selective_igev(published, PUBLISHED)
    in_file, loaded, duplicates, unused = COUNTS
    keys_loaded = len(conversion.network.state_dict())
    assert (conversion.tensors_in_file, keys_loaded, conversion.duplicates, len(conversion.unused)) == COUNTS
    assert in_file == loaded + duplicates + unused  # every tensor of the file has its place or its reason
    assert conversion.architecture == {"n_gru_layers": 3, "corr_levels": 2, "corr_radius": 4, "max_disp": 192,
                                       "iterations": 32, "dtype": "float32", "given": ["max_disp"]}
    assert not conversion.network.training
    rebuilt = network_for(conversion.architecture)  # as a saved import is rebuilt: architecture + state dict
    rebuilt.load_state_dict(conversion.network.state_dict(), strict=True)
    ours = predict_disparity(conversion.network.stereo_branch, fixture["left"], fixture["right"])
    assert ours.dtype == np.float32 and ours.shape == (height, width)
    reference = fixture["disparity"]
    assert np.ptp(reference) > 50  # a disparity that varies, not a constant the network cannot miss
    error = np.abs(ours - reference)
    assert _within_tolerance(ours, reference), f"max |error| {error.max():.3g} px"


def _bn_stuck_in_training(network: SelectiveIGEV) -> None:
    norm = network.cnet.trunk.stem[1]  # the context encoder's first batch norm
    norm.train(True)
    norm.train = lambda mode=True: norm  # type: ignore[method-assign]  # eval() no longer reaches it


def _bottom_right_padding(height: int, width: int, multiple: int = 32) -> tuple[int, int, int, int]:
    return 0, -width % multiple, 0, -height % multiple


@pytest.mark.parametrize("bug", ["sign", "padding", "batch_norm", "iterations"])
def test_the_comparison_catches_deliberate_bugs(bug: str, fixture: dict, network: SelectiveIGEV,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    iters = 32
    if bug == "padding":
        monkeypatch.setattr(inputs, "centred_padding", _bottom_right_padding)
    elif bug == "batch_norm":
        _bn_stuck_in_training(network)
    elif bug == "iterations":
        iters = 31
    ours = predict_disparity(network, fixture["left"], fixture["right"], iters=iters)
    if bug == "sign":
        ours = -ours
    assert not _within_tolerance(ours, fixture["disparity"])


def test_predict_puts_the_network_in_eval_mode_and_checks_inputs(fixture: dict, network: SelectiveIGEV) -> None:
    network.train()
    left = fixture["left"][:40, :40]
    predict_disparity(network, left, fixture["right"][:40, :40], iters=1)
    assert not network.training  # as the demo: model.eval()
    with pytest.raises(ValueError, match="differ in size"):
        predict_disparity(network, left, fixture["right"], iters=1)
    with pytest.raises(ValueError, match="uint8"):
        predict_disparity(network, left.astype(np.float32), left, iters=1)


def test_max_disp_is_never_guessed(state: dict) -> None:
    with pytest.raises(NotSelectiveIGEV, match=r"--max-disp 192 .* or 768"):
        convert(state)
    with pytest.raises(NotSelectiveIGEV, match="multiple of 32"):
        convert(state, Flags(max_disp=100))
    assert infer_architecture(strip_module(state), Flags(max_disp=768, iterations=80))["iterations"] == 80


def _theirs(config: SelectiveIGEVConfig) -> dict:
    """A file of another architecture, in the reference's layout, from this network's own tensors."""
    return {f"module.{to_theirs(key)}": value for key, value in SelectiveIGEV(config).state_dict().items()}


def test_the_tensors_settle_gru_levels_and_correlation_planes(state: dict) -> None:
    # The reference builds the context encoder's 1/16 stage whatever the levels: with 2 it never runs.
    coarse = {key: value for key, value in state.items() if key.startswith(("module.cnet.layer5.", "module.cnet.outputs16."))}
    two = convert({**_theirs(SelectiveIGEVConfig(n_gru_layers=2)), **coarse}, PUBLISHED)
    assert two.architecture["n_gru_layers"] == 2 and not hasattr(two.network.stereo_branch.update_block, "gru16")
    assert sorted(two.unused) == sorted(key.removeprefix("module.") for key in coarse if ".norm3." not in key)
    assert two.duplicates == 5 and len(coarse) == 44  # norm3 (5 tensors) counts as the duplicate it is
    wide = _theirs(SelectiveIGEVConfig(corr_levels=3, corr_radius=2))  # 3 × 9 × 5 = 135 planes
    with pytest.raises(NotSelectiveIGEV, match=r"--corr-levels and --corr-radius .* 135 planes"):
        convert(wide, PUBLISHED)
    with pytest.raises(NotSelectiveIGEV, match="is not the 135 planes"):
        convert(wide, Flags(max_disp=192, corr_levels=2, corr_radius=4))
    given = convert(wide, Flags(max_disp=192, corr_levels=3, corr_radius=2))
    assert (given.architecture["corr_levels"], given.architecture["corr_radius"]) == (3, 2)


def test_a_half_precision_file_is_upcast(state: dict) -> None:
    half = {key: value.half() if value.is_floating_point() else value for key, value in state.items()}
    conversion = convert(half, PUBLISHED)
    assert conversion.architecture["dtype"] == "float16"
    weight = conversion.network.stereo_branch.feature.conv_stem.weight
    assert weight.dtype == torch.float32
    assert torch.equal(weight, half["module.feature.conv_stem.weight"].float())


def test_files_that_are_not_selective_igev_are_refused(state: dict, tmp_path: Path) -> None:
    with pytest.raises(NotSelectiveIGEV, match="not a Selective-IGEV checkpoint: no feature.conv_stem.weight"):
        convert({"module.fnet.conv1.weight": torch.zeros(1)}, PUBLISHED)
    extra = {**state, "module.extra.weight": torch.zeros(1)}
    with pytest.raises(NotSelectiveIGEV, match="unknown extra.weight"):
        convert(extra, PUBLISHED)
    missing = {key: value for key, value in state.items() if not key.startswith("module.cost_agg.agg_0.")}
    with pytest.raises(NotSelectiveIGEV, match="missing cost_agg.agg_0"):
        convert(missing, PUBLISHED)
    shapes = {**state, "module.desc.weight": torch.zeros(96, 96, 3, 3)}
    with pytest.raises(NotSelectiveIGEV, match=r"desc.weight has shape \(96, 96, 3, 3\)"):
        convert(shapes, PUBLISHED)
    split = {**state, "module.cnet.layer2.0.norm3.weight": state["module.cnet.layer2.0.norm3.weight"] + 1}
    with pytest.raises(NotSelectiveIGEV, match="differs from its block's downsample.1"):
        convert(split, PUBLISHED)
    text = tmp_path / "notes.pth"
    text.write_text("not a checkpoint")
    with pytest.raises(ValueError, match="not a readable checkpoint"):
        load_selective_igev(text, PUBLISHED)
