"""Frame thumbnails for grids: JPEG, 320 px wide."""

from __future__ import annotations

import cv2
import numpy as np

from dataset.media import MediaStore

THUMB_WIDTH = 320


def put_thumbnail(media: MediaStore, rgb: np.ndarray) -> str:
    """Store a thumbnail of the RGB uint8 HxWx3 image; returns its media key."""
    height, width = rgb.shape[:2]
    small = cv2.resize(cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), (THUMB_WIDTH, max(1, round(height * THUMB_WIDTH / width))),
                       interpolation=cv2.INTER_AREA)
    ok, buf = cv2.imencode(".jpg", small, [cv2.IMWRITE_JPEG_QUALITY, 85])
    if not ok:
        raise ValueError("could not encode a thumbnail")
    return media.put_bytes(buf.tobytes(), "jpg")
