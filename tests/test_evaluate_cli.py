"""`illusion-studio evaluate --here --json` end to end on a KITTI folder written here."""

from __future__ import annotations

import json
from pathlib import Path

from click.testing import CliRunner

from dataset.formats import write_kitti_disparity, write_pfm, write_rgb
from dataset.synthetic import render_video
from webapp.cli import main


def write_kitti(root: Path, count: int = 2) -> None:
    """A KITTI 2015 training layout of rendered pairs, and the ground truth as ``predictions`` PFMs."""
    for folder in ("image_2", "image_3", "disp_occ_0"):
        (root / "training" / folder).mkdir(parents=True)
    for i in range(count):
        frame = render_video(i, n_frames=1, width=128, height=64).frames[0]
        name = f"{i:06d}_10.png"
        write_rgb(root / "training" / "image_2" / name, frame.left)
        write_rgb(root / "training" / "image_3" / name, frame.right)
        write_kitti_disparity(root / "training" / "disp_occ_0" / name, frame.disparity)
        pred = root.parent / "preds" / "training" / "image_2" / name.replace(".png", ".pfm")
        pred.parent.mkdir(parents=True, exist_ok=True)
        write_pfm(pred, (frame.disparity * 256).round() / 256)  # as KITTI's uint16 stores it


def _cli(home: Path, *args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(main, ["--data-dir", str(home), *args])
    return result.exit_code, result.stdout, result.stderr


def test_evaluate_here_json_on_a_kitti_folder(tmp_path: Path) -> None:
    home = tmp_path / "ws"
    assert _cli(home, "init")[0] == 0
    write_kitti(tmp_path / "kitti")
    out = tmp_path / "report"
    code, stdout, stderr = _cli(home, "evaluate", "--data", str(tmp_path / "kitti"), "--format", "kitti",
                                "--method", "sgbm", "--method", "predictions", "--predictions", str(tmp_path / "preds"),
                                "--out", str(out), "--here", "--json")
    assert code == 0, stderr
    report = json.loads(stdout)
    assert report["samples"] == 2 and report["resolution"] == "full" and report["dataset"] == str(tmp_path / "kitti")
    assert set(report["methods"]) == {"sgbm", "predictions"}
    predictions = report["methods"]["predictions"]
    assert predictions["regions"]["all"]["epe"] < 1e-3 and predictions["regions"]["all"]["bad2"] == 0
    assert {"epe", "bad1", "bad2", "bad3", "bad5"} <= set(report["methods"]["sgbm"]["regions"]["all"])
    assert len(predictions["per_sample"]) == 2 and (out / "index.html").is_file()


def test_evaluate_without_data_or_model_is_one_clear_error(tmp_path: Path) -> None:
    home = tmp_path / "ws"
    assert _cli(home, "init")[0] == 0
    code, _, stderr = _cli(home, "evaluate", "--method", "sgbm", "--run", "7", "--here")
    assert code != 0 and "test split" in stderr
    code, _, stderr = _cli(home, "evaluate", "--data", str(tmp_path), "--format", "kitti", "--here")
    assert code != 0 and "checkpoint" in stderr  # fusion by default, and no model promoted
