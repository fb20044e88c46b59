"""`predict` without --mono: the workspace's depth backend (a tiny random Depth Anything V2) estimates the
left view's disparity; without one the message names both ways; a non-finite output is an error."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

torch = pytest.importorskip("torch")
pytest.importorskip("transformers")

from annotation.depth import make_depth_backend  # noqa: E402
from core.formats import read_pfm, read_rgb, write_rgb  # noqa: E402
from dataset.settings import write_settings_file  # noqa: E402
from model.checkpoint import save_checkpoint  # noqa: E402
from model.network import FusionNetwork  # noqa: E402
from model.presets import load_preset  # noqa: E402
from tests.model_pairs import random_dot_pair  # noqa: E402
from tests.test_depth_backends import _save_tiny as save_tiny_depth_anything  # noqa: E402
from tests.test_model_predict_cli import SMALL  # noqa: E402
from webapp.cli import main  # noqa: E402


@pytest.fixture(scope="module")
def pair(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("pair")
    left, right, _ = random_dot_pair(40, 70, 3)
    paths = {"left": root / "l.png", "right": root / "r.png", "checkpoint": root / "lite.pt",
             "depth": save_tiny_depth_anything(root / "da")}
    write_rgb(paths["left"], left)
    write_rgb(paths["right"], right)
    config = load_preset("lite", SMALL)
    torch.manual_seed(0)
    save_checkpoint(paths["checkpoint"], FusionNetwork(config.model), config, step=1)
    return paths


def _predict(pair: dict[str, Path], out: Path, *extra: str) -> object:
    return CliRunner().invoke(main, [*extra, "predict", str(pair["left"]), str(pair["right"]), "--checkpoint",
                                     str(pair["checkpoint"]), "--out", str(out)])


def test_the_workspace_depth_backend_gives_the_mono_disparity(pair: dict[str, Path], tmp_path: Path) -> None:
    home = tmp_path / "ws"
    home.mkdir()
    write_settings_file(home, depth_backend="depth-anything-v2", depth_model_path=pair["depth"])
    out = tmp_path / "estimated.pfm"
    result = _predict(pair, out, "--data-dir", str(home))
    assert result.exit_code == 0, result.output
    estimated = read_pfm(out)
    assert estimated.shape == (40, 70) and np.isfinite(estimated).all()
    # the same as passing the backend's estimate as --mono
    mono = tmp_path / "mono.npy"
    np.save(mono, make_depth_backend("depth-anything-v2", model_path=pair["depth"]).estimate(read_rgb(pair["left"])))
    given = tmp_path / "given.pfm"
    result = CliRunner().invoke(main, ["predict", str(pair["left"]), str(pair["right"]), "--checkpoint",
                                       str(pair["checkpoint"]), "--out", str(given), "--mono", str(mono)])
    assert result.exit_code == 0, result.output
    np.testing.assert_allclose(estimated, read_pfm(given), rtol=1e-5, atol=1e-5)


def test_without_a_depth_model_the_message_names_both_ways(pair: dict[str, Path], tmp_path: Path) -> None:
    home = tmp_path / "ws"
    home.mkdir()
    for extra in ((), ("--data-dir", str(home))):  # no workspace; a workspace on the default precomputed backend
        result = _predict(pair, tmp_path / "d.pfm", *extra)
        assert result.exit_code != 0
        assert "--mono FILE" in result.output and 'depth_backend = "depth-anything-v2"' in result.output
        assert "depth_model_path" in result.output and len(result.output.strip().splitlines()) == 1
    write_settings_file(home, depth_backend="depth-anything-v2", depth_model_path=tmp_path / "missing")
    result = _predict(pair, tmp_path / "d.pfm", "--data-dir", str(home))
    assert result.exit_code != 0 and "is not a directory" in result.output
    assert not (tmp_path / "d.pfm").exists()


def test_a_non_finite_output_is_an_error_and_writes_nothing(pair: dict[str, Path], tmp_path: Path) -> None:
    """A diverged run's weights (NaN) once gave an all-NaN disparity and exit 0."""
    config = load_preset("lite", SMALL)
    network = FusionNetwork(config.model)
    with torch.no_grad():
        for parameter in network.parameters():
            parameter.fill_(float("nan"))
    diverged = tmp_path / "diverged.pt"
    save_checkpoint(diverged, network, config, step=1)
    out = tmp_path / "d.pfm"
    mono = tmp_path / "mono.npy"
    np.save(mono, np.ones((40, 70), np.float32) + np.linspace(0, 1, 70, dtype=np.float32))
    result = CliRunner().invoke(main, ["predict", str(pair["left"]), str(pair["right"]), "--checkpoint", str(diverged),
                                       "--out", str(out), "--mono", str(mono)])
    assert result.exit_code != 0 and "finite" in result.output, result.output
    assert not out.exists()
