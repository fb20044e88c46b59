"""``illusion-studio predict`` on a random-dot pair with a lite checkpoint: PFMs that
core/formats reads back, the preview PNG, and one-line errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

torch = pytest.importorskip("torch")

from core.formats import read_pfm, read_rgb, write_pfm, write_rgb  # noqa: E402
from model.checkpoint import save_checkpoint  # noqa: E402
from model.network import FusionNetwork  # noqa: E402
from model.presets import load_preset  # noqa: E402
from tests.model_pairs import random_dot_pair  # noqa: E402
from webapp.cli import main  # noqa: E402

SMALL = {"hidden_dims": [16, 16, 16], "motion_dim": 16, "feature_dim": 32, "vlm_dim": 32, "flow_dim": 32,
         "confidence_dim": 16, "fusion_dim": 16, "test_iters": 2}


@pytest.fixture()
def files(tmp_path: Path) -> dict[str, Path]:
    left, right, gt = random_dot_pair(40, 70, 3)
    paths = {"left": tmp_path / "l.png", "right": tmp_path / "r.png", "mono": tmp_path / "m.pfm",
             "checkpoint": tmp_path / "run.pt", "small": tmp_path / "small.png"}
    write_rgb(paths["left"], left)
    write_rgb(paths["right"], right)
    write_rgb(paths["small"], left[:20])
    write_pfm(paths["mono"], (gt + np.linspace(0, 1, 70, dtype=np.float32))[::2, ::2])  # another size: resized
    config = load_preset("lite", SMALL)
    torch.manual_seed(0)
    save_checkpoint(paths["checkpoint"], FusionNetwork(config.model), config, step=1)
    return paths


def test_predict_writes_what_formats_reads_back(files: dict[str, Path], tmp_path: Path) -> None:
    out = tmp_path / "out" / "disp.pfm"
    result = CliRunner().invoke(main, ["predict", str(files["left"]), str(files["right"]), "--checkpoint",
                                       str(files["checkpoint"]), "--out", str(out), "--mono", str(files["mono"]),
                                       "--preview", str(tmp_path / "disp.png"),
                                       "--outputs", "confidence,stereo,mono-align"])
    assert result.exit_code == 0, result.output
    disparity = read_pfm(out)
    assert disparity.shape == (40, 70) and np.isfinite(disparity).all()
    for name in ("confidence", "stereo", "mono_align"):
        assert read_pfm(out.with_name(f"disp_{name}.pfm")).shape == (40, 70)
    confidence = read_pfm(out.with_name("disp_confidence.pfm"))
    assert ((confidence > 0) & (confidence < 1)).all()
    preview = read_rgb(tmp_path / "disp.png")
    assert preview.shape[0] == 40 and preview.shape[1] > 70  # the colour bar sits on the right


def test_predict_errors_are_one_line(files: dict[str, Path], tmp_path: Path) -> None:
    runner = CliRunner()
    base = ["predict", str(files["left"])]
    cases = [
        ([str(files["small"]), "--checkpoint", str(files["checkpoint"]), "--out", str(tmp_path / "d.pfm"),
          "--mono", str(files["mono"])], "differ in size"),
        ([str(files["right"]), "--checkpoint", str(files["checkpoint"]), "--out", str(tmp_path / "d.pfm")],
         "pass --mono FILE"),
        ([str(files["right"]), "--checkpoint", str(tmp_path / "none.pt"), "--out", str(tmp_path / "d.pfm")],
         "does not exist"),
        ([str(files["right"]), "--checkpoint", str(files["checkpoint"]), "--out", str(tmp_path / "d.pfm"),
          "--outputs", "depth"], "unknown output"),
    ]
    for args, message in cases:
        result = runner.invoke(main, base + args)
        assert result.exit_code != 0 and message in result.output, result.output
    home = tmp_path / "ws"
    home.mkdir()
    result = runner.invoke(main, ["--data-dir", str(home), *base, str(files["right"]), "--out", str(tmp_path / "d.pfm")])
    assert result.exit_code != 0 and "no --checkpoint given and this workspace has no current model" in result.output
    (home / "models").mkdir()
    (home / "models" / "current.json").write_text(json.dumps({"checkpoint": str(files["checkpoint"])}))
    result = runner.invoke(main, ["--data-dir", str(home), *base, str(files["right"]), "--out",
                                  str(tmp_path / "d.pfm"), "--mono", str(files["mono"])])
    assert result.exit_code == 0, result.output
