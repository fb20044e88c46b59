"""The rig calibration file: a depth sensor rigidly mounted on a stereo colour camera (JSON).

Example (metres, pixels)::

    {
      "depth_camera": {"K": [[460, 0, 319.5], [0, 460, 239.5], [0, 0, 1]], "width": 640, "height": 480},
      "color_camera": {"K": [[1400, 0, 959.5], [0, 1400, 539.5], [0, 0, 1]], "width": 1920, "height": 1080},
      "R": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
      "T": [0.03, 0.0, 0.0],
      "baseline": 0.0628167,
      "depth_scale": 0.00025
    }

``R``, ``T`` map depth-camera coordinates to colour-camera (left) coordinates: X_c = R·X_d + T.
``baseline`` is the colour stereo pair's baseline (metres) and ``depth_scale`` the metres per
unit of the depth sensor's raw values.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from core.geometry import checks
from core.geometry.errors import CalibrationError, InputError

_TOP_KEYS = {"depth_camera", "color_camera", "R", "T", "baseline", "depth_scale"}
_CAMERA_KEYS = {"K", "width", "height"}


@dataclass(frozen=True)
class RigCalibration:
    """Validated calibration; shapes are (H, W) in pixels, K matrices 3x3 float64."""

    K_depth: np.ndarray
    depth_shape: tuple[int, int]
    K_color: np.ndarray
    color_shape: tuple[int, int]
    R: np.ndarray
    T: np.ndarray
    baseline: float
    depth_scale: float

    @property
    def focal(self) -> float:
        """The colour camera's horizontal focal length (pixels), for disparity = B·f / Z."""
        return float(self.K_color[0, 0])

    def to_json(self) -> dict[str, Any]:
        """The file's JSON object."""
        return {
            "depth_camera": _camera_json(self.K_depth, self.depth_shape),
            "color_camera": _camera_json(self.K_color, self.color_shape),
            "R": self.R.tolist(),
            "T": self.T.tolist(),
            "baseline": self.baseline,
            "depth_scale": self.depth_scale,
        }


def load_calibration(path: str | Path) -> RigCalibration:
    """Read and validate a calibration JSON file.

    Raises :class:`CalibrationError` naming the file and the offending key for a missing or
    unreadable file, invalid JSON, missing/unknown keys, wrong shapes, non-finite numbers,
    a non-rotation ``R`` or non-positive focal lengths, sizes, baseline or depth scale.
    """
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise CalibrationError(f"{path}: calibration file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise CalibrationError(f"{path}: cannot read calibration file: {exc}") from None
    except json.JSONDecodeError as exc:
        raise CalibrationError(f"{path}: not valid JSON: {exc}") from None
    try:
        return parse_calibration(data)
    except CalibrationError as exc:
        raise CalibrationError(f"{path}: {exc}") from None


def parse_calibration(data: object) -> RigCalibration:
    """Validate a calibration JSON object (see the module docstring for the layout)."""
    fields = _object(data, "calibration", _TOP_KEYS)
    K_depth, depth_shape = _camera(fields["depth_camera"], "depth_camera")
    K_color, color_shape = _camera(fields["color_camera"], "color_camera")
    return RigCalibration(
        K_depth=K_depth,
        depth_shape=depth_shape,
        K_color=K_color,
        color_shape=color_shape,
        R=_checked(checks.rotation, fields["R"], "R"),
        T=_checked(checks.vector3, fields["T"], "T"),
        baseline=_checked(checks.positive, fields["baseline"], "baseline"),
        depth_scale=_checked(checks.positive, fields["depth_scale"], "depth_scale"),
    )


def save_calibration(calibration: RigCalibration, path: str | Path) -> None:
    """Write ``calibration`` as indented JSON."""
    Path(path).write_text(json.dumps(calibration.to_json(), indent=2) + "\n", encoding="utf-8")


def _object(data: object, where: str, keys: set[str]) -> dict[str, Any]:
    if not isinstance(data, dict):
        raise CalibrationError(f"{where} must be a JSON object, got {type(data).__name__}")
    missing = sorted(keys - data.keys())
    unknown = sorted(data.keys() - keys)
    if missing:
        raise CalibrationError(f"{where} is missing {', '.join(missing)}")
    if unknown:
        raise CalibrationError(f"{where} has unknown keys {', '.join(unknown)} (expected {', '.join(sorted(keys))})")
    return data


def _camera(data: object, where: str) -> tuple[np.ndarray, tuple[int, int]]:
    fields = _object(data, where, _CAMERA_KEYS)
    K = _checked(checks.intrinsics, fields["K"], f"{where}.K")
    size = []
    for key in ("height", "width"):
        value = fields[key]
        if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
            raise CalibrationError(f"{where}.{key} must be a positive integer, got {value!r}")
        size.append(value)
    return K, (size[0], size[1])


def _checked(check: Any, value: object, name: str) -> Any:
    try:
        return check(value, name)
    except InputError as exc:
        raise CalibrationError(str(exc)) from None


def _camera_json(K: np.ndarray, shape: tuple[int, int]) -> dict[str, Any]:
    return {"K": K.tolist(), "width": shape[1], "height": shape[0]}
