"""Each dataset reader on a tiny fixture written here in its exact layout; resizing; errors."""

from __future__ import annotations

import pickle
from pathlib import Path

import cv2
import numpy as np
import pytest

from core.formats import write_kitti_disparity, write_mask, write_pfm, write_png, write_rgb
from dataset.export.errors import LayoutError
from dataset.readers import READER_FORMATS, Camera, SampleError, StereoSample, open_reader, resize_sample
from dataset.readers.base import make_regions, resize_disparity
from tests.fixtures.workspaces import SEED, SPLIT, export
from webapp.runtime import Runtime

H, W = 12, 16
RNG = np.random.default_rng(0)


def rgb(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (H, W, 3), dtype=np.uint8)


def put_rgb(path: Path, image: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    write_rgb(path, image)


def put_pfm(path: Path, array: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    write_pfm(path, array)


def check_sample(sample: StereoSample) -> None:
    assert sample.left.shape == sample.right.shape == (*sample.disparity.shape, 3) and sample.left.dtype == np.uint8
    assert sample.disparity.dtype == np.float32
    assert np.array_equal(sample.regions["all"], np.isfinite(sample.disparity))
    assert all(not (m & ~sample.regions["all"]).any() for m in sample.regions.values())


def test_formats_are_the_contracts() -> None:
    assert READER_FORMATS == ("native", "authors", "booster", "middlebury", "kitti", "sceneflow", "synthetic")


# --- authors ----------------------------------------------------------------------------------

def write_authors(root: Path, *, index: bool) -> dict[str, np.ndarray]:
    testing = root / "testing"
    disp = np.full((H, W), 91.11, np.float32)  # fx·b = 91.11 px·m: depth 1 m
    disp[0, :4] = np.inf  # their unmeasured depth
    disp[1, :4] = 10.0  # 9.1 m: beyond the valid 5 m
    disp[2, :4] = 400.0  # 0.23 m: nearer than 0.3 m
    mask = np.zeros((H, W), np.uint8)
    mask[6:, 8:] = 255
    mask[6, 8] = 100  # a JPEG-blurred edge below the 128 threshold
    folder = "lab_00"
    put_rgb(testing / "left" / folder / "frame_000003.png", rgb(1))
    put_rgb(testing / "right" / folder / "frame_000003.png", rgb(2))
    put_pfm(testing / "disp" / folder / "frame_000003.pfm", disp)
    (testing / "mask" / folder).mkdir(parents=True)
    cv2.imwrite(str(testing / "mask" / folder / "frame_000003.jpg"), mask, [cv2.IMWRITE_JPEG_QUALITY, 100])
    if index:
        (root / "meta_data").mkdir()
        entry = {p: f"{p}/{folder}/frame_000003.{ext}" for p, ext in
                 (("left", "png"), ("right", "png"), ("disp", "pfm"), ("mask", "jpg"))}
        (root / "meta_data" / "testing_enter.pkl").write_bytes(pickle.dumps({("lab", "00", "000003"): entry}))
    return {"disp": disp, "mask": mask}


@pytest.mark.parametrize("index", [True, False])
def test_authors_reader(tmp_path: Path, index: bool) -> None:
    truth = write_authors(tmp_path, index=index)
    reader = open_reader("authors", tmp_path)
    assert reader.names == ["lab_00/frame_000003"] and len(reader) == 1
    sample = reader[0]
    check_sample(sample)
    assert np.array_equal(sample.left, rgb(1)) and np.array_equal(sample.right, rgb(2))
    valid = np.ones((H, W), bool)
    valid[:3, :4] = False  # inf, too far, too near
    assert np.array_equal(sample.regions["all"], valid)
    assert np.allclose(sample.disparity[valid], 91.11)
    illusion = np.zeros((H, W), bool)
    illusion[6:, 8:] = True
    illusion[6, 8] = False
    assert np.array_equal(sample.regions["illusion"], illusion)
    assert np.array_equal(sample.regions["non_illusion"], valid & ~illusion)
    assert sample.camera == Camera(1450.4127, 0.0628167, depth_range=(0.3, 5.0))
    assert sample.meta["left"] == "testing/left/lab_00/frame_000003.png"
    # configurable: no depth range keeps every positive finite disparity; another camera
    wide = open_reader("authors", tmp_path / "testing" if not index else tmp_path, depth_range=None, fx=1000.0)[0]
    assert int(wide.regions["all"].sum()) == H * W - 4 and wide.camera == Camera(1000.0, 0.0628167)
    assert truth["mask"].max() == 255


def test_authors_index_pickle_is_read_as_plain_data(tmp_path: Path) -> None:
    write_authors(tmp_path, index=True)

    class Evil:
        def __reduce__(self):  # type: ignore[no-untyped-def]
            return (print, ("owned",))

    (tmp_path / "meta_data" / "testing_enter.pkl").write_bytes(pickle.dumps({("a", "00", "1"): Evil()}))
    with pytest.raises(LayoutError, match="refusing to load builtins.print"):
        open_reader("authors", tmp_path)


# --- booster ----------------------------------------------------------------------------------

def test_booster_reader(tmp_path: Path) -> None:
    scene = tmp_path / "train" / "balanced" / "Bathroom"
    for k in (0, 1):
        put_rgb(scene / "camera_00" / f"im{k}.png", rgb(10 + k))
        put_rgb(scene / "camera_02" / f"im{k}.png", rgb(20 + k))
    disp = np.linspace(0.5, 80, H * W, dtype=np.float32).reshape(H, W)
    disp[:2] = 0  # invalid
    np.save(scene / "disp_00.npy", disp)
    classes = np.zeros((H, W), np.uint8)
    classes[:, 4:8], classes[:, 8:12], classes[:, 12:] = 1, 2, 3
    write_png(scene / "mask_cat.png", classes)
    booster_valid = np.ones((H, W), bool)
    booster_valid[-1] = False
    write_mask(scene / "mask_00.png", booster_valid)

    reader = open_reader("booster", tmp_path)
    assert reader.names == ["Bathroom/im0", "Bathroom/im1"] and reader.default_factor == 0.25
    sample = reader[1]
    check_sample(sample)
    assert np.array_equal(sample.left, rgb(11)) and np.array_equal(sample.right, rgb(21))
    assert np.array_equal(sample.regions["all"], disp > 0)
    trans = (classes == 3) & (disp > 0)
    assert np.array_equal(sample.regions["trans"], trans)
    assert np.array_equal(sample.regions["nontrans"], (disp > 0) & ~trans)
    assert {f"class_{c}" for c in range(4)} <= sample.regions.keys()
    assert np.array_equal(sample.regions["class_2"], (classes == 2) & (disp > 0))
    strict = open_reader("booster", tmp_path / "train" / "balanced", min_disparity=1, valid_mask=True)[0]
    assert np.array_equal(strict.regions["all"], (disp > 1) & booster_valid)


# --- middlebury -------------------------------------------------------------------------------

CALIB = "cam0=[1000.5 0 8; 0 1000.5 6; 0 0 1]\ncam1=[1000.5 0 9; 0 1000.5 6; 0 0 1]\ndoffs=1.25\nbaseline=176.252\n" \
        "width=16\nheight=12\nndisp=64\n"


def test_middlebury_eval3_and_2014(tmp_path: Path) -> None:
    disp = RNG.uniform(5, 60, (H, W)).astype(np.float32)
    disp[0, 0] = np.inf
    nocc = np.full((H, W), 255, np.uint8)
    nocc[3, :], nocc[4, :] = 128, 0  # occluded, invalid
    for res in ("Q", "H"):
        scene = tmp_path / "MiddEval3" / f"training{res}" / "Adirondack"
        put_rgb(scene / "im0.png", rgb(1))
        put_rgb(scene / "im1.png", rgb(2))
        put_pfm(scene / "disp0GT.pfm", disp)
        write_png(scene / "mask0nocc.png", nocc)
        (scene / "calib.txt").write_text(CALIB)
    reader = open_reader("middlebury", tmp_path / "MiddEval3")
    assert reader.names == ["Adirondack"] and reader[0].meta["left"] == "trainingH/Adirondack/im0.png"
    sample = open_reader("middlebury", tmp_path / "MiddEval3", resolution="Q")[0]
    check_sample(sample)
    assert not sample.regions["all"][0, 0] and int(sample.regions["all"].sum()) == H * W - 1
    assert not sample.regions["nonocc"][3:5].any() and sample.regions["nonocc"][5:].all()
    assert (sample.camera.fx, sample.camera.baseline, sample.camera.doffs) == (1000.5, pytest.approx(0.176252), 1.25)
    with pytest.raises(LayoutError, match="trainingF"):
        open_reader("middlebury", tmp_path / "MiddEval3", resolution="F")

    perfect = tmp_path / "2014" / "Piano-perfect"
    put_rgb(perfect / "im0.png", rgb(3))
    put_rgb(perfect / "im1.png", rgb(4))
    put_pfm(perfect / "disp0.pfm", disp)
    (perfect / "calib.txt").write_text(CALIB)
    sample = open_reader("middlebury", tmp_path / "2014")[0]
    assert sample.name == "Piano-perfect" and set(sample.regions) == {"all"}
    assert np.array_equal(sample.disparity[1:], disp[1:])


# --- kitti ------------------------------------------------------------------------------------

def test_kitti_reader(tmp_path: Path) -> None:
    training = tmp_path / "training"
    disp = np.round(RNG.uniform(1, 100, (H, W)) * 256) / 256
    disp[5, 5] = np.nan
    noc = disp.copy()
    noc[:, :3] = np.nan
    for folder, image in (("image_2", rgb(1)), ("image_3", rgb(2))):
        put_rgb(training / folder / "000007_10.png", image)
    for folder, values in (("disp_occ_0", disp), ("disp_noc_0", noc)):
        (training / folder).mkdir(parents=True)
        write_kitti_disparity(training / folder / "000007_10.png", values.astype(np.float32))
    sample = open_reader("kitti", tmp_path)[0]
    check_sample(sample)
    assert sample.name == "000007_10" and np.allclose(sample.disparity, disp, equal_nan=True)
    assert np.array_equal(sample.regions["nonocc"], np.isfinite(noc))
    assert open_reader("kitti", training).names == ["000007_10"]


# --- sceneflow --------------------------------------------------------------------------------

def write_sceneflow(root: Path) -> None:
    for sub, seq in (("FlyingThings3D", "TRAIN/A/0000"), ("FlyingThings3D", "TEST/A/0001"), ("Monkaa", "eating_x2"),
                     ("Driving", "35mm_focallength/scene_forwards/fast")):
        for pass_ in ("frames_cleanpass", "frames_finalpass"):
            put_rgb(root / sub / pass_ / seq / "left" / "0006.png", rgb(1))
            put_rgb(root / sub / pass_ / seq / "right" / "0006.png", rgb(2))
        put_pfm(root / sub / "disparity" / seq / "left" / "0006.pfm", np.full((H, W), 12.5, np.float32))


def test_sceneflow_reader(tmp_path: Path) -> None:
    write_sceneflow(tmp_path)
    reader = open_reader("sceneflow", tmp_path)
    assert reader.names == ["Driving/frames_cleanpass/35mm_focallength/scene_forwards/fast/left/0006",
                            "FlyingThings3D/frames_cleanpass/TEST/A/0001/left/0006",
                            "FlyingThings3D/frames_cleanpass/TRAIN/A/0000/left/0006",
                            "Monkaa/frames_cleanpass/eating_x2/left/0006"]
    for sample in (reader[i] for i in range(len(reader))):
        check_sample(sample)
        assert (sample.disparity == 12.5).all() and np.array_equal(sample.right, rgb(2))
    train = open_reader("sceneflow", tmp_path / "FlyingThings3D", split="TRAIN", passes=("clean", "final"))
    assert train.names == ["frames_cleanpass/TRAIN/A/0000/left/0006", "frames_finalpass/TRAIN/A/0000/left/0006"]
    assert train[1].meta["pass"] == "frames_finalpass"


# --- native (a real export of the pipeline's samples) -----------------------------------------

def test_native_reader(source: Runtime, tmp_path: Path) -> None:
    out = tmp_path / "ds"
    export(source, out, split=SPLIT, seed=SEED)
    reader = open_reader("native", out)
    test_split = open_reader("native", out, split="test")
    assert len(reader) == 6 and 0 < len(test_split) < 6 and set(test_split.names) < set(reader.names)
    kinds = set()
    for i in range(len(reader)):
        sample = reader[i]
        check_sample(sample)
        entry = reader.entries[i]
        assert sample.name == entry["id"] and sample.meta["left"] == entry["files"]["left"]["path"]
        assert np.array_equal(sample.regions["illusion"] | sample.regions["non_illusion"], sample.regions["all"])
        kinds.add(sample.meta["kind"])
        if sample.meta["kind"] == "synthesized":
            assert sample.mono is not None and sample.mono.shape == sample.disparity.shape
            kinds_here = sample.meta["illusion_types"]  # a picture and a mirror, each its own region
            assert np.array_equal(np.logical_or.reduce([sample.regions[k] for k in kinds_here]), sample.regions["illusion"])
            assert all(sample.regions[k].any() for k in kinds_here)
        else:  # the capture: NaN outside its valid mask
            assert not sample.regions["all"][:6, :10].any() and sample.mono is None
            assert sample.camera is None  # its video records a baseline but no intrinsics
    assert kinds == {"synthesized", "capture"}
    with pytest.raises(LayoutError, match="no split 'val'"):
        open_reader("native", out, split="val")


# --- errors and resizing ------------------------------------------------------------------------

@pytest.mark.parametrize("fmt", READER_FORMATS)
def test_a_folder_of_another_layout_says_what_was_expected(tmp_path: Path, fmt: str) -> None:
    (tmp_path / "stuff").mkdir()
    with pytest.raises(LayoutError, match="expected|no manifest.json"):
        open_reader(fmt, tmp_path)
    with pytest.raises(LayoutError, match="no such folder"):
        open_reader(fmt, tmp_path / "missing")


def test_broken_file_names_sample_and_file(tmp_path: Path) -> None:
    write_sceneflow(tmp_path)
    broken = tmp_path / "Monkaa" / "disparity" / "eating_x2" / "left" / "0006.pfm"
    broken.write_bytes(b"Pf\n16 12\n-1.0\n" + b"\0" * 10)
    reader = open_reader("sceneflow", tmp_path / "Monkaa")
    with pytest.raises(SampleError, match=r"sample 'frames_cleanpass/eating_x2/left/0006'.*0006\.pfm: truncated"):
        reader[0]
    write_pfm(broken, np.ones((H, W), np.float32))
    (tmp_path / "Monkaa" / "frames_cleanpass" / "eating_x2" / "right" / "0006.png").unlink()
    with pytest.raises(SampleError, match="right/0006.png: .*file not found"):
        reader[0]


def test_unknown_format_and_option(tmp_path: Path) -> None:
    with pytest.raises(LayoutError, match="unknown dataset format 'eth3d'"):
        open_reader("eth3d", tmp_path)
    with pytest.raises(LayoutError, match="'kitti' has no option 'min_disparity'; it takes fx, baseline, depth_range"):
        open_reader("kitti", tmp_path, min_disparity=1)


def test_resize_sample_scales_disparity_and_keeps_invalid_invalid() -> None:
    disparity = np.tile(np.linspace(8, 40, 32, dtype=np.float32), (24, 1))
    disparity[:4, :4] = np.nan
    region = np.zeros((24, 32), bool)
    region[12:, 16:] = True
    mono = np.tile(np.linspace(0, 1, 32, dtype=np.float32), (24, 1))
    sample = StereoSample("x", np.zeros((24, 32, 3), np.uint8), np.zeros((24, 32, 3), np.uint8), disparity,
                          make_regions(disparity, {"r": region}), mono=mono, camera=Camera(100.0, 0.1, doffs=2.0))
    small = resize_sample(sample, 0.25)
    assert small.disparity.shape == (6, 8) and small.left.shape == (6, 8, 3)
    assert np.isnan(small.disparity[0, 0]) and np.isfinite(small.disparity[2:]).all()
    # a linear ramp stays a ramp, its values a quarter
    assert np.nanmax(small.disparity) <= 10 and np.nanmin(small.disparity[2:]) >= 2
    assert np.array_equal(small.regions["r"], np.pad(np.ones((3, 4), bool), ((3, 0), (4, 0))))
    assert np.array_equal(small.regions["all"], np.isfinite(small.disparity))
    assert small.camera == Camera(25.0, 0.1, doffs=0.5) and small.mono.max() <= 1.0 and small.mono.min() >= 0.0
    assert resize_sample(sample, 1.0) is sample
    big = resize_disparity(disparity, (48, 64))
    assert np.isnan(big[:8, :8]).all() and np.nanmax(big) == pytest.approx(80, rel=0.02)

