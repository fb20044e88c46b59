"""`illusion-studio evaluate --here --json` end to end on a KITTI folder written here."""

from __future__ import annotations

import json
from pathlib import Path

from click.testing import CliRunner

from core.formats import read_kitti_disparity, write_pfm
from tests.test_evaluate import _write_kitti
from webapp.cli import main


def write_predictions(kitti: Path, out: Path) -> None:
    """The KITTI folder's ground truth as ``predictions`` PFMs (``out/training/image_2/x.pfm``)."""
    for png in sorted((kitti / "training" / "disp_occ_0").glob("*.png")):
        pred = out / "training" / "image_2" / png.with_suffix(".pfm").name
        pred.parent.mkdir(parents=True, exist_ok=True)
        write_pfm(pred, read_kitti_disparity(png))


def _cli(home: Path, *args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(main, ["--data-dir", str(home), *args])
    return result.exit_code, result.stdout, result.stderr


def test_evaluate_here_json_on_a_kitti_folder(tmp_path: Path) -> None:
    home = tmp_path / "ws"
    assert _cli(home, "init")[0] == 0
    _write_kitti(tmp_path / "kitti")
    write_predictions(tmp_path / "kitti", tmp_path / "preds")
    out = tmp_path / "report"
    code, stdout, stderr = _cli(home, "evaluate", "--data", str(tmp_path / "kitti"), "--format", "kitti",
                                "--method", "sgbm", "--method", "predictions", "--predictions", str(tmp_path / "preds"),
                                "--out", str(out), "--here", "--json")
    assert code == 0, stderr
    report = json.loads(stdout)
    assert report["samples"] == 2 and report["resolution"] == "full" and report["dataset"] == "kitti"
    assert str(tmp_path) not in json.dumps(report)  # the report names folders, never server paths
    # Progress and one short closing line on stderr: the report itself only on stdout.
    closing = [line for line in stderr.splitlines() if line.startswith("job ") and "succeeded" in line]
    assert closing and len(closing[0]) < 200, stderr[-500:]
    assert set(report["methods"]) == {"sgbm", "predictions"}
    predictions = report["methods"]["predictions"]
    assert predictions["regions"]["all"]["epe"] == 0 and predictions["regions"]["all"]["bad2"] == 0
    assert {"epe", "bad1", "bad2", "bad3", "bad5"} <= set(report["methods"]["sgbm"]["regions"]["all"])
    assert len(predictions["per_sample"]) == 2 and (out / "index.html").is_file()


def test_evaluate_without_data_or_model_is_one_clear_error(tmp_path: Path) -> None:
    home = tmp_path / "ws"
    assert _cli(home, "init")[0] == 0
    code, _, stderr = _cli(home, "evaluate", "--method", "sgbm", "--run", "7", "--here")
    assert code != 0 and "run: no run 7" in stderr
    code, _, stderr = _cli(home, "evaluate", "--method", "sgbm", "--here")
    assert code != 0 and "test split" in stderr
    code, _, stderr = _cli(home, "evaluate", "--data", str(tmp_path), "--format", "kitti", "--here")
    assert code != 0 and "checkpoint" in stderr  # fusion by default, and no model promoted


def test_fusion_predictions_bring_their_confidence(tmp_path: Path) -> None:
    from types import SimpleNamespace

    import numpy as np

    from core.formats import read_pfm
    from dataset.readers import StereoSample
    from model.runs.evaluation import SeenSamples
    from model.runs.report import PredictionWriter

    image = np.zeros((4, 6, 3), np.uint8)
    sample = StereoSample(name="a/b", left=image, right=image, disparity=np.ones((4, 6), np.float32),
                          regions={"all": np.ones((4, 6), bool)}, mono=None, meta={"left": "a/b.png", "sample_id": 7})
    confidence = np.linspace(0, 1, 24, dtype=np.float32).reshape(4, 6)
    seen = SeenSamples(PredictionWriter(tmp_path), lambda s: SimpleNamespace(confidence=confidence))
    seen("fusion", sample, np.full((4, 6), 2.0, np.float32))
    seen("sgbm", sample, np.full((4, 6), 3.0, np.float32))
    assert np.array_equal(read_pfm(tmp_path / "predictions" / "confidence" / "a" / "b.pfm"), confidence)
    assert read_pfm(tmp_path / "predictions" / "sgbm" / "a" / "b.pfm")[0, 0] == 3.0
    assert not (tmp_path / "predictions" / "confidence" / "sgbm").exists()
    assert seen.sample_ids == {"a/b": 7} and seen.predictions == {"a/b": "a/b.pfm"}
