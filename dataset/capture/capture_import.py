"""The capture import job: a capture folder (layout in :mod:`dataset.capture.layout`) becomes a
``real_capture`` Video whose frames come with their ground truth: each Frame (state
``generated``) gets a Sample with the captured pair, the reprojected disparity and its valid mask.

Idempotent and resumable like ingest: the video is keyed by a hash over the calibration file and
every frame file, frames by (video, index), and a Frame row commits together with its Sample, so
a re-import of a finished capture is a no-op and a retry continues where it stopped. A folder
that turns out to be broken (unreadable image, wrong size, a depth frame without any return)
removes the partial video again: a failed import leaves nothing in the database.
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from sqlalchemy import delete, select

from core.formats import FormatError, read_image, read_rgb
from core.geometry import CalibrationError, GeometryError, RigCalibration, load_calibration
from core.wording import plural
from dataset.capture.errors import CaptureError
from dataset.capture.layout import CaptureFrame, scan_capture
from dataset.capture.truth import DEFAULT_DEPTH_RANGE_M, DEFAULT_EPSILON_M, capture_truth
from dataset.db import transaction
from dataset.ingest import dhash
from dataset.media import sha256_file
from dataset.samples import mask_name, store_outputs
from dataset.services.jobs import JobContext
from dataset.tables import Frame, FrameState, Sample, SourceKind, Video, utcnow
from dataset.thumbnails import put_thumbnail
from dataset.version import code_version

CAPTURE_JOB = "import_capture"


def capture_params(path: str | Path, calibration: str | Path, *, scene: str | None = None,
                   depth_range: tuple[float, float] = DEFAULT_DEPTH_RANGE_M, epsilon: float = DEFAULT_EPSILON_M,
                   fps: float | None = None, user_id: int | None = None) -> dict[str, Any]:
    """Validated parameters of an ``import_capture`` job: the folder's files match up and the
    calibration file is valid (else :class:`CaptureError`, one line). ``depth_range``: valid
    ground-truth depth (near, far) in metres; ``epsilon``: Algorithm 3's backward-check threshold
    in metres; ``fps``: the capture's frame rate, if known (frame times are index / fps, else 0)."""
    root = Path(path).resolve()
    scan_capture(root)
    calibration = Path(calibration).resolve()
    _load_calibration(calibration)
    near, far = (float(x) for x in depth_range)
    if not (math.isfinite(far) and 0 < near < far):
        raise CaptureError(f"depth range must be 0 < near < far metres, got {near:g}, {far:g}")
    if not (math.isfinite(epsilon) and epsilon > 0):
        raise CaptureError(f"epsilon must be a number of metres > 0, got {epsilon:g}")
    if fps is not None and not (math.isfinite(fps) and fps > 0):
        raise CaptureError(f"fps must be > 0, got {fps:g}")
    return {"path": str(root), "calibration": str(calibration), "scene": scene or root.name,
            "depth_range_m": [near, far], "epsilon_m": float(epsilon), "fps": fps, "user_id": user_id}


def import_capture_job(ctx: JobContext) -> dict[str, Any]:
    """Job handler for kind ``import_capture`` (params from :func:`capture_params`)."""
    p = ctx.params
    frames = scan_capture(p["path"])
    calibration = _load_calibration(Path(p["calibration"]))
    calibration_bytes = Path(p["calibration"]).read_bytes()
    options = {"depth_range_m": p["depth_range_m"], "epsilon_m": p["epsilon_m"]}
    fingerprint = _fingerprint(frames, calibration_bytes)
    with transaction(ctx.sessions) as s:
        video = s.scalar(select(Video).where(Video.content_sha256 == fingerprint))
        if video is not None and video.meta.get("options") != options:
            raise CaptureError(f"this capture is already imported as video {video.id} with {video.meta.get('options')}; "
                               "delete that video to import it with other options")
        if video is not None and video.meta.get("capture") == "complete":
            ctx.log(f"already imported as video {video.id}; nothing to do")
            return {"video_id": video.id, "frames": len(frames), "new_frames": 0, "skipped": True}
        if video is None:
            video = _new_video(p, fingerprint, calibration, options, len(frames))
            s.add(video)
            s.flush()
        video_id = video.id
        done = set(s.scalars(select(Frame.index).where(Frame.video_id == video_id)))
    ctx.log(f"video {video_id}: {plural(len(frames), 'frame')} of {p['path']}; {len(done)} from an earlier attempt")
    reference = {"calibration_sha256": hashlib.sha256(calibration_bytes).hexdigest(),
                 "calibration_key": ctx.media.put_bytes(calibration_bytes, "json")}
    new = 0
    try:
        for index, frame in enumerate(frames):
            if index not in done:
                _import_frame(ctx, video_id, index, frame, calibration, reference)
                new += 1
            ctx.progress((index + 1) / len(frames), f"frame {frame.stem}")
    except CaptureError:
        # Bad input: nothing of it stays. Any other failure (a locked database, a full disk) keeps
        # what was imported, for the retry to finish.
        with transaction(ctx.sessions) as s:
            s.execute(delete(Video).where(Video.id == video_id))  # frames and samples go with it (ON DELETE CASCADE)
        raise
    with transaction(ctx.sessions) as s:
        video = s.get(Video, video_id)
        video.meta = {**video.meta, "capture": "complete"}
    ctx.log(f"imported {plural(len(frames), 'frame')} ({new} new)")
    return {"video_id": video_id, "frames": len(frames), "new_frames": new}


def calibration_summary(calibration: RigCalibration) -> dict[str, Any]:
    """The figures a sample's disparity depends on: left-camera intrinsics (px), stereo baseline
    (m), the sensor's depth scale (m per unit) and its offset from the left camera (m)."""
    K = calibration.K_color
    return {"fx": float(K[0, 0]), "fy": float(K[1, 1]), "cx": float(K[0, 2]), "cy": float(K[1, 2]),
            "baseline_m": calibration.baseline, "depth_scale": calibration.depth_scale,
            "depth_to_left_T_m": calibration.T.tolist()}


def _load_calibration(path: Path) -> RigCalibration:
    try:
        return load_calibration(path)
    except CalibrationError as exc:
        raise CaptureError(str(exc)) from None


def _fingerprint(frames: list[CaptureFrame], calibration_bytes: bytes) -> str:
    """SHA-256 over the calibration and every frame's stem and file contents."""
    digest = hashlib.sha256(hashlib.sha256(calibration_bytes).digest())
    for frame in frames:
        digest.update(frame.stem.encode() + b"\0")
        for path in frame.files:
            digest.update(bytes.fromhex(sha256_file(path)))
    return digest.hexdigest()


def _new_video(p: dict[str, Any], fingerprint: str, calibration: RigCalibration, options: dict[str, Any],
               n_frames: int) -> Video:
    summary = calibration_summary(calibration)
    height, width = calibration.color_shape
    return Video(name=p["scene"], source_kind=SourceKind.real_capture, illusion_types=[], content_sha256=fingerprint,
                 original_path=p["path"], fps=p["fps"], width=width, height=height, created_by_id=p.get("user_id"),
                 # the keys synthetic scenes use, so that previews find the camera the same way
                 meta={"capture": "running", "options": options, "frames": n_frames, "calibration": summary,
                       "intrinsics": {k: summary[k] for k in ("fx", "fy", "cx", "cy")},
                       "baseline_m": calibration.baseline})


def _import_frame(ctx: JobContext, video_id: int, index: int, frame: CaptureFrame, calibration: RigCalibration,
                  reference: dict[str, str]) -> None:
    p = ctx.params
    shape = calibration.color_shape
    left, right = (_read_colour(path, shape) for path in (frame.left, frame.right))
    depth_raw = _read_depth(frame.depth, calibration.depth_shape)
    masks = {mask_name("illusion", i): _read_mask(path, shape) for i, path in enumerate(frame.masks)}
    try:
        truth = capture_truth(left, depth_raw, calibration, depth_range=tuple(p["depth_range_m"]), epsilon=p["epsilon_m"])
    except GeometryError as exc:
        raise CaptureError(f"{frame.depth}: {exc}") from None
    outputs: dict[str, Any] = {"left": left, "right": right, "disparity": truth.disparity, "valid": truth.valid}
    if masks:
        outputs["masks"] = masks
    # Media first, rows last: a crash in between leaves orphan files, never a row without its file.
    files = store_outputs(ctx.media, outputs)
    assets = {"thumb": put_thumbnail(ctx.media, left), "dhash": f"{dhash(left):016x}",
              "lidar_depth": ctx.media.put_file(frame.depth)}
    params = {"scale": 1.0, "calibration": calibration_summary(calibration), "depth_range_m": p["depth_range_m"],
              "epsilon_m": p["epsilon_m"]}
    provenance = {"source": "capture", "capture_path": p["path"], "capture_stem": frame.stem, **reference,
                  "code_version": code_version(), "imported_at": utcnow().isoformat() + "Z"}
    with transaction(ctx.sessions) as s:
        row = Frame(video_id=video_id, index=index, time_s=index / p["fps"] if p["fps"] else 0.0, width=shape[1],
                    height=shape[0], content_sha256=Path(files["left"]).stem,  # media keys are content hashes
                    media_key=files["left"], state=FrameState.generated, assets=assets)
        s.add(row)
        s.flush()
        s.add(Sample(frame_id=row.id, files=files, params=params, provenance=provenance, qa=truth.qa,
                     flagged=bool(truth.qa["flags"])))


def _read_colour(path: Path, shape: tuple[int, int]) -> np.ndarray:
    """RGB uint8 HxWx3 of the calibration's colour-camera ``shape``."""
    try:
        image = read_rgb(path)
    except FormatError as exc:
        raise CaptureError(str(exc)) from None
    _check_shape(path, image.shape[:2], shape, "the calibration's colour camera")
    return image


def _read_depth(path: Path, shape: tuple[int, int]) -> np.ndarray:
    """The raw uint16 HxW depth frame of the calibration's depth-camera ``shape``."""
    try:
        raw = read_image(path, cv2.IMREAD_UNCHANGED)
    except FormatError as exc:
        raise CaptureError(str(exc)) from None
    if raw.dtype != np.uint16 or raw.ndim != 2:
        raise CaptureError(f"{path}: depth must be a single-channel 16-bit PNG, got {raw.dtype} with shape {raw.shape}")
    _check_shape(path, raw.shape, shape, "the calibration's depth camera")
    return raw


def _read_mask(path: Path, shape: tuple[int, int]) -> np.ndarray:
    """bool HxW from a 0/255 PNG; other values (a JPEG-damaged mask) are refused, not guessed at."""
    try:
        gray = read_image(path, cv2.IMREAD_GRAYSCALE)
    except FormatError as exc:
        raise CaptureError(str(exc)) from None
    _check_shape(path, gray.shape, shape, "the left image")
    stray = int(((gray != 0) & (gray != 255)).sum())
    if stray:
        raise CaptureError(f"{path}: mask values must be 0 or 255, {stray} pixels hold others (a JPEG-damaged mask?)")
    return gray == 255


def _check_shape(path: Path, got: tuple[int, ...], expected: tuple[int, int], what: str) -> None:
    if tuple(got) != tuple(expected):
        raise CaptureError(f"{path}: {got[1]}x{got[0]} px (WxH), {what} is {expected[1]}x{expected[0]}")
