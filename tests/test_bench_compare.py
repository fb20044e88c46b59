"""``bench compare``: two records of the same pairs, frame by frame, decided by an interval over scenes."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner

from benchmarks.compare import compare_records
from benchmarks.fusion import REGIONS
from webapp.cli import main


def _record(fusion_epe: list[list[float]], sha: str = "a" * 64) -> dict[str, Any]:
    """A record of 8 frames of 4 scenes whose fusion EPE per seed and frame is ``fusion_epe`` in every
    region, SGBM's 3 px; mirrors absent from the last two frames."""
    frames = [{"sample": f"s{i}", "scene": 2000 + i // 2} for i in range(8)]

    def rows(values: list[list[float]]) -> dict[str, Any]:
        out = {}
        for region in REGIONS:
            kept = [[v if region != "mirror" or i < 6 else None for i, v in enumerate(seed)] for seed in values]
            out[region] = {"epe": kept, "bad2": [[10 * v if v is not None else None for v in seed] for seed in kept]}
        return out

    methods = {"fusion": rows(fusion_epe), "sgbm": rows([[3.0] * 8])}
    return {"pairs": {"sha256": sha}, "seeds": len(fusion_epe), "per_frame": {"frames": frames, "methods": methods}}


def test_a_difference_is_decided_only_when_its_interval_excludes_zero() -> None:
    better = _record([[1.0, 1.2, 0.9, 1.1, 1.0, 1.3, 0.8, 1.0], [1.2, 1.0, 1.1, 0.9, 1.2, 1.1, 1.0, 0.8]])
    worse = _record([[1.5, 1.7, 1.4, 1.6, 1.5, 1.8, 1.3, 1.5]])
    found = compare_records(better, worse)
    assert found["scenes"] == 4 and found["seeds"] == [2, 1]
    epe = found["regions"]["all"]["epe"]
    assert epe["value"] == pytest.approx(-0.5, abs=1e-6) and epe["high"] < 0 and epe["decided"] == "lower"
    assert found["regions"]["mirror"]["epe"]["value"] == pytest.approx(-0.5, abs=1e-6)  # frames without mirrors left out
    assert found["regions"]["all"]["bad2"]["decided"] == "lower"
    mixed = _record([[1.0, 2.0, 2.0, 1.0, 1.0, 2.0, 2.0, 1.0]])
    even = compare_records(mixed, _record([[1.5] * 8]))["regions"]["all"]["epe"]
    assert even["value"] == pytest.approx(0.0, abs=1e-9) and even["decided"] == "undecided"
    against = compare_records(better, better, other="sgbm")["regions"]["all"]["epe"]
    assert against["value"] == pytest.approx(np.mean([1.1, 1.1, 1.0, 1.0, 1.1, 1.2, 0.9, 0.9]) - 3.0, abs=1e-3)  # rounded


def test_records_of_other_pairs_or_without_frames_are_refused() -> None:
    with pytest.raises(ValueError, match="different pairs"):
        compare_records(_record([[1.0] * 8]), _record([[1.0] * 8], sha="b" * 64))
    with pytest.raises(ValueError, match="per_frame"):
        compare_records({"pairs": {"sha256": "a" * 64}}, _record([[1.0] * 8]))
    with pytest.raises(KeyError, match="holds fusion, sgbm"):
        compare_records(_record([[1.0] * 8]), _record([[1.0] * 8]), other="stereo")


def test_cli_prints_each_region_and_refuses_what_does_not_compare(tmp_path: Path) -> None:
    first, second, third = tmp_path / "a.json", tmp_path / "b.json", tmp_path / "c.json"
    first.write_text(json.dumps(_record([[1.0, 1.2, 0.9, 1.1, 1.0, 1.3, 0.8, 1.0]])))
    second.write_text(json.dumps(_record([[1.5, 1.7, 1.4, 1.6, 1.5, 1.8, 1.3, 1.5]])))
    third.write_text(json.dumps(_record([[1.0] * 8], sha="b" * 64)))
    result = CliRunner().invoke(main, ["bench", "compare", str(first), str(second)])
    assert result.exit_code == 0, result.output
    assert "fusion of a.json minus fusion of b.json, 4 scenes" in result.output
    assert [line.split()[0] for line in result.output.splitlines()[1:]] == list(REGIONS)
    assert "epe -0.500" in result.output and "lower" in result.output
    shown = json.loads(CliRunner().invoke(main, ["bench", "compare", str(first), str(second), "--json"]).output)
    assert shown["regions"]["all"]["epe"]["decided"] == "lower"
    for args, message in (([str(first), str(third)], "different pairs"), ([str(first), str(second), "--other", "x"],
                                                                          "no method 'x'")):
        result = CliRunner().invoke(main, ["bench", "compare", *args])
        assert result.exit_code == 2 and message in result.output, result.output
