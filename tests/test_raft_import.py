"""RAFT-Stereo's published checkpoints imported and run output-identical: for each of the
three published architectures, seeded full-width weights in the published files' layout
(tests/raft_golden.py) go through `checkpoints import --from raft-stereo` and `predict`,
and must give what RAFT-Stereo's own code gave for them, demo-style (tests/fixtures/raft_stereo/,
made by make_golden.py there): |ours − reference| ≤ 1e-3 px + 1e-4·|reference| at every pixel.
The small fixtures (random dots, disparities of a few px, batch norm near identity) are joined by
wide ones (a Middlebury strip, disparities past ±100 px, batch norm far from identity) and a float16
copy of a file. Deliberate bugs — some that only the wide disparities show, batch norm in training
mode — break the comparison. Files that are not such checkpoints are one-line errors; a pickle
naming code is refused."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from model.checkpoint import load_checkpoint  # noqa: E402
from model.predictor import Predictor  # noqa: E402
from model.raft_import import Flags, NotRaftStereo, convert, infer_architecture, strip_module  # noqa: E402
from model.stereo import corr as corr_module  # noqa: E402
from tests.golden_cli import assert_accounted, excess, predict_cli  # noqa: E402
from tests.golden_cli import cli as _cli  # noqa: E402
from tests.raft_golden import fixture_state, load_fixture  # noqa: E402

# architecture → (tensors in the published layout, tensors of the network, norm3 duplicates, never-run tensors)
COUNTS = {"default": (337, 317, 20, 0), "realtime": (309, 244, 20, 45), "rvc": (152, 152, 0, 0)}
ARCHITECTURES = {
    "default": {"n_downsample": 2, "gru_levels": 3, "shared_backbone": False, "context_norm": "batch",
                "slow_fast_gru": False, "iterations": 32,
                "published": "raftstereo-sceneflow, raftstereo-middlebury, raftstereo-eth3d"},
    "realtime": {"n_downsample": 3, "gru_levels": 2, "shared_backbone": True, "context_norm": "batch",
                 "slow_fast_gru": True, "iterations": 7, "published": "raftstereo-realtime"},
    "rvc": {"n_downsample": 2, "gru_levels": 3, "shared_backbone": False, "context_norm": "instance",
            "slow_fast_gru": False, "iterations": 32, "published": "iraftstereo_rvc"},
}
# wide fixture → its published layout: disparities past ±100 px, batch norm far from identity
WIDE = {"default_wide": "default", "realtime_wide": "realtime"}


@pytest.fixture()
def home(tmp_path: Path) -> Path:
    (tmp_path / "ws").mkdir()
    return tmp_path / "ws"


@pytest.mark.parametrize("name", [*sorted(COUNTS), *WIDE])
def test_imported_checkpoint_predicts_what_raft_stereo_does(name: str, home: Path, tmp_path: Path) -> None:
    fixture, layout = load_fixture(name), WIDE.get(name, name)
    if "pair_sha256" in fixture:  # a crop of the Middlebury pair: the same pixels the reference saw
        assert hashlib.sha256(fixture["left"].tobytes() + fixture["right"].tobytes()).hexdigest() == fixture["pair_sha256"]
    published = tmp_path / f"raftstereo-{layout}.pth"
    torch.save(fixture_state(fixture), published)
    imported = _cli(home, "checkpoints", "import", "--from", "raft-stereo", str(published), "--json")
    assert imported.exit_code == 0, imported.output
    doc = json.loads(imported.output)
    assert_accounted(doc, f"imported:raftstereo-{layout}", COUNTS[layout], ARCHITECTURES[layout])
    payload = load_checkpoint(home / "checkpoints" / "imported" / f"raftstereo-{layout}.pt")
    assert payload["config"]["model"]["upsample_border"] == "zeros" and payload["source"]["file"] == published.name
    assert payload["config"]["preset"] == "raft-stereo" and not payload["config"]["train"]["amp"]

    ours = _predict(home, tmp_path, fixture, doc["checkpoint"])
    reference = fixture["disparity"]
    assert excess(ours, reference) <= 0, f"{name}: off by up to {np.abs(ours - reference).max():.2e} px"


def _predict(home: Path, tmp_path: Path, fixture: dict[str, Any], checkpoint: str) -> np.ndarray:
    """`predict` with ``checkpoint`` on the fixture's pair (sides not multiples of 32), its iterations."""
    height, width = fixture["shape"]
    assert height % 32 and width % 32
    ours = predict_cli(home, tmp_path, fixture, checkpoint, "--iters", str(fixture["iters"]))
    assert ours.shape == (height, width)
    return ours


def test_the_wide_fixtures_reach_past_100_px_both_ways_with_batch_norm_far_from_identity() -> None:
    """What the small fixtures miss (their disparities span −26…+9 px, their statistics sit near 0/1)."""
    for name, layout in WIDE.items():
        fixture = load_fixture(name)
        reference = fixture["disparity"]
        assert reference.min() <= -100 and reference.max() >= 100, name
        assert min(np.mean(reference >= 100), np.mean(reference <= -100)) > 0.01  # a share of the image each way
        state = fixture_state(fixture)
        norms = [key.removesuffix("running_mean") for key in state if key.endswith("running_mean")]
        assert norms and any(key.startswith("module.cnet.") for key in norms)  # the context encoder's batch norms
        means, variances, scales = (torch.cat([state[key + leaf] for key in norms]) for leaf in
                                    ("running_mean", "running_var", "weight"))
        assert means.abs().mean() > 0.3 and means.abs().max() > 1.0
        assert variances.min() < 0.3 and variances.max() > 3.0 and (variances.log().abs() > 0.5).float().mean() > 0.5
        assert scales.min() < 0.5 and scales.max() > 1.5 and (scales - 1).abs().mean() > 0.15
        assert ARCHITECTURES[layout]["context_norm"] == "batch"


def test_a_float16_file_imports_and_predicts_what_raft_stereo_does_for_its_weights(home: Path, tmp_path: Path) -> None:
    """A half-precision copy of a published file (as some labs keep them) imports as float32 weights of the
    same values and predicts what the reference gives for the float16-rounded weights. Rounding alone moves
    the reference's output by up to ``half_vs_float_px`` (0.63 px, disparities to 316 px, 32 iterations): that, not
    the comparison's tolerance, is how far a float16 file lies from its float32 original."""
    fixture = load_fixture("default_wide")
    state = fixture_state(fixture)
    half = tmp_path / "raftstereo-sceneflow-fp16.pth"
    torch.save({k: v.half() if v.is_floating_point() else v for k, v in state.items()}, half)
    imported = _cli(home, "checkpoints", "import", "--from", "raft-stereo", str(half), "--json")
    assert imported.exit_code == 0, imported.output
    doc = json.loads(imported.output)
    assert doc["architecture"].items() >= ARCHITECTURES["default"].items() and doc["keys_loaded"] == 317
    weights = load_checkpoint(home / "checkpoints" / "imported" / "raftstereo-sceneflow-fp16.pt")["state"]
    assert all(v.dtype == torch.float32 for v in weights.values() if v.is_floating_point())
    mean = weights["stereo_branch.cnet.trunk.stem.1.running_mean"]  # RAFT-Stereo's cnet.norm1
    assert torch.equal(mean, state["module.cnet.norm1.running_mean"].half().float())

    ours = _predict(home, tmp_path, fixture, doc["checkpoint"])
    assert excess(ours, fixture["disparity_half"]) <= 0, f"off by up to {np.abs(ours - fixture['disparity_half']).max():.2e}"
    moved = float(np.abs(fixture["disparity_half"] - fixture["disparity"]).max())
    assert moved == pytest.approx(fixture["half_vs_float_px"], rel=1e-2) and excess(ours, fixture["disparity"]) > 0


# Deliberate bugs a port could make that the small fixtures cannot show: each changes only what lies
# more than 192 px away. (Their lookups, ±4 at the coarsest of 4 levels, 8 feature px apart, reach
# ±32 feature px, ±128 px, around disparities of a few px.)
_INIT, _LOOKUP = corr_module.CorrPyramid1D.__init__, corr_module.CorrPyramid1D.lookup
MAX_DISPARITY = 192  # px: the cost volume of PSMNet-style networks, and of ports written after them


def _volume_of_192_px(factor: int) -> Callable[..., None]:
    """CorrPyramid1D.__init__, but correlations of pairs more than 192 px apart are 0."""

    def init(self, left, right, **options) -> None:  # type: ignore[no-untyped-def]
        _INIT(self, left, right, **options)
        width = self.shape[2]
        x = torch.arange(width, dtype=torch.float32)
        near = ((x.view(-1, 1) - x.view(1, -1)).abs() * factor <= MAX_DISPARITY).float()  # left x × right x
        volume = (self.pyramid[0].view(-1, width, width) * near).view(-1, 1, 1, width)
        self.pyramid = [volume]
        for _ in range(self.levels - 1):
            volume = torch.nn.functional.avg_pool2d(volume, (1, 2), stride=(1, 2))
            self.pyramid.append(volume)
    return init


def _lookup_clamped_to_192_px(factor: int) -> Callable[..., torch.Tensor]:
    """CorrPyramid1D.lookup, but the disparity it looks around clamped to ±192 px."""
    return lambda self, disparity: _LOOKUP(self, disparity.clamp(-MAX_DISPARITY / factor, MAX_DISPARITY / factor))


WIDE_ONLY_BUGS: dict[str, Callable[[int], tuple[str, Callable[..., Any]]]] = {
    "a cost volume of ±192 px": lambda factor: ("__init__", _volume_of_192_px(factor)),
    "lookups clamped to ±192 px": lambda factor: ("lookup", _lookup_clamped_to_192_px(factor)),
}


def _predictor(name: str) -> tuple[Predictor, dict[str, Any]]:
    fixture = load_fixture(name)
    conversion = convert(strip_module(fixture_state(fixture)))
    return Predictor(conversion.network, conversion.config), fixture


def test_deliberate_bugs_that_only_the_wide_disparities_show_and_batch_norm_statistics_matter() -> None:
    torch.set_num_threads(1)
    wide, small = _predictor("default_wide"), _predictor("default")
    factor = 2 ** wide[0].config.model.n_downsample

    def off(case: tuple[Predictor, dict[str, Any]]) -> float:
        predictor, fixture = case
        return excess(predictor.predict(fixture["left"], fixture["right"], iters=fixture["iters"]).disparity,
                      fixture["disparity"])

    assert off(wide) <= 0
    for bug, patch in WIDE_ONLY_BUGS.items():
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(corr_module.CorrPyramid1D, *patch(factor))
            assert off(wide) > 0, f"{bug} went unnoticed"
            assert off(small) <= 0, f"{bug}: the small fixture shows it too; it is no wide-only bug"
    network = wide[0].network
    saved = {k: v.clone() for k, v in network.state_dict().items()}
    norms = [m for m in network.modules() if isinstance(m, torch.nn.BatchNorm2d)]
    try:
        for norm in norms:  # batch statistics instead of the file's running ones
            norm.train()
        assert off(wide) > 0, "batch norm in training mode went unnoticed"
        network.load_state_dict(saved)
        network.eval()
        for norm in norms:  # the file's statistics ignored: identity
            norm.reset_running_stats()
        assert off(wide) > 0, "batch-norm statistics ignored went unnoticed"
    finally:
        network.load_state_dict(saved)
        network.eval()


def test_architecture_is_read_from_the_tensors_and_the_published_flags() -> None:
    for name, expected in ARCHITECTURES.items():
        state = strip_module(fixture_state(load_fixture(name)))
        assert infer_architecture(state).items() >= expected.items()
    # A layout no published file has (2 GRU levels, no norm tensors): refused, naming every flag to give.
    state = strip_module(fixture_state(load_fixture("rvc")))
    two_levels = {k: v for k, v in state.items() if not k.startswith("context_zqr_convs.2")}
    with pytest.raises(NotRaftStereo, match="give --context-norm instance|none .*--slow-fast or --no-slow-fast"
                                            ".*--corr-levels and --corr-radius"):
        infer_architecture(two_levels)
    with pytest.raises(NotRaftStereo, match="give --slow-fast or --no-slow-fast"):
        infer_architecture(two_levels, Flags(context_norm="none", corr_levels=4, corr_radius=4))
    arch = infer_architecture(two_levels, Flags(context_norm="none", slow_fast_gru=False, corr_levels=4, corr_radius=4))
    assert arch["gru_levels"] == 2 and arch["published"] is None and arch["context_norm"] == "none"
    assert not arch["slow_fast_gru"] and arch["iterations"] == 32  # RAFT-Stereo's demo default
    assert arch["given"] == ["context_norm", "corr_levels", "corr_radius", "slow_fast_gru"]
    # flags the tensors contradict are refused; a published layout takes the importer's word where given
    with pytest.raises(NotRaftStereo, match="--context-norm batch does not fit the file"):
        infer_architecture(state, Flags(context_norm="batch"))
    with pytest.raises(NotRaftStereo, match="is not the 36 correlation planes"):
        infer_architecture(state, Flags(corr_levels=4, corr_radius=3))
    realtime = strip_module(fixture_state(load_fixture("realtime")))
    assert infer_architecture(realtime, Flags(slow_fast_gru=False, iterations=12)).items() >= {
        "slow_fast_gru": False, "iterations": 12, "published": "raftstereo-realtime"}.items()


@pytest.fixture(scope="module")
def rvc_state() -> dict[str, torch.Tensor]:
    return fixture_state(load_fixture("rvc"))


@pytest.mark.parametrize(("edit", "message"), [
    (lambda s: {"conv.weight": torch.zeros(1)}, "not a RAFT-Stereo checkpoint: no update_block.mask.2.weight"),
    (lambda s: {k: v for k, v in s.items() if "gru16.convq.bias" not in k}, "missing update_block.gru16.convq.bias"),
    (lambda s: {**s, "module.extra.weight": torch.zeros(1)}, "unknown extra.weight"),
    (lambda s: {**s, "module.fnet.conv2.bias": torch.zeros(3)}, "fnet.conv2.bias has shape (3,), expected (256,)"),
    (lambda s: {**s, "module.update_block.mask.2.weight": torch.zeros(100, 256, 1, 1)}, "has 100 rows: not 9·f²"),
    (lambda s: {**s, "module.update_block.flow_head.conv1.bias": torch.full((256,), np.nan)}, "not finite"),
    (lambda s: {**s, "module.cnet.conv1.weight": [1, 2]}, "not a state dict of tensors"),
])
def test_files_that_are_not_raft_stereo_name_what_is_wrong(rvc_state, edit, message: str) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(NotRaftStereo, match=message.replace("(", r"\(").replace(")", r"\)")):
        convert(edit(rvc_state))


class _Code:
    def __reduce__(self):  # type: ignore[no-untyped-def]
        return (print, ("this would have run",))


def test_the_cli_refuses_in_one_line_and_registers_nothing(home: Path, tmp_path: Path, rvc_state) -> None:  # type: ignore[no-untyped-def]
    pickled, text, odd = tmp_path / "evil.pth", tmp_path / "notes.pth", tmp_path / "odd.pth"
    torch.save({"module.cnet.conv1.weight": _Code()}, pickled)
    text.write_text("not a checkpoint")
    torch.save({"module.conv.weight": torch.zeros(2)}, odd)
    cases = [(pickled, "evil.pth holds Python objects beyond tensors and plain values and is not loaded"),
             (text, "notes.pth is not a readable checkpoint"),
             (odd, "not a RAFT-Stereo checkpoint: no update_block.mask.2.weight")]
    for path, message in cases:
        result = _cli(home, "checkpoints", "import", "--from", "raft-stereo", str(path))
        assert result.exit_code == 1 and message in result.output, result.output
        assert result.output.count("\n") == 1 and "Traceback" not in result.output
    assert not (home / "checkpoints" / "imported").exists() or not any((home / "checkpoints" / "imported").iterdir())
    good = tmp_path / "good.pth"
    torch.save(rvc_state, good)
    bad_name = _cli(home, "checkpoints", "import", "--from", "raft-stereo", str(good), "--name", "../up")
    assert bad_name.exit_code == 1 and "imported checkpoint name '../up'" in bad_name.output
    first = _cli(home, "checkpoints", "import", "--from", "raft-stereo", str(good), "--name", "rvc")
    assert first.exit_code == 0 and first.output.startswith("imported:rvc: RAFT-Stereo (iraftstereo_rvc)")
    again = _cli(home, "checkpoints", "import", "--from", "raft-stereo", str(good), "--name", "rvc")
    assert again.exit_code == 1 and "imported:rvc exists" in again.output
    assert _cli(home, "checkpoints", "import", "--from", "raft-stereo", str(good), "--name", "rvc",
                "--replace").exit_code == 0


def test_the_cli_refuses_an_unsettled_layout_until_its_flags_are_given(home: Path, tmp_path: Path) -> None:
    """A 2-level file without norm tensors (no published layout): the refusal names the flags; given, it
    imports with them and RAFT-Stereo's demo iterations; flags are refused for a Depth Anything file."""
    from model.network import FusionNetwork
    from model.presets import load_preset
    from model.raft_import import PREFIX, to_theirs

    torch.manual_seed(0)
    built = FusionNetwork(load_preset("raft-stereo", {"gru_levels": 2, "context_norm": "none"}).model)
    custom = tmp_path / "custom.pth"
    torch.save({"module." + to_theirs(k.removeprefix(PREFIX)): v for k, v in built.state_dict().items()}, custom)
    refused = _cli(home, "checkpoints", "import", "--from", "raft-stereo", str(custom))
    assert refused.exit_code != 0 and "--slow-fast or --no-slow-fast" in refused.output
    assert "--context-norm instance|none" in refused.output and not (home / "checkpoints" / "imported").exists() \
        or not any((home / "checkpoints" / "imported").iterdir())
    imported = _cli(home, "checkpoints", "import", "--from", "raft-stereo", str(custom), "--json", "--context-norm",
                    "instance", "--no-slow-fast", "--corr-levels", "4", "--corr-radius", "4", "--iters", "20")
    assert imported.exit_code == 0, imported.output
    arch = json.loads(imported.output)["architecture"]
    assert (arch["gru_levels"], arch["context_norm"], arch["slow_fast_gru"], arch["iterations"]) == (2, "instance", False, 20)
    payload = load_checkpoint(home / "checkpoints" / "imported" / "custom.pt")
    assert payload["config"]["train"]["test_iters"] == 20
    wrong = _cli(home, "checkpoints", "import", "--from", "depth-anything-v2", str(custom), "--slow-fast")
    assert wrong.exit_code != 0 and "architecture flags are for stereo networks' files" in wrong.output
