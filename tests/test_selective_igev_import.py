"""Selective-IGEV's published checkpoints through the command line: seeded weights in the layout of its
published files — a DataParallel state dict, keys under ``module.`` (tests/selective_igev_golden.py) —
go through `checkpoints import --from selective-igev --max-disp 192` and `predict` (its default
iterations, no --iters), and must give what Selective-IGEV's own demo gave for them on a Middlebury
crop whose sides are not multiples of 32 (tests/fixtures/selective_igev/): |ours − reference| ≤ 1e-3 px
+ 1e-4·|reference| at every pixel. Another max_disp, an iteration short, the sign, padding at the
bottom/right or with zeros are shown to break that comparison; what the tensors do not settle is refused
with its flag; `evaluate` scores the import beside SGBM and Selective-RAFT in one report."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

torch = pytest.importorskip("torch")

from model.checkpoint import load_checkpoint  # noqa: E402
from model.selective_igev_import import Flags, convert, to_theirs  # noqa: E402
from model.stereo.selective_igev import SelectiveIGEV, SelectiveIGEVConfig  # noqa: E402
from tests.golden_cli import (  # noqa: E402
    assert_evaluated_beside,
    assert_igev_family_import,
    assert_predictor_path_catches_bugs,
    excess,
)
from tests.golden_cli import cli as _cli  # noqa: E402
from tests.golden_cli import predict_cli as _predict  # noqa: E402
from tests.raft_golden import fixture_state as raft_state  # noqa: E402
from tests.raft_golden import load_fixture as raft_fixture  # noqa: E402
from tests.selective_igev_golden import fixture_state, load_fixture  # noqa: E402
from webapp.cli import main  # noqa: E402

# (tensors in the published layout, tensors of the network, norm3 duplicates, training-only tensors)
COUNTS = (785, 759, 20, 6)
SELECTIVE_RAFT = Path(__file__).parent / "fixtures" / "selective_raft"


@pytest.fixture(scope="module")
def fixture() -> dict[str, Any]:
    torch.set_num_threads(1)
    return load_fixture("default")


@pytest.fixture()
def published(fixture: dict[str, Any], tmp_path: Path) -> Path:
    path = tmp_path / "sceneflow.pth"
    torch.save(fixture_state(fixture), path)  # as the published files are: a DataParallel state dict
    return path


@pytest.fixture()
def home(tmp_path: Path) -> Path:
    (tmp_path / "ws").mkdir()
    return tmp_path / "ws"


def test_imported_checkpoint_predicts_what_selective_igev_does(fixture: dict[str, Any], published: Path,
                                                               home: Path, tmp_path: Path) -> None:
    assert_igev_family_import(home, tmp_path, fixture, published, "selective-igev", "sigev", COUNTS)
    reference = fixture["disparity"]
    # max_disp shapes the output though no tensor holds it: a wrong --max-disp is caught.
    wrong = _cli(home, "checkpoints", "import", "--from", "selective-igev", str(published), "--max-disp", "384",
                 "--name", "sigev-384")
    assert wrong.exit_code == 0 and "max_disp 384 px" in wrong.output, wrong.output
    assert excess(_predict(home, tmp_path, fixture, "imported:sigev-384"), reference) > 0


def test_the_predictor_path_holds_and_fails_for_each_deliberate_bug(fixture: dict[str, Any]) -> None:
    conversion = convert(fixture_state(fixture), Flags(max_disp=192))
    assert_predictor_path_catches_bugs(conversion.network, conversion.config, fixture)


def test_the_cli_refuses_what_the_tensors_do_not_settle_in_one_line(published: Path, home: Path,
                                                                     tmp_path: Path) -> None:
    # A file of 3 correlation levels × radius 2 (135 planes): not the published 2 × 4.
    wide = tmp_path / "wide.pth"
    torch.save({f"module.{to_theirs(key)}": value for key, value in
                SelectiveIGEV(SelectiveIGEVConfig(corr_levels=3, corr_radius=2)).state_dict().items()}, wide)
    raft = tmp_path / "selective_raft.pth"
    torch.save(raft_state(raft_fixture("default", SELECTIVE_RAFT)), raft)
    for args, words in (((str(published),), "give --max-disp 192"),
                        ((str(published), "--max-disp", "100"), "--max-disp 100: must be a positive multiple of 32"),
                        ((str(wide), "--max-disp", "192"), "give --corr-levels and --corr-radius"),
                        ((str(wide), "--max-disp", "192", "--corr-levels", "3"), "--corr-levels and --corr-radius together"),
                        ((str(wide), "--max-disp", "192", "--corr-levels", "2", "--corr-radius", "4"),
                         "is not the 135 planes"),
                        ((str(published), "--max-disp", "192", "--slow-fast"),
                         "--slow-fast: not an option of selective-igev files"),
                        ((str(published), "--max-disp", "192", "--context-norm", "batch"),
                         "--context-norm: not an option of selective-igev files"),
                        ((str(raft), "--max-disp", "192"), "not a Selective-IGEV checkpoint: no feature.conv_stem")):
        result = _cli(home, "checkpoints", "import", "--from", "selective-igev", *args)
        assert result.exit_code == 1 and words in result.output, result.output
        assert result.output.count("\n") == 1 and "Traceback" not in result.output
    assert not (home / "checkpoints" / "imported").exists() or not any((home / "checkpoints" / "imported").iterdir())
    # --max-disp is Selective-IGEV's alone: another network's file refuses it.
    refused = _cli(home, "checkpoints", "import", "--from", "selective-raft", str(raft), "--max-disp", "192")
    assert refused.exit_code == 1 and "--max-disp: not an option of selective-raft files" in refused.output
    given = _cli(home, "checkpoints", "import", "--from", "selective-igev", str(wide), "--max-disp", "768",
                 "--corr-levels", "3", "--corr-radius", "2", "--iters", "80", "--json")
    assert given.exit_code == 0, given.output
    assert json.loads(given.output)["architecture"] == {
        "n_gru_layers": 3, "corr_levels": 3, "corr_radius": 2, "max_disp": 768, "iterations": 80, "dtype": "float32",
        "given": ["corr_levels", "corr_radius", "iterations", "max_disp"]}
    assert load_checkpoint(home / "checkpoints" / "imported" / "wide.pt")["config"]["train"]["test_iters"] == 80


def test_evaluate_scores_selective_igev_beside_the_others_in_one_report(tmp_path: Path, fixture: dict[str, Any],
                                                                        published: Path) -> None:
    home = tmp_path / "evaluated"
    assert _cli(home, "init").exit_code == 0
    imported = _cli(home, "checkpoints", "import", "--from", "selective-igev", str(published), "--max-disp", "192",
                    "--name", "sigev", "--json")
    assert imported.exit_code == 0, imported.output
    igev = json.loads(imported.output)["checkpoint"]
    raft_file = tmp_path / "sraft.pth"
    torch.save(raft_state(raft_fixture("default", SELECTIVE_RAFT)), raft_file)
    imported = _cli(home, "checkpoints", "import", "--from", "selective-raft", str(raft_file), "--json")
    assert imported.exit_code == 0, imported.output
    selective_raft = json.loads(imported.output)["checkpoint"]
    assert_evaluated_beside(home, tmp_path, "selective-igev", igev, "selective-raft", selective_raft, "Selective-IGEV")


def test_the_preset_is_import_only_and_pads_as_the_demo() -> None:
    from model.network import FusionNetwork
    from model.presets import ALL_PRESETS, load_preset

    preset = load_preset("selective-igev")
    assert "selective-igev" not in ALL_PRESETS  # no `train --preset selective-igev`: only imports fill it
    assert (preset.model.architecture, preset.model.max_disp, preset.train.test_iters, preset.train.amp) \
        == ("selective-igev", 192, 32, False)
    # Its features reach 1/32 whatever its GRU levels: the demo's centred padding to 32 is the network's own need.
    for levels in (2, 3):
        config = load_preset("selective-igev", {"gru_levels": levels}).model
        assert config.size_multiple == 32 and config.inference_padding == (32, True)
    with pytest.raises(ValueError, match="max_disp must be a positive multiple of 32"):
        load_preset("selective-igev", {"max_disp": 100})
    with pytest.raises(ValueError, match="'selective-igev' is stereo only"):
        load_preset("selective-igev", {"use_mono": True})
    network = FusionNetwork(preset.model).eval()
    images = torch.rand(2, 1, 3, 32, 64) * 255
    with torch.inference_mode():
        out = network(images[0], images[1], iters=2, all_iterates=True)
    assert out.stereo_only and len(out.stereo_iterates) == 2 and out.disparity.shape == (1, 1, 32, 64)
    assert torch.equal(out.disparity, out.stereo_iterates[-1])


def test_bench_model_offers_to_skip_selective_igev() -> None:
    result = CliRunner().invoke(main, ["bench", "model", "--help"])
    assert result.exit_code == 0 and "--no-selective-igev" in result.output


def test_the_evaluation_page_offers_a_selective_igev_checkpoint_and_says_how_to_import_one(client, tokens) -> None:  # type: ignore[no-untyped-def]
    from tests.conftest import login

    login(client, "curator")
    html = client.get("/evaluations").get_data(as_text=True)
    assert 'name="selective_igev_checkpoint" data-baseline="selective_igev"' in html
    assert "checkpoints import --from selective-igev FILE --max-disp 192</code>" in html  # none imported yet
