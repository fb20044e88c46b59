"""`illusion-studio table`: the paper's Table 1 for every method a workspace has (model/runs/table.py), and
`example-data motorcycle`, the real pair it is shown on."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from core.formats import write_pfm, write_rgb
from dataset.readers.middlebury import MiddleburyReader
from model.runs.table import CURRENT, Round, Row, format_table, plan_rounds, table_regions
from webapp.cli import main


def _cli(home: Path, *args: str):  # type: ignore[no-untyped-def]
    return CliRunner().invoke(main, ["--data-dir", str(home), *args])


def test_every_checkpoint_gets_a_round_and_the_first_round_the_methods_without_one() -> None:
    rounds = plan_rounds(True, [("imported:a", "raft_stereo"), ("imported:s", "selective_raft"),
                                ("imported:b", "raft_stereo")])
    assert rounds == [
        Round(("mono_gt_align", "raft_stereo", "selective_raft", "stereo", "mono_align", "fusion", "sgbm"),
              {"raft_stereo": "imported:a", "selective_raft": "imported:s", "stereo": CURRENT, "mono_align": CURRENT,
               "fusion": CURRENT}),
        Round(("raft_stereo",), {"raft_stereo": "imported:b"})]
    assert plan_rounds(False, []) == [Round(("mono_gt_align", "sgbm"), {})]


def test_the_table_has_the_papers_columns_drops_depth_without_a_camera_and_says_why_a_row_is_empty() -> None:
    figures = {"epe": 1.2345, "bad2": 12.5, "bad3": 8.0, "bad5": 3.25, "abs_rel": math.nan, "rmse": math.nan,
               "delta1": math.nan}
    rows = [Row("raft_stereo", "RAFT-Stereo", "imported:a", {"all": figures, "mirror": figures}, 2),
            Row("mono_gt_align", "mono + GT align", "", {}, 0, "no monocular disparity")]
    assert table_regions(rows) == ["all", "mirror"] and table_regions(rows, ["mirror"]) == ["mirror"]
    text = format_table(rows, ["all"]).splitlines()
    assert text[0] == "region: all" and text[1].split() == ["Method", "Checkpoint", "EPE", "bad2", "bad3", "bad5"]
    assert text[3].split() == ["RAFT-Stereo", "imported:a", "1.234", "12.50", "8.000", "3.250"]
    assert text[4].startswith("mono + GT align  –") and text[4].endswith("– (no monocular disparity)")
    markdown = format_table(rows, ["all"], markdown=True).splitlines()
    assert markdown[2] == "| Method | Checkpoint | EPE | bad2 | bad3 | bad5 |"
    assert markdown[4] == "| RAFT-Stereo | imported:a | 1.234 | 12.50 | 8.000 | 3.250 |"


def test_example_data_writes_the_motorcycle_as_a_middlebury_scene_with_its_camera(tmp_path: Path) -> None:
    result = CliRunner().invoke(main, ["example-data", "motorcycle", str(tmp_path / "mb")])
    assert result.exit_code == 0, result.output
    (sample,) = list(MiddleburyReader(tmp_path / "mb"))
    assert sample.left.shape == (500, 741, 3) and sample.disparity.shape == (500, 741)
    valid = np.isfinite(sample.disparity)
    assert 0.5 < valid.mean() < 1 and sample.camera is not None
    # depth = f·B / (d + doffs): the motorcycle stands about 2 m from the camera
    depth = sample.camera.fx * sample.camera.baseline / (np.median(sample.disparity[valid]) + sample.camera.doffs)
    assert 1.5 < depth < 3.0, depth


@pytest.fixture()
def tiny_middlebury(tmp_path: Path) -> Path:
    """A 64×96 Middlebury scene: the Motorcycle's centre, every 4th pixel (disparity scaled with it)."""
    import skimage.data

    from tests.raft_golden import motorcycle_pair

    left, right = motorcycle_pair(4)
    disparity = skimage.data.stereo_motorcycle()[2][::4, ::4] / 4
    scene = tmp_path / "data" / "Tiny-perfect"
    scene.mkdir(parents=True)
    write_rgb(scene / "im0.png", left[30:94, 40:136])
    write_rgb(scene / "im1.png", right[30:94, 40:136])
    write_pfm(scene / "disp0.pfm", np.ascontiguousarray(disparity[30:94, 40:136], np.float32))
    return tmp_path / "data"


def test_the_table_scores_every_imported_network_once_beside_sgbm(tmp_path: Path, tiny_middlebury: Path) -> None:
    torch = pytest.importorskip("torch")
    from tests.raft_golden import fixture_state, load_fixture

    home = tmp_path / "ws"
    assert _cli(home, "init").exit_code == 0
    published = tmp_path / "realtime.pth"
    torch.save(fixture_state(load_fixture("realtime")), published)
    for name in ("rt-a", "rt-b"):  # the same network twice: two rounds, the same figures
        assert _cli(home, "checkpoints", "import", "--from", "raft-stereo", str(published), "--name", name).exit_code == 0
    result = _cli(home, "table", "--data", str(tiny_middlebury), "--format", "middlebury", "--json")
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    rows = {(row["method"], row["checkpoint"]): row for row in doc["rows"]}
    assert list(rows) == [("mono_gt_align", ""), ("raft_stereo", "imported:rt-a"), ("raft_stereo", "imported:rt-b"),
                          ("sgbm", "")]
    assert rows[("mono_gt_align", "")]["missing"].startswith("this dataset carries no monocular disparity")
    a, b = rows[("raft_stereo", "imported:rt-a")], rows[("raft_stereo", "imported:rt-b")]
    assert a["regions"]["all"]["epe"] == b["regions"]["all"]["epe"] and a["samples"] == 1
    # the figures are evaluate's own
    direct = _cli(home, "evaluate", "--data", str(tiny_middlebury), "--format", "middlebury", "--method", "sgbm",
                  "--here", "--json")
    assert direct.exit_code == 0, direct.output
    assert rows[("sgbm", "")]["regions"]["all"] == json.loads(direct.stdout)["methods"]["sgbm"]["regions"]["all"]
    text = _cli(home, "table", "--data", str(tiny_middlebury), "--format", "middlebury")
    assert text.exit_code == 0, text.output
    lines = text.stdout.splitlines()  # the table alone: the jobs' progress goes to stderr
    assert lines[0] == "region: all" and lines[1].split()[:3] == ["Method", "Checkpoint", "EPE"]
    assert [line.split()[:2] for line in lines[4:6]] == [["RAFT-Stereo", "imported:rt-a"], ["RAFT-Stereo", "imported:rt-b"]]


def test_synth_writes_the_benchmarks_held_out_scenes_and_the_synthetic_reader_reads_them_back(tmp_path: Path) -> None:
    from benchmarks import fusion
    from dataset.readers import open_reader

    seeds = fusion.TEST_SEEDS[:2]
    result = CliRunner().invoke(main, ["synth", str(tmp_path / "test"), "--videos", "2", "--seed", str(seeds[0]),
                                       "--frames", str(fusion.HELD_OUT_FRAMES), "--size", "x".join(map(str, fusion.SIZE)),
                                       "--families", "--baseline-m", str(fusion.HELD_OUT_BASELINE_M)])
    assert result.exit_code == 0, result.output
    reader = open_reader("synthetic", tmp_path / "test")
    samples = [reader[i] for i in range(len(reader))]
    # bit for bit the pairs `bench fusion` scores: images, truth, mono and names
    assert fusion.pairs_digest(samples) == fusion.pairs_digest(fusion.held_out_samples(seeds))
    assert {"all", "illusion", "picture", "mirror", "non_illusion"} <= set(samples[0].regions)
    assert samples[0].camera is not None and samples[0].camera.baseline == fusion.HELD_OUT_BASELINE_M
    assert samples[0].meta["left"] == "synthetic-families-1000/frames/000000/left.png"
