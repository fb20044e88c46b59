"""The authors' layout: export, import, the round trip within the uint16 quantisation, and files
written the way the authors' own tools wrote them (absolute CSV paths, JPEG masks, mask parts)."""

from __future__ import annotations

import os
import pickle
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner
from sqlalchemy import select

from core.formats import read_pfm, write_pfm
from dataset.export import HANDLERS as EXPORT_HANDLERS
from dataset.samples import load_outputs
from dataset.tables import Annotation, Frame, JobState, Sample, SourceKind, Video
from tests.fixtures.workspaces import counts, export, import_, tree
from webapp.cli import main
from webapp.jobs.handlers import HANDLERS
from webapp.runtime import Runtime

QUANTUM = 1 / 16  # one uint16 step of depth_rect, in unscaled disparity units


def samples_by_name(rt: Runtime) -> dict[tuple[str, int], tuple[Sample, dict]]:
    """(video name, frame index) → (sample, its outputs as arrays)."""
    with rt.sessions() as s:
        rows = s.execute(select(Sample, Frame, Video).join(Frame, Frame.id == Sample.frame_id)
                         .join(Video, Video.id == Frame.video_id)).all()
    return {(v.name, f.index): (sample, load_outputs(rt.media, sample.files)) for sample, f, v in rows}


def test_export_writes_the_authors_layout(source: Runtime, tmp_path: Path) -> None:
    out = tmp_path / "authors"
    result = export(source, out, format="authors")
    assert (result["training"], result["testing"], result["zeroed_disparity_px"]) == (5, 1, 0)
    lines = (out / "meta_data" / "scale_factors.csv").read_text().splitlines()
    assert len(lines) == 5 and lines == sorted(lines)
    right, scale = lines[0].rsplit(",", 1)
    assert right == "video_frame_sequence_right/synthetic-0000/mirror+picture/frame_0000.png" and float(scale) > 0
    for part in ("video_frame_sequence", "video_frame_sequence_right", "depth_rect"):
        assert (out / right.replace("video_frame_sequence_right", part)).is_file()
    depth = cv2.imread(str(out / "depth_rect/synthetic-0000/mirror+picture/frame_0000.png"), cv2.IMREAD_UNCHANGED)
    assert depth.dtype == np.uint16 and depth.ndim == 2 and depth.max() > 0
    masks = sorted(p.name for p in (out / "sam_mask/synthetic-0000/mirror+picture").glob("frame_0000-*"))
    assert masks == ["frame_0000-00-00-illusion.png", "frame_0000-00-00-nonillusion.png",
                     "frame_0000-01-00-illusion.png", "frame_0000-01-00-nonillusion.png"]
    with (out / "meta_data" / "testing_enter.pkl").open("rb") as fh:
        index = pickle.load(fh)
    assert index == {("lab_scene_tv", "00", "000003"): {
        "left": "left/lab_scene_tv_00/frame_000003.png", "right": "right/lab_scene_tv_00/frame_000003.png",
        "disp": "disp/lab_scene_tv_00/frame_000003.pfm", "mask": "mask/lab_scene_tv_00/frame_000003.png"}}
    mask = cv2.imread(str(out / "testing" / index[("lab_scene_tv", "00", "000003")]["mask"]), cv2.IMREAD_GRAYSCALE)
    disp = read_pfm(out / "testing/disp/lab_scene_tv_00/frame_000003.pfm")
    assert set(np.unique(mask)) == {0, 255} and not (mask[~np.isfinite(disp)] > 0).any()


def test_round_trip_keeps_disparity_within_the_uint16_step(source: Runtime, fresh: Runtime, tmp_path: Path) -> None:
    out = tmp_path / "authors"
    export(source, out, format="authors")
    job = import_(fresh, out, "authors")
    assert job.state == JobState.succeeded, job.error
    assert job.result["added"] == 6
    after = samples_by_name(fresh)
    worst = 0.0
    for (video, index), (sample, old) in samples_by_name(source).items():
        if sample.state.value != "accepted":
            continue
        capture = sample.provenance["source"] == "capture"
        # names: <scene>_<obj> for the capture; <video folder>/<illusion type> for training data
        new_sample, new = after["lab_scene_tv_00" if capture else f"{video}/mirror+picture", index]
        assert np.array_equal(new["left"], old["left"]) and np.array_equal(new["right"], old["right"])
        if capture:
            # PFM is exact; the test mask is illusion ∧ valid, and only pair 0's illusion survives
            assert np.array_equal(new["disparity"], old["disparity"], equal_nan=True)
            assert np.array_equal(new["valid"], old["valid"])
            assert np.array_equal(new["masks"]["illusion_00"], old["masks"]["illusion_00"] & old["valid"])
            continue
        s = sample.params["scale"]
        assert new_sample.params["scale"] == s  # exact: the CSV holds s/16 as a shortest round-trip decimal
        # Quantisation enters once, at export: round(d/s · 16), so |Δd/s| ≤ 1/32 (+ float32 rounding).
        error = np.abs(new["disparity"].astype(np.float64) - old["disparity"]) / s
        worst = max(worst, float(error.max()))
        assert error.max() <= QUANTUM / 2 + 1e-5
        assert np.abs(new["disparity_rect"] - old["disparity"] / s).max() <= QUANTUM / 2 + 1e-5
        assert new["masks"].keys() == old["masks"].keys()
        assert all(np.array_equal(new["masks"][m], old["masks"][m]) for m in old["masks"])
    assert 0 < worst <= 1 / 32 + 1e-5
    # the names the data came with are kept: exporting it again gives the same files, byte for byte
    again = tmp_path / "again"
    export(fresh, again, format="authors")
    assert tree(again) == tree(out)
    with fresh.sessions() as s:
        kinds = {v.name: v.source_kind for v in s.scalars(select(Video))}
        assert kinds["lab_scene_tv_00"] == SourceKind.real_capture
        assert s.scalar(select(Annotation).limit(1)).submitted


def test_jpeg_masks_are_written_and_read(source: Runtime, fresh: Runtime, tmp_path: Path) -> None:
    out = tmp_path / "jpg"
    export(source, out, format="authors", mask_format="jpg")
    assert {p.suffix for p in (out / "sam_mask").rglob("*.*")} == {".jpg"}
    assert import_(fresh, out, "authors").result["added"] == 6
    old = {k[1]: v for k, v in samples_by_name(source).items() if k[0] == "synthetic-0001"}
    new = {k[1]: v for k, v in samples_by_name(fresh).items() if k[0] == "synthetic-0001/mirror+picture"}
    for index, (_, outputs) in new.items():
        for name, mask in outputs["masks"].items():
            assert (mask != old[index][1]["masks"][name]).mean() < 0.001  # JPEG at quality 100, thresholded at 128


def write_authors_tree(root: Path) -> None:
    """A tiny dataset as the authors' scripts wrote it: absolute CSV paths, JPEG masks split in parts,
    test data under real_data/testing/<scene>/<obj>/ with inf where the depth was 0."""
    h, w = 32, 40
    rng = np.random.default_rng(1)
    rel = Path("vid_a/scene_1/frame_0007.png")
    for part in ("video_frame_sequence", "video_frame_sequence_right"):
        (root / part / rel).parent.mkdir(parents=True)
        cv2.imwrite(str(root / part / rel), rng.integers(0, 255, (h, w, 3), dtype=np.uint8))
    (root / "depth_rect" / rel).parent.mkdir(parents=True)
    cv2.imwrite(str(root / "depth_rect" / rel), np.full((h, w), 160, np.uint16))  # 10 px before scaling
    masks = root / "sam_mask/vid_a/scene_1"
    masks.mkdir(parents=True)
    left_half, right_half = np.zeros((h, w), np.uint8), np.zeros((h, w), np.uint8)
    left_half[8:24, 8:20], right_half[8:24, 20:32] = 255, 255
    cv2.imwrite(str(masks / "frame_0007-00-00-illusion.jpg"), left_half)
    cv2.imwrite(str(masks / "frame_0007-00-01-illusion.jpg"), right_half)
    cv2.imwrite(str(masks / "frame_0007-00-00-nonillusion.jpg"), 255 - left_half - right_half)
    cv2.imwrite(str(masks / "frame_0070-00-00-illusion.jpg"), left_half)  # another frame's: not ours
    (root / "meta_data").mkdir()
    (root / "meta_data/scale_factors.csv").write_text(
        f"/data2/Fooling3D/video_frame_sequence_right/{rel.as_posix()},0.25\n")
    test = root / "real_data/testing"
    entry = {p: f"{p}/lab/tv/frame_12.{ext}" for p, ext in
             (("left", "png"), ("right", "png"), ("disp", "pfm"), ("mask", "jpg"))}
    for part in ("left", "right"):
        (test / entry[part]).parent.mkdir(parents=True)
        cv2.imwrite(str(test / entry[part]), rng.integers(0, 255, (h, w, 3), dtype=np.uint8))
    disp = np.full((h, w), 30.0, np.float32)
    disp[0, :5] = np.inf
    (test / entry["disp"]).parent.mkdir(parents=True)
    write_pfm(test / entry["disp"], disp, little_endian=False)
    (test / entry["mask"]).parent.mkdir(parents=True)
    cv2.imwrite(str(test / entry["mask"]), left_half)
    with (root / "meta_data/testing_enter.pkl").open("wb") as fh:
        pickle.dump({("lab", "tv", "12"): entry}, fh)


def test_import_reads_what_the_authors_wrote(fresh: Runtime, tmp_path: Path) -> None:
    write_authors_tree(tmp_path / "theirs")
    job = import_(fresh, tmp_path / "theirs", "authors")
    assert job.state == JobState.succeeded, job.error
    assert (job.result["added"], counts(fresh)["Video"]) == (2, 2)
    samples = samples_by_name(fresh)
    sample, train = samples[("vid_a/scene_1", 7)]
    assert sample.params == {"scale": 4.0} and sample.provenance["authors"] == {
        "video": "vid_a", "title": "scene_1", "frame": "frame_0007"}
    assert np.all(train["disparity"] == 40.0) and np.all(train["disparity_rect"] == 10.0)
    assert train["masks"].keys() == {"illusion_00", "support_00"}
    assert train["masks"]["illusion_00"][8:24, 8:32].all() and train["masks"]["illusion_00"].sum() == 16 * 24
    sample, test = samples[("lab_tv", 12)]
    assert sample.provenance["source"] == "capture" and sample.params == {"scale": 1.0}
    assert np.isnan(test["disparity"][0, :5]).all() and not test["valid"][0, :5].any() and test["valid"].sum() == 32 * 40 - 5
    assert test["masks"]["illusion_00"].sum() == 16 * 12
    assert import_(fresh, tmp_path / "theirs", "authors").result["present"] == 2


def test_bad_authors_input(fresh: Runtime, tmp_path: Path) -> None:
    root = tmp_path / "theirs"
    write_authors_tree(root)
    depth = root / "depth_rect/vid_a/scene_1/frame_0007.png"
    os.rename(depth, depth.with_suffix(".bak"))
    job = import_(fresh, root, "authors")
    assert job.state == JobState.failed and f"{depth.name}: missing" in job.error
    os.rename(depth.with_suffix(".bak"), depth)
    cv2.imwrite(str(root / "sam_mask/vid_a/scene_1/frame_0007-00-00-illusion.jpg"), np.zeros((8, 8), np.uint8))
    assert "8x8 pixels, but its frame is 40x32" in import_(fresh, root, "authors").error
    (root / "meta_data/scale_factors.csv").unlink()

    class Evil:
        def __reduce__(self):  # type: ignore[no-untyped-def]
            return (os.system, ("touch pwned",))

    (root / "meta_data/testing_enter.pkl").write_bytes(pickle.dumps({("a", "b", "1"): Evil()}))
    job = import_(fresh, root, "authors")
    assert job.state == JobState.failed and "refusing to load" in job.error and not Path("pwned").exists()
    (root / "meta_data/testing_enter.pkl").unlink()
    assert "not the authors' layout" in import_(fresh, root, "authors").error
    assert counts(fresh)["Sample"] == 0


def test_cli_queues_for_a_worker(fresh: Runtime, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    for kind, handler in EXPORT_HANDLERS.items():  # what webapp/jobs/handlers.py registers
        monkeypatch.setitem(HANDLERS, kind, handler)
    runner = CliRunner()
    home = ["--data-dir", str(fresh.settings.home)]
    write_authors_tree(tmp_path / "theirs")
    result = runner.invoke(main, [*home, "import", "--format", "authors", str(tmp_path / "theirs")])
    assert result.exit_code == 0 and "queued for a worker" in result.output
    assert counts(fresh)["Sample"] == 0
    result = runner.invoke(main, [*home, "worker", "--burst"])
    assert result.exit_code == 0 and "succeeded" in result.output and counts(fresh)["Sample"] == 2


def test_an_index_naming_files_outside_the_dataset_is_refused(tmp_path: Path) -> None:
    from dataset.export.authors_import import _within
    from dataset.export.errors import LayoutError

    root = tmp_path / "theirs"
    root.mkdir()
    assert _within(root, {"left": root / "a" / "b.png"}, "x")
    with pytest.raises(LayoutError, match="leaves the dataset folder"):
        _within(root, {"left": root / "video_frame_sequence" / ".." / ".." / "secret.png"}, "scale_factors.csv line 3")
    with pytest.raises(LayoutError, match="leaves the dataset folder"):
        _within(root, {"left": Path("/etc/passwd")}, "testing_enter.pkl entry")
