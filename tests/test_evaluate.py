"""Evaluation: per-sample and pooled metrics, methods that need no network, failures, the report."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from core.formats import read_pfm, write_kitti_disparity, write_pfm, write_rgb
from dataset.readers import SampleError, StereoSample, open_reader
from dataset.readers.base import make_regions
from dataset.synthetic import render_video
from model.evaluate import EvalOptions, evaluate, iter_reader, mean_over_samples
from model.methods import build_methods
from model.runs.report import PredictionWriter, write_report


def _sample(name: str, gt: np.ndarray, masks: dict[str, np.ndarray] | None = None,
            mono: np.ndarray | None = None) -> StereoSample:
    h, w = gt.shape
    image = np.zeros((h, w, 3), np.uint8)
    return StereoSample(name=name, left=image, right=image, disparity=gt.astype(np.float32),
                        regions=make_regions(gt, masks), mono=mono, meta={"left": f"{name}.png"})


def test_ground_truth_as_prediction_scores_zero() -> None:
    video = render_video(0, n_frames=2, width=96, height=54)
    samples = [_sample(f"f{f.index}", f.disparity, {"illusion": f.regions[0].illusion}) for f in video.frames]
    report = evaluate(samples, {"gt": lambda s: s.disparity}, EvalOptions())
    regions = report["methods"]["gt"]["regions"]
    assert report["samples"] == 2 and not report["failed"]
    for region in ("all", "illusion"):
        assert regions[region]["epe"] == 0 and regions[region]["bad2"] == 0 and regions[region]["samples"] == 2


def test_headline_is_the_mean_over_samples_and_pooled_sits_beside_it() -> None:
    gt = np.zeros((2, 2), np.float32)
    one_bad_pixel = _sample("a", np.array([[0, np.nan], [np.nan, np.nan]], np.float32))
    four_good = _sample("b", gt)
    preds = {"a": np.full((2, 2), 2.5, np.float32), "b": gt}
    report = evaluate([one_bad_pixel, four_good], {"m": lambda s: preds[s.name]}, EvalOptions())
    method = report["methods"]["m"]
    assert method["regions"]["all"]["epe"] == pytest.approx((2.5 + 0) / 2)  # per image, then averaged
    assert method["pooled"]["all"]["epe"] == pytest.approx(2.5 / 5)  # every pixel alike
    assert method["regions"]["all"]["bad2"] == pytest.approx(50.0)  # percent
    assert method["pooled"]["all"]["bad2"] == pytest.approx(20.0)


def test_an_empty_region_does_not_count_for_that_image() -> None:
    rows = [{"sample": "a", "regions": {"mirror": {"epe": float("nan")}}},
            {"sample": "b", "regions": {"mirror": {"epe": 3.0}}}]
    assert mean_over_samples(rows) == {"mirror": {"epe": 3.0, "samples": 1}}


def test_a_failing_sample_is_reported_and_skipped() -> None:
    def flaky(sample: StereoSample) -> np.ndarray:
        if sample.name == "bad":
            raise SampleError("no prediction for bad")
        return sample.disparity

    samples = [_sample("good", np.ones((4, 4))), _sample("bad", np.ones((4, 4)))]
    report = evaluate(samples, {"m": flaky}, EvalOptions())
    assert report["failed"] == [{"sample": "bad", "method": "m", "reason": "no prediction for bad"}]
    assert [r["sample"] for r in report["methods"]["m"]["per_sample"]] == ["good"]


def test_mono_gt_align_fits_on_non_illusion_pixels_only() -> None:
    gt = np.tile(np.linspace(10, 40, 16, dtype=np.float32), (8, 1))
    illusion = np.zeros_like(gt, bool)
    illusion[2:6, 4:12] = True
    mono = (gt - 10) / 30  # the true shape up to an affine map…
    mono[illusion] = 5.0  # …except where the picture fools it
    sample = _sample("s", gt, {"illusion": illusion, "non_illusion": ~illusion}, mono=mono)
    methods = build_methods(["mono_gt_align"], checkpoint=None, predictions=None, mono_dir=None)
    report = evaluate([sample], methods, EvalOptions())
    regions = report["methods"]["mono_gt_align"]["regions"]
    assert regions["non_illusion"]["epe"] == pytest.approx(0, abs=1e-4)
    assert regions["illusion"]["epe"] > 50


def test_predictions_of_another_resolution_are_resized(tmp_path: Path) -> None:
    gt = np.full((20, 40), 8.0, np.float32)
    sample = _sample("scene/frame_0001", gt)
    (tmp_path / "scene").mkdir()
    write_pfm(tmp_path / "scene" / "frame_0001.pfm", np.full((10, 20), 4.0, np.float32))  # half size, half disparity
    methods = build_methods(["predictions"], checkpoint=None, predictions=tmp_path, mono_dir=None)
    report = evaluate([sample], methods, EvalOptions())
    assert report["methods"]["predictions"]["regions"]["all"]["epe"] == pytest.approx(0, abs=1e-5)
    missing = _sample("scene/frame_0002", gt)
    assert "no prediction" in evaluate([missing], methods, EvalOptions())["failed"][0]["reason"]


def _write_kitti(root: Path, count: int = 2) -> None:
    for folder in ("image_2", "image_3", "disp_occ_0"):
        (root / "training" / folder).mkdir(parents=True)
    for i in range(count):
        frame = render_video(i, n_frames=1, width=128, height=64).frames[0]
        name = f"{i:06d}_10.png"
        write_rgb(root / "training" / "image_2" / name, frame.left)
        write_rgb(root / "training" / "image_3" / name, frame.right)
        write_kitti_disparity(root / "training" / "disp_occ_0" / name, frame.disparity)


def test_sgbm_and_the_report_folder(tmp_path: Path) -> None:
    _write_kitti(tmp_path / "kitti")
    reader = open_reader("kitti", tmp_path / "kitti")
    out = tmp_path / "report"
    writer = PredictionWriter(out, kitti_png=True)
    methods = build_methods(["sgbm"], checkpoint=None, predictions=None, mono_dir=None)
    report = evaluate(iter_reader(reader), methods, EvalOptions(), total=len(reader), on_prediction=writer)
    write_report(out, report)
    sgbm = report["methods"]["sgbm"]["regions"]["all"]
    assert sgbm["samples"] == 2 and 0 < sgbm["epe"] < 10  # a real matcher on rendered pairs: close, not exact
    pred = read_pfm(out / "predictions" / "sgbm" / "training" / "image_2" / "000000_10.pfm")
    assert pred.shape == (64, 128) and np.isfinite(pred).all()  # dense: holes filled
    assert (out / "predictions" / "sgbm" / "training" / "image_2" / "000000_10.png").is_file()
    assert json.loads((out / "report.json").read_text())["methods"]["sgbm"]["regions"]["all"]["samples"] == 2
    assert "method,sample,region,epe" in (out / "per_sample.csv").read_text()
    page = (out / "index.html").read_text()
    assert "<th>sgbm</th>" in page and (out / "report.js").is_file()
