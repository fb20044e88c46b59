"""Throughput of the openai backend's client against the local server answering at once.

The figure that matters is frames/s of the client alone: it must stay well above what a real
VLM server delivers (≥ 50 frames/s here), so that the server, never the client, is the limit.
"""

from __future__ import annotations

import time

import numpy as np

from annotation.vlm.backends.openai_compat import OpenAICompatBackend
from annotation.vlm.parse import format_answers
from annotation.vlm.prompt import N_QUESTIONS
from benchmarks.vlm_server import LocalVLMServer, fixed_responder

_DISTINCT_FRAMES = 4  # rendered once and cycled: the client still JPEG-encodes every request
_SEQUENTIAL_FRAMES = 100  # enough for a stable concurrency-1 reference


def run_prefilter_bench(frames: int = 400, concurrency: int = 16) -> dict[str, float | int]:
    """Classify ``frames`` synthetic 640x360 frames at ``concurrency`` and, for reference, at 1.

    Returns ``openai_client_fps``, ``reference_sequential_fps`` (frames/s), ``frames`` and ``concurrency``.
    """
    # Imported here: the synthetic renderer is only needed to benchmark.
    from dataset.synthetic import render_video

    images = [render_video(seed, n_frames=1, width=640, height=360).frames[0].left for seed in range(_DISTINCT_FRAMES)]
    with LocalVLMServer(fixed_responder(format_answers([False] * N_QUESTIONS))) as server:
        client_fps = _frames_per_second(server.base_url, images, frames, concurrency)
        sequential_fps = _frames_per_second(server.base_url, images, min(frames, _SEQUENTIAL_FRAMES), 1)
    return {
        "openai_client_fps": round(client_fps, 1),
        "frames": frames,
        "concurrency": concurrency,
        "reference_sequential_fps": round(sequential_fps, 1),
    }


def _frames_per_second(base_url: str, images: list[np.ndarray], frames: int, concurrency: int) -> float:
    batch = [images[i % len(images)] for i in range(frames)]
    with OpenAICompatBackend(base_url, "bench", concurrency=concurrency, timeout_s=10.0, max_retries=0) as backend:
        backend.classify(batch[:concurrency])  # open the connections and start the threads first
        started = time.perf_counter()
        verdicts = backend.classify(batch)
        elapsed = time.perf_counter() - started
    failed = [v.error for v in verdicts if not v.parsed]
    if failed:
        raise RuntimeError(f"{len(failed)} of {frames} benchmark requests failed, first: {failed[0]}")
    return frames / elapsed
