"""RAFT-Stereo's published checkpoints imported and run output-identical: for each of the
three published architectures, seeded full-width weights in the published files' layout
(tests/raft_golden.py) go through `checkpoints import --from raft-stereo` and `predict --iters 32`,
and must give what RAFT-Stereo's own code gave for them, demo-style (tests/fixtures/raft_stereo/,
made by make_golden.py there): |ours − reference| ≤ 1e-3 px + 1e-4·|reference| at every pixel.
Files that are not such checkpoints are one-line errors; a pickle naming code is refused."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

torch = pytest.importorskip("torch")

from core.formats import read_pfm, write_rgb  # noqa: E402
from model.checkpoint import load_checkpoint  # noqa: E402
from model.raft_import import Flags, NotRaftStereo, convert, infer_architecture, strip_module  # noqa: E402
from tests.raft_golden import fixture_state, load_fixture  # noqa: E402
from webapp.cli import main  # noqa: E402

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


def _cli(home: Path, *args: str):  # type: ignore[no-untyped-def]
    return CliRunner().invoke(main, ["--data-dir", str(home), *args])


@pytest.fixture()
def home(tmp_path: Path) -> Path:
    (tmp_path / "ws").mkdir()
    return tmp_path / "ws"


@pytest.mark.parametrize("name", sorted(COUNTS))
def test_imported_checkpoint_predicts_what_raft_stereo_does(name: str, home: Path, tmp_path: Path) -> None:
    fixture = load_fixture(name)
    published = tmp_path / f"raftstereo-{name}.pth"
    torch.save(fixture_state(fixture), published)
    imported = _cli(home, "checkpoints", "import", "--from", "raft-stereo", str(published), "--json")
    assert imported.exit_code == 0, imported.output
    doc = json.loads(imported.output)
    in_file, loaded, duplicates, unused = COUNTS[name]
    assert doc["checkpoint"] == f"imported:raftstereo-{name}"
    assert (doc["tensors_in_file"], doc["keys_loaded"], doc["duplicates"], len(doc["unused"])) == COUNTS[name]
    assert in_file == loaded + duplicates + unused  # every tensor of the file has its place or its reason
    assert doc["architecture"].items() >= ARCHITECTURES[name].items()
    payload = load_checkpoint(home / "checkpoints" / "imported" / f"raftstereo-{name}.pt")
    assert payload["config"]["model"]["upsample_border"] == "zeros" and payload["source"]["file"] == published.name
    assert payload["config"]["preset"] == "raft-stereo" and not payload["config"]["train"]["amp"]

    height, width = fixture["shape"]
    assert height % 32 and width % 32
    write_rgb(tmp_path / "left.png", fixture["left"])
    write_rgb(tmp_path / "right.png", fixture["right"])
    out = tmp_path / "disparity.pfm"
    predicted = _cli(home, "predict", str(tmp_path / "left.png"), str(tmp_path / "right.png"), "--checkpoint",
                     doc["checkpoint"], "--iters", str(fixture["iters"]), "--out", str(out))
    assert predicted.exit_code == 0, predicted.output
    ours, reference = read_pfm(out), fixture["disparity"]
    assert ours.shape == reference.shape == (height, width)
    excess = np.abs(ours - reference) - (1e-3 + 1e-4 * np.abs(reference))
    assert excess.max() <= 0, f"{name}: off by up to {np.abs(ours - reference).max():.2e} px"


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
