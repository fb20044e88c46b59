"""Native export/import: byte-identical round trip, idempotent import, splits by video, clear errors, CLI.

The ``source`` and ``fresh`` workspaces come from tests/fixtures/workspaces.py.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from click.testing import CliRunner
from pycocotools.coco import COCO
from sqlalchemy import select

from core.formats import read_mask
from dataset.export import LayoutError, export_params, parse_split_spec, split_of
from dataset.tables import Job, JobState
from tests.fixtures.workspaces import SEED, SPLIT, counts, export, import_, run_job, tree
from webapp.cli import main
from webapp.runtime import Runtime


def test_round_trip_is_byte_identical(source: Runtime, fresh: Runtime, tmp_path: Path) -> None:
    first = tmp_path / "first"
    result = export(source, first, split=SPLIT, seed=SEED)
    assert result["samples"] == 6 and [s["samples"] for s in result["splits"].values()] == [3, 3]
    job = import_(fresh, first)
    assert job.state == JobState.succeeded, job.error
    assert job.result == {"path": str(first), "format": "native", "samples": 6, "added": 6, "present": 0, "conflicts": 0}
    assert counts(fresh) == {"Video": 4, "Frame": 6, "Annotation": 5, "Region": 5 * 4, "Sample": 6}
    second = tmp_path / "second"
    export(fresh, second, split=SPLIT, seed=SEED)
    a, b = tree(first), tree(second)
    assert a.keys() == b.keys()
    assert [name for name in a if a[name] != b[name]] == []  # every file, the manifest included


def test_layout_manifest_and_coco(source: Runtime, tmp_path: Path) -> None:
    out = tmp_path / "ds"
    export(source, out, split=SPLIT, seed=SEED)
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["format"] == "illusion-studio/native" and manifest["created_by"].startswith("illusion-studio ")
    capture = next(s for s in manifest["samples"] if s["provenance"]["source"] == "capture")
    assert capture["id"] == "lab_scene_tv/000003" and capture["frame"]["index"] == 3
    base = out / capture["split"] / "lab_scene_tv" / "000003"
    assert {p.name for p in base.iterdir()} == {"left.png", "right.png", "disparity.pfm", "valid.png", "masks"}
    assert [p.name for p in (base / "masks").iterdir()] == ["illusion_00.png"]
    synthesized = next(s for s in manifest["samples"] if s["provenance"]["source"] == "synthesized")
    assert set(synthesized["files"]) == {"left", "right", "disparity", "disparity_rect", "disparity_mono", "holes", "masks"}
    assert synthesized["params"]["scale"] > 0 and "flags" in synthesized["qa"]
    for split in manifest["splits"]:
        coco = COCO(str(out / split["annotations"]))
        assert len(coco.getImgIds()) == split["samples"]
        for ann in coco.loadAnns(coco.getAnnIds()):
            image = coco.loadImgs(ann["image_id"])[0]
            kind, pair = ann["attributes"]["kind"], ann["attributes"]["pair"]
            png = out / Path(image["file_name"]).parent / "masks" / f"{kind}_{pair:02d}.png"
            assert np.array_equal(coco.annToMask(ann).astype(bool), read_mask(png))
            types = next(s["provenance"].get("pair_types", {}) for s in manifest["samples"] if s["id"] == image["sample"])
            expected = "unspecified" if image["sample"] == capture["id"] else types[f"illusion_{pair:02d}"]
            assert coco.loadCats(ann["category_id"])[0]["name"] == f"{expected}/{kind}"


def test_state_filter(source: Runtime, tmp_path: Path) -> None:
    assert export(source, tmp_path / "acc")["samples"] == 6
    assert export(source, tmp_path / "all", states=["generated", "accepted"])["samples"] == 7
    job = run_job(source, "export", export_params(tmp_path / "none", format="native", states=["rejected"]))
    assert job.state == JobState.failed and "no samples to export" in job.error
    assert not (tmp_path / "none").exists()


def test_import_twice_adds_nothing(source: Runtime, fresh: Runtime, tmp_path: Path) -> None:
    export(source, tmp_path / "ds")
    assert import_(fresh, tmp_path / "ds").result["added"] == 6
    before = counts(fresh)
    again = import_(fresh, tmp_path / "ds")
    assert again.state == JobState.succeeded and (again.result["added"], again.result["present"]) == (0, 6)
    assert counts(fresh) == before
    # into the workspace it came from: everything is there already
    home = counts(source)
    assert import_(source, tmp_path / "ds").result["present"] == 6 and counts(source) == home


def test_an_interrupted_import_resumes(source: Runtime, fresh: Runtime, tmp_path: Path,
                                      monkeypatch: pytest.MonkeyPatch) -> None:
    import dataset.export.handlers as export_jobs

    export(source, tmp_path / "ds")
    calls = []

    def crash_on_the_fourth(*args: Any) -> str:
        calls.append(1)
        if len(calls) == 4:
            raise RuntimeError("worker killed")
        return add_sample(*args)

    add_sample = export_jobs.add_sample
    monkeypatch.setattr(export_jobs, "add_sample", crash_on_the_fourth)
    assert import_(fresh, tmp_path / "ds").state == JobState.failed
    assert counts(fresh)["Sample"] == 3
    monkeypatch.undo()
    result = import_(fresh, tmp_path / "ds").result
    assert (result["added"], result["present"]) == (3, 3) and counts(fresh)["Sample"] == 6


def test_splits_are_by_video_and_deterministic(source: Runtime, tmp_path: Path) -> None:
    spec = parse_split_spec("train=0.7,val=0.1,test=0.2")
    names = [f"video-{n}" for n in range(400)]
    assignment = {n: split_of(n, spec, seed=5) for n in names}
    assert assignment == {n: split_of(n, spec, seed=5) for n in names}
    assert assignment != {n: split_of(n, spec, seed=6) for n in names}
    shares = {s: sum(v == s for v in assignment.values()) / len(names) for s in spec}
    assert all(abs(shares[s] - spec[s]) < 0.07 for s in spec), shares
    manifests = []
    for seed in (1, 2):
        export(source, tmp_path / f"s{seed}", split=SPLIT, seed=seed)
        manifests.append(json.loads((tmp_path / f"s{seed}" / "manifest.json").read_text()))
    for manifest in manifests:
        split_videos = [set(s["videos"]) for s in manifest["splits"]]
        assert split_videos[0].isdisjoint(split_videos[1]) and len(split_videos[0] | split_videos[1]) == 4
        for sample in manifest["samples"]:
            assert sample["split"] == split_of(sample["video"], parse_split_spec(SPLIT), manifest["seed"])
            assert sample["files"]["left"]["path"].startswith(f"{sample['split']}/{sample['video']}/")
    for bad, message in [("train=0.8,test=0.3", "sum to 1"), ("Train=1", "bad split"), ("train", "bad split"),
                         ("train=0.5,train=0.5", "named twice")]:
        with pytest.raises(LayoutError, match=message):
            parse_split_spec(bad)
    with pytest.raises(LayoutError, match="no splits"):
        export_params(tmp_path / "x", format="authors", split=SPLIT)


def test_bad_input_is_refused_with_a_clear_error(source: Runtime, fresh: Runtime, tmp_path: Path) -> None:
    (tmp_path / "empty").mkdir()
    job = import_(fresh, tmp_path / "empty")
    assert job.state == JobState.failed and "no manifest.json" in job.error
    out = tmp_path / "ds"
    export(source, out)
    manifest = json.loads((out / "manifest.json").read_text())
    victim = out / manifest["samples"][2]["files"]["disparity"]["path"]
    victim.unlink()
    job = import_(fresh, out)
    assert job.state == JobState.failed and f"{victim.name}: missing" in job.error and str(victim) not in job.error
    export(source, out, overwrite=True)
    mask = out / manifest["samples"][1]["files"]["masks"]["illusion_00"]["path"]
    mask.write_bytes(b"not a png")
    assert "does not match its SHA-256" in import_(fresh, out).error
    export(source, out, overwrite=True)
    sample = manifest["samples"][1]
    small = cv2.imencode(".png", np.zeros((10, 12), np.uint8))[1].tobytes()
    (out / sample["files"]["holes"]["path"]).write_bytes(small)
    sample["files"]["holes"]["sha256"] = hashlib.sha256(small).hexdigest()
    (out / "manifest.json").write_text(json.dumps(manifest))
    job = import_(fresh, out)
    assert job.state == JobState.failed and "12x10 pixels, but its frame is 96x64" in job.error
    assert counts(fresh) == {"Video": 0, "Frame": 0, "Annotation": 0, "Region": 0, "Sample": 0}


def test_export_is_atomic(source: Runtime, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import dataset.export.native as native

    out = tmp_path / "ds"
    monkeypatch.setattr(native, "coco_document", lambda *a: 1 / 0)
    job = run_job(source, "export", export_params(out, format="native"))
    assert job.state == JobState.failed and "ZeroDivisionError" in job.error
    assert not out.exists() and list(tmp_path.iterdir()) == []
    monkeypatch.undo()
    out.mkdir()  # an empty folder is fine: it is replaced in one rename
    params = export_params(out, format="native")
    export(source, out)
    with pytest.raises(LayoutError, match="not an empty folder"):
        export_params(out, format="native")
    job = run_job(source, "export", params)  # checked again when the job starts
    assert job.state == JobState.failed and "not an empty folder" in job.error


def test_cli_export_and_import_here(source: Runtime, fresh: Runtime, tmp_path: Path) -> None:
    runner = CliRunner()
    out = tmp_path / "cli-ds"
    result = runner.invoke(main, ["--data-dir", str(source.settings.home), "export", "--format", "native", str(out),
                                    "--split", SPLIT, "--seed", str(SEED), "--here"])
    assert result.exit_code == 0, result.output
    assert "export native" in result.output and '"samples": 6' in result.output
    assert (out / "manifest.json").is_file()
    args = ["--data-dir", str(fresh.settings.home), "import", "--format", "native", str(out), "--here"]
    result = runner.invoke(main, args)
    assert result.exit_code == 0, result.output
    assert '"added": 6' in result.output and counts(fresh)["Sample"] == 6
    with fresh.sessions() as s:
        assert [j.kind for j in s.scalars(select(Job))] == ["import"]
    bad = runner.invoke(main, ["--data-dir", str(fresh.settings.home), "import", "--format", "authors", str(out),
                                 "--here"])
    assert bad.exit_code == 1 and "not the authors' layout" in bad.output
    bad = runner.invoke(main, ["--data-dir", str(fresh.settings.home), "export", "--format", "native",
                                 str(tmp_path / "x"), "--split", "train=2"])
    assert bad.exit_code == 1 and "sum to 1" in bad.output and not (tmp_path / "x").exists()
