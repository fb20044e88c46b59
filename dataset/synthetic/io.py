"""Write and read synthetic videos in their on-disk layout.

``<out_dir>/<video.name>/``: ``video.mp4`` (left frames, mp4v), ``scene.json`` and
``frames/{index:06d}/`` holding ``left.png``, ``right.png``, ``disparity.npy``,
``mono_disparity.npy``, ``mono_ideal.npy``, ``stereo_disparity.npy`` and ``illusion_{pair:02d}.png`` /
``support_{pair:02d}.png``. Every file is written atomically (temp file + ``os.replace``);
``scene.json`` is written last, so a reader that finds it also finds every frame it lists.
Same video in → byte-identical files out.
"""

from __future__ import annotations

import io
import json
import os
import tempfile
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from core.atomic import atomic_write_bytes
from dataset.synthetic.defects import DEFECT_FRAMES, spoil_last_frames
from dataset.synthetic.layout import BASELINE_M
from dataset.synthetic.mono import FrameAffine, MonoModel
from dataset.synthetic.records import RegionPair, SyntheticFrame, SyntheticVideo
from dataset.synthetic.render import render_video

FORMAT = "illusion-studio/synthetic-v2"  # v2: the realistic mono_disparity, mono_ideal beside it
_MAPS = ("disparity", "mono_disparity", "mono_ideal", "stereo_disparity")
_FILES = {
    "video.mp4": "left frames at fps, MPEG-4 Part 2 ('mp4v'), lossy; for ingest",
    "frames/{index:06d}/left.png": "left image, 8-bit RGB, lossless",
    "frames/{index:06d}/right.png": "right image rendered exactly (not warped), 8-bit RGB; "
                                    "right camera = left camera + baseline along its +x",
    "frames/{index:06d}/disparity.npy": "true disparity f*B/Z, float32 (H, W), px, left view; "
                                        "a mirror counts as its flat glass",
    "frames/{index:06d}/mono_disparity.npy": "a realistic monocular network's disparity, float32 "
                                             "(H, W) > 0, relative (frame's mono_scale, mono_shift): "
                                             "the depicted scene inside pictures, a fraction "
                                             "mono.mirror_fraction of the way from the glass to the "
                                             "reflected scene inside mirrors, elsewhere the truth "
                                             "distorted in log-depth and blurred (scene.json's mono)",
    "frames/{index:06d}/mono_ideal.npy": "exact mono-fooled disparity, float32 (H, W), px: the "
                                         "depicted scene inside pictures, the reflected (virtual) "
                                         "scene inside mirrors, the truth elsewhere",
    "frames/{index:06d}/stereo_disparity.npy": "stereo-fooled disparity, float32 (H, W): the "
                                               "reflected (virtual) scene inside mirrors, the "
                                               "truth elsewhere",
    "frames/{index:06d}/illusion_{pair:02d}.png": "illusion mask of pair `pair`, 8-bit 0/255",
    "frames/{index:06d}/support_{pair:02d}.png": "support mask (wall band around the illusion) "
                                                 "of pair `pair`, 8-bit 0/255",
}


def _png(image: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", image)
    if not ok:
        raise OSError("PNG encoding failed")
    return buf.tobytes()


def _npy(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, array, allow_pickle=False)
    return buf.getvalue()


def _write_mp4(path: Path, frames: list[np.ndarray], fps: float) -> None:
    """Encode RGB uint8 frames to ``path`` (mp4v) through a temp file in the same folder."""
    height, width = frames[0].shape[:2]
    # OpenCV picks the container from the extension, so the temp name must end in .mp4.
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=".tmp.mp4")
    os.close(fd)
    try:
        writer = cv2.VideoWriter(tmp, cv2.VideoWriter_fourcc(*"mp4v"), fps, (width, height))
        if not writer.isOpened():
            raise OSError(f"cv2.VideoWriter cannot write mp4v to {tmp}")
        for frame in frames:
            writer.write(cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
        writer.release()
        os.chmod(tmp, 0o644)  # like every other dataset file (mkstemp makes 0600)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_video(video: SyntheticVideo, out_dir: Path, defects: dict[int, str] | None = None) -> Path:
    """Write ``video`` under ``out_dir / video.name`` and return that folder; ``defects`` (frame
    index → defect name, see dataset.synthetic.defects) is recorded in scene.json."""
    root = Path(out_dir) / video.name
    (root / "frames").mkdir(parents=True, exist_ok=True)
    _write_mp4(root / "video.mp4", [f.left for f in video.frames], video.fps)
    for frame in video.frames:
        folder = root / "frames" / f"{frame.index:06d}"
        folder.mkdir(exist_ok=True)
        atomic_write_bytes(folder / "left.png", _png(cv2.cvtColor(frame.left, cv2.COLOR_RGB2BGR)))
        atomic_write_bytes(folder / "right.png", _png(cv2.cvtColor(frame.right, cv2.COLOR_RGB2BGR)))
        for name in _MAPS:
            atomic_write_bytes(folder / f"{name}.npy", _npy(getattr(frame, name).astype(np.float32)))
        for region in frame.regions:
            for name in ("illusion", "support"):
                mask = getattr(region, name).astype(np.uint8) * 255
                atomic_write_bytes(folder / f"{name}_{region.pair:02d}.png", _png(mask))
    scene = {
        "format": FORMAT,
        "name": video.name,
        "seed": video.seed,
        "fps": video.fps,
        "width": video.width,
        "height": video.height,
        "n_frames": len(video.frames),
        "intrinsics": {"fx": video.fx, "fy": video.fy, "cx": video.cx, "cy": video.cy},
        "baseline_m": video.baseline_m,
        "conventions": "pixel centres at integer (u, v); disparity d = fx*B/Z > 0 in the left "
                       "view, a left pixel (u, v) matching right pixel (u - d, v)",
        "pairs": [{"pair": r.pair, "kind": r.kind, "illusion_type": r.illusion_type}
                  for r in video.frames[0].regions],
        "mono": video.mono.as_dict(),
        "families": video.families,
        "frames": [{"index": f.index, "time_s": f.time_s, "mono_scale": f.mono_affine.scale,
                    "mono_shift": f.mono_affine.shift,
                    **({"defect": defects[f.index]} if f.index in (defects or {}) else {})} for f in video.frames],
        "files": _FILES,
    }
    atomic_write_bytes(root / "scene.json", (json.dumps(scene, indent=2) + "\n").encode())
    return root


def _read_png(path: Path, flags: int) -> np.ndarray:
    image = cv2.imread(str(path), flags)
    if image is None:
        raise FileNotFoundError(f"cannot read image {path}")
    return image


def read_scene(video_dir: Path) -> dict[str, Any]:
    """A folder's ``scene.json`` (intrinsics, baseline, pairs, frames…); ValueError if it is not a FORMAT scene."""
    path = Path(video_dir) / "scene.json"
    scene = json.loads(path.read_text())
    if not isinstance(scene, dict) or scene.get("format") != FORMAT:
        raise ValueError(f"{path}: not a {FORMAT} scene")
    return scene


def read_frame(video_dir: Path, scene: dict[str, Any], entry: dict[str, Any]) -> SyntheticFrame:
    """The frame ``entry`` (one of ``scene["frames"]``) of the folder :func:`write_video` wrote."""
    folder = Path(video_dir) / "frames" / f"{entry['index']:06d}"
    images = {name: cv2.cvtColor(_read_png(folder / f"{name}.png", cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
              for name in ("left", "right")}
    maps = {name: np.load(folder / f"{name}.npy", allow_pickle=False) for name in _MAPS}
    regions = []
    for pair in scene["pairs"]:
        masks = {name: _read_png(folder / f"{name}_{pair['pair']:02d}.png", cv2.IMREAD_GRAYSCALE) > 127
                 for name in ("illusion", "support")}
        regions.append(RegionPair(pair["pair"], pair["kind"], pair["illusion_type"], **masks))
    return SyntheticFrame(index=entry["index"], time_s=entry["time_s"], **images, **maps, regions=regions,
                          mono_affine=FrameAffine(entry["mono_scale"], entry["mono_shift"]))


def read_video(video_dir: Path) -> SyntheticVideo:
    """Read a folder written by :func:`write_video` (everything but the lossy video.mp4)."""
    scene = read_scene(video_dir)
    frames = [read_frame(video_dir, scene, entry) for entry in scene["frames"]]
    k = scene["intrinsics"]
    return SyntheticVideo(name=scene["name"], seed=scene["seed"], fps=scene["fps"], fx=k["fx"],
                          fy=k["fy"], cx=k["cx"], cy=k["cy"], baseline_m=scene["baseline_m"],
                          frames=frames, mono=MonoModel.from_dict(scene["mono"]),
                          families=bool(scene.get("families", False)))


def write_synthetic_dataset(out_dir: Path, videos: int = 3, seed: int = 0, n_frames: int = 12,
                            width: int = 640, height: int = 360, *, defects: bool = False,
                            families: bool = False, baseline_m: float = BASELINE_M) -> list[Path]:
    """Render and write ``videos`` videos (video k from seed ``seed + k``, with the scene ``families``
    or not); their folders. ``defects``: add DEFECT_FRAMES spoilt frames (a caption, a blur) to each
    video's ``n_frames`` clean ones, for the prefilter to catch."""
    paths = []
    for k in range(videos):
        video, spoilt = render_video(seed + k, n_frames + (DEFECT_FRAMES if defects else 0), width, height,
                                     baseline_m, families=families), {}
        if defects:
            video, spoilt = spoil_last_frames(video)
        paths.append(write_video(video, out_dir, spoilt))
    return paths
