"""RGB frames ↔ ``data:image/jpeg;base64,…`` URLs, the way OpenAI-compatible servers take images."""

from __future__ import annotations

import base64

import cv2
import numpy as np

_PREFIX = "data:image/jpeg;base64,"


def image_to_data_url(rgb: np.ndarray, quality: int = 90) -> str:
    """JPEG-encode an RGB uint8 HxWx3 image (quality 0–100) as a data URL."""
    ok, jpeg = cv2.imencode(".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise ValueError("JPEG encoding failed")
    return _PREFIX + base64.b64encode(jpeg.tobytes()).decode("ascii")


def data_url_to_image(url: str) -> np.ndarray:
    """Decode a base64 image data URL (JPEG, PNG, …) to RGB uint8 HxWx3; ValueError when it is not one."""
    header, sep, payload = url.partition(",")
    if not sep or not header.startswith("data:image/") or not header.endswith(";base64"):
        raise ValueError("not a base64 image data URL")
    try:
        raw = base64.b64decode(payload, validate=True)
    except ValueError as exc:
        raise ValueError(f"bad base64 payload: {exc}") from None
    bgr = cv2.imdecode(np.frombuffer(raw, np.uint8), cv2.IMREAD_COLOR)
    if bgr is None:
        raise ValueError("undecodable image")
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
