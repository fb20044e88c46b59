"""Click → mask over HTTP: p50/p95 of ``POST /api/v1/frames/{id}/segment`` at 1080p with a cached
embedding, for the classical backend and SAM2 (default hiera-tiny architecture, random weights),
beside the same clicks answered in-process (the reference: what HTTP, JSON and RLE add).

A real server (`illusion-studio serve`: cheroot, webapp.server) in its own process, a real database and media
store in a temp workspace, and clicks placed as a careful annotator would (``person_click``).
SAM2 with random weights answers with noisy masks whose RLE is far larger than a trained
model's (see ``response_kb_p50``), so its HTTP figure is an upper bound.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path
from typing import Any

import cv2
import httpx
import numpy as np

from annotation.segment import Embedding
from benchmarks.segment import default_sam2_dir, person_click
from benchmarks.served import served_app
from benchmarks.workspace import approved_frame_workspace
from core.formats import mask_to_rle, rle_to_mask
from dataset.db import transaction
from dataset.services import segmentation
from dataset.services import users as user_service
from dataset.synthetic import write_synthetic_dataset
from dataset.tables import Frame, User
from webapp.runtime import Runtime


def _workspace(root: Path, scene: Path, **settings: Any) -> tuple[Runtime, int, str]:
    rt, frame_id, user_id = approved_frame_workspace(root / f"ws-{settings.get('segmenter', 'classical')}", scene,
                                                     **settings)
    with transaction(rt.sessions) as s:
        token = user_service.issue_token(s, s.get(User, user_id))
    return rt, frame_id, token


def _bench_backend(rt: Runtime, frame_id: int, token: str, truths: list[np.ndarray], clicks: int) -> dict[str, float]:
    with rt.sessions() as s:
        frame = s.get(Frame, frame_id)
    started = time.perf_counter()
    segmentation.encode_frames(rt.settings, rt.media, [frame])
    encode_ms = (time.perf_counter() - started) * 1000
    segmenter = segmentation.settings_segmenter(rt.settings)
    embedding = Embedding.from_bytes(segmentation.embedding_cache(rt.settings).get(frame.content_sha256, segmenter.model_id))

    http, local, response_bytes = [], [], []
    # The server runs in its own process, as in production, so client and server don't share a GIL.
    with served_app(rt.settings.home) as base_url, httpx.Client(
            base_url=base_url, headers={"Authorization": f"Bearer {token}"}, timeout=120) as client:
        # Untimed: the server loads the segmenter and the embedding once, as for an annotator's first click.
        client.post(f"/api/v1/frames/{frame_id}/segment", json={"points": [[1.0, 1.0]], "labels": [1]})
        session = 0
        while len(http) < clicks:  # sessions of up to 3 clicks per illusion, as a careful annotator works
            truth, points, labels, mask = truths[session % len(truths)], [], [], None
            session += 1
            for _ in range(3):
                click = person_click(truth, mask)
                if click is None or len(http) >= clicks:
                    break
                points.append([click[0], click[1]])
                labels.append(click[2])
                body: dict[str, Any] = {"points": points, "labels": labels, "region_kind": "illusion"}
                if mask is not None:
                    body["prev_mask"] = mask_to_rle(mask)
                start = time.perf_counter()
                response = client.post(f"/api/v1/frames/{frame_id}/segment", json=body)
                http.append((time.perf_counter() - start) * 1000)
                response.raise_for_status()
                response_bytes.append(len(response.content))
                if not response.json()["embedding_cached"]:
                    raise RuntimeError("the embedding was not cached: the benchmark would time the encoder")
                start = time.perf_counter()
                segmenter.predict(embedding, np.array(points), np.array(labels), prev_mask=mask)
                local.append((time.perf_counter() - start) * 1000)
                mask = rle_to_mask(response.json()["mask"], truth.shape)
    return {"http_p50_ms": round(float(np.percentile(http, 50)), 1), "http_p95_ms": round(float(np.percentile(http, 95)), 1),
            "in_process_p50_ms": round(float(np.percentile(local, 50)), 1), "encode_ms": round(encode_ms, 1),
            "response_kb_p50": round(float(np.percentile(response_bytes, 50)) / 1024, 1), "clicks": len(http)}


def run_click_bench(clicks: int = 30, size: tuple[int, int] = (1920, 1080), sam2: bool = True) -> dict[str, Any]:
    """Per backend: HTTP p50/p95, the in-process predict p50 of the same clicks, and the encoder time."""
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        [scene] = write_synthetic_dataset(root / "scene", videos=1, seed=0, n_frames=1, width=size[0], height=size[1])
        masks = sorted((scene / "frames" / "000000").glob("illusion_*.png"))
        truths = [cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) > 127 for p in masks]
        results: dict[str, Any] = {"size": f"{size[0]}x{size[1]}"}
        rt, frame_id, token = _workspace(root, scene)
        results["classical"] = _bench_backend(rt, frame_id, token, truths, clicks)
        rt.close()
        if sam2:
            model_dir = default_sam2_dir(root / "sam2-tiny-random")
            rt, frame_id, token = _workspace(root, scene, segmenter="sam2", sam2_model_path=model_dir)
            results["sam2"] = _bench_backend(rt, frame_id, token, truths, clicks)
            rt.close()
        return results
