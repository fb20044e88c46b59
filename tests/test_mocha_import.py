"""MoCha-Stereo's published checkpoint through the command line: seeded weights in the layout of
``mocha-stereo.pth`` — a DataParallel state dict, keys under ``module.`` (tests/mocha_golden.py) — go
through `checkpoints import --from mocha-stereo --max-disp 192` and `predict` (its default iterations, no
--iters), and must give what MoCha-Stereo's own demo gave for them on a Middlebury crop whose sides are
not multiples of 32 (tests/fixtures/mocha_stereo/): |ours − reference| ≤ 1e-3 px + 1e-4·|reference| at
every pixel. An iteration short, the sign, padding at the bottom/right or with zeros are shown to break
that comparison; what the tensors do not settle is refused with its flag; `evaluate` scores the import
beside SGBM and Selective-IGEV in one report."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

torch = pytest.importorskip("torch")

from model.checkpoint import load_checkpoint  # noqa: E402
from model.mocha_import import Flags, convert  # noqa: E402
from tests.golden_cli import (  # noqa: E402
    assert_evaluated_beside,
    assert_igev_family_import,
    assert_predictor_path_catches_bugs,
)
from tests.golden_cli import cli as _cli  # noqa: E402
from tests.mocha_golden import fixture_state, load_fixture  # noqa: E402
from tests.selective_igev_golden import fixture_state as igev_state  # noqa: E402
from tests.selective_igev_golden import load_fixture as igev_fixture  # noqa: E402
from webapp.cli import main  # noqa: E402

# (tensors in the published layout, tensors of the network, norm3 duplicates, never run in test mode)
COUNTS = (2090, 2062, 20, 8)


@pytest.fixture(scope="module")
def fixture() -> dict[str, Any]:
    torch.set_num_threads(1)
    return load_fixture("default")


@pytest.fixture(scope="module")
def published(fixture: dict[str, Any], tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("published") / "mocha-stereo.pth"
    torch.save(fixture_state(fixture), path)  # as the published file is: a DataParallel state dict
    return path


@pytest.fixture()
def home(tmp_path: Path) -> Path:
    (tmp_path / "ws").mkdir()
    return tmp_path / "ws"


def test_imported_checkpoint_predicts_what_mocha_stereo_does(fixture: dict[str, Any], published: Path,
                                                             home: Path, tmp_path: Path) -> None:
    assert_igev_family_import(home, tmp_path, fixture, published, "mocha-stereo", "mocha-stereo", COUNTS)


def test_the_predictor_path_holds_and_fails_for_each_deliberate_bug(fixture: dict[str, Any]) -> None:
    conversion = convert(fixture_state(fixture), Flags(max_disp=192))
    assert_predictor_path_catches_bugs(conversion.network, conversion.config, fixture)


def test_the_cli_refuses_what_the_tensors_do_not_settle_in_one_line(published: Path, home: Path,
                                                                     tmp_path: Path) -> None:
    igev = tmp_path / "sceneflow.pth"
    torch.save(igev_state(igev_fixture("default")), igev)
    for args, words in (((str(published),), "give --max-disp 192"),
                        ((str(published), "--max-disp", "100"), "--max-disp 100: must be a positive multiple of 32"),
                        ((str(published), "--max-disp", "192", "--corr-levels", "3"), "--corr-levels and --corr-radius together"),
                        ((str(published), "--max-disp", "192", "--corr-levels", "3", "--corr-radius", "2"),
                         "is not the 162 planes"),
                        ((str(published), "--max-disp", "192", "--slow-fast"),
                         "--slow-fast: not an option of mocha-stereo files"),
                        ((str(published), "--max-disp", "192", "--context-norm", "batch"),
                         "--context-norm: not an option of mocha-stereo files"),
                        ((str(igev), "--max-disp", "192"), "not a MoCha-Stereo checkpoint: no update_block.lstm04")):
        result = _cli(home, "checkpoints", "import", "--from", "mocha-stereo", *args)
        assert result.exit_code == 1 and words in result.output, result.output
        assert result.output.count("\n") == 1 and "Traceback" not in result.output
    assert not (home / "checkpoints" / "imported").exists() or not any((home / "checkpoints" / "imported").iterdir())
    given = _cli(home, "checkpoints", "import", "--from", "mocha-stereo", str(published), "--max-disp", "384",
                 "--iters", "12")
    assert given.exit_code == 0 and "MoCha-Stereo, 3 mogrifier-LSTM levels, max_disp 384 px" in given.output
    assert "2062 tensors loaded (2090 in the file: 20 duplicates, 8 never run in test mode)" in given.output
    assert load_checkpoint(home / "checkpoints" / "imported" / "mocha-stereo.pt")["config"]["train"]["test_iters"] == 12


def test_evaluate_scores_mocha_stereo_beside_the_others_in_one_report(tmp_path: Path, published: Path) -> None:
    home = tmp_path / "evaluated"
    assert _cli(home, "init").exit_code == 0
    imported = _cli(home, "checkpoints", "import", "--from", "mocha-stereo", str(published), "--max-disp", "192",
                    "--json")
    assert imported.exit_code == 0, imported.output
    mocha = json.loads(imported.output)["checkpoint"]
    igev_file = tmp_path / "sceneflow.pth"
    torch.save(igev_state(igev_fixture("default")), igev_file)
    imported = _cli(home, "checkpoints", "import", "--from", "selective-igev", str(igev_file), "--max-disp", "192",
                    "--name", "sigev", "--json")
    assert imported.exit_code == 0, imported.output
    assert_evaluated_beside(home, tmp_path, "mocha-stereo", mocha, "selective-igev", "imported:sigev", "MoCha-Stereo")


def test_the_preset_is_import_only_and_pads_as_the_demo() -> None:
    from model.presets import ALL_PRESETS, load_preset

    preset = load_preset("mocha-stereo")
    assert "mocha-stereo" not in ALL_PRESETS  # no `train --preset mocha-stereo`: only imports fill it
    assert (preset.model.architecture, preset.model.max_disp, preset.train.test_iters, preset.train.amp) \
        == ("mocha-stereo", 192, 32, False)
    assert preset.model.size_multiple == 32 and preset.model.inference_padding == (32, True)
    with pytest.raises(ValueError, match="'mocha-stereo' is stereo only"):
        load_preset("mocha-stereo", {"use_mono": True})


def test_bench_model_offers_to_skip_mocha_stereo() -> None:
    result = CliRunner().invoke(main, ["bench", "model", "--help"])
    assert result.exit_code == 0 and "--no-mocha-stereo" in result.output


def test_the_evaluation_page_offers_a_mocha_stereo_checkpoint_and_says_how_to_import_one(client, tokens) -> None:  # type: ignore[no-untyped-def]
    from tests.conftest import login

    login(client, "curator")
    html = client.get("/evaluations").get_data(as_text=True)
    assert 'name="mocha_stereo_checkpoint" data-baseline="mocha_stereo"' in html
    assert "checkpoints import --from mocha-stereo FILE --max-disp 192</code>" in html  # none imported yet
