"""Middlebury 2014's Motorcycle as scikit-image ships it — the default-exposure pair down-sampled 4×
(741×500) with its ground truth (infinite where unknown) and calibration — written as a Middlebury
"perfect" scene: a real pair with exact truth that needs no download (`illusion-studio example-data`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from core.formats import write_pfm, write_rgb

SCENE = "Motorcycle-perfect"
# scikit-image's docstring of stereo_motorcycle: valid for the down-sampled images (px; baseline mm).
FOCAL_PX, CX0_PX, CY_PX, DOFFS_PX, BASELINE_MM = 994.978, 311.193, 254.877, 31.086, 193.001


def write_motorcycle(root: Path) -> Path:
    """Write ``root/Motorcycle-perfect/{im0.png, im1.png, disp0.pfm, calib.txt}``; returns the scene folder.
    Disparity in pixels, float32 HxW; unknown pixels infinite, as Middlebury's files have them."""
    import skimage.data

    left, right, disparity = skimage.data.stereo_motorcycle()
    scene = Path(root) / SCENE
    scene.mkdir(parents=True, exist_ok=True)
    write_rgb(scene / "im0.png", left)
    write_rgb(scene / "im1.png", right)
    write_pfm(scene / "disp0.pfm", np.where(np.isfinite(disparity), disparity, np.inf).astype(np.float32))
    height, width = disparity.shape
    cam = lambda cx: f"[{FOCAL_PX} 0 {cx}; 0 {FOCAL_PX} {CY_PX}; 0 0 1]"
    (scene / "calib.txt").write_text(
        f"cam0={cam(CX0_PX)}\ncam1={cam(round(CX0_PX + DOFFS_PX, 3))}\ndoffs={DOFFS_PX}\nbaseline={BASELINE_MM}\n"
        f"width={width}\nheight={height}\n")
    return scene
