"""An upload refused with 503 while the job queue is down leaves no file in the media store."""

from __future__ import annotations

import io
import os
from pathlib import Path

import pytest

from tests.test_queue_outage import outage_app


@pytest.mark.parametrize("outage", ["redis", "sqlite"])
def test_an_upload_refused_with_503_stores_no_file(tmp_path: Path, outage: str) -> None:
    if outage == "redis":  # nothing listens on port 1
        app, runtime, auth = outage_app(tmp_path, queue_url="redis://127.0.0.1:1/0")
    else:  # the SQLite queue file goes bad while the server runs
        app, runtime, auth = outage_app(tmp_path)
        assert runtime.queue.huey is not None  # opened before its file went bad
        runtime.settings.queue_path.write_bytes(b"this is not an SQLite database" * 100)
    client = app.test_client()
    for _ in range(3):
        data = {"file": (io.BytesIO(os.urandom(4096)), "clip.mp4")}
        response = client.post("/api/v1/videos", data=data, headers=auth, content_type="multipart/form-data")
        assert response.status_code == 503, response.get_json()
    media = runtime.settings.media_root
    assert [p.relative_to(media) for p in media.rglob("*") if p.is_file()] == []
    runtime.close()
