"""In-process click-to-mask benchmark: encoder time and per-click predict latency (p50/p95) of
the classical backend and of SAM2 at the default hiera-tiny architecture with random weights
and a cached (bytes round-tripped) embedding, on a synthetic illusion scene.

Run: ``python -m benchmarks.segment [--clicks N] [--size WxH] [--no-sam2]``.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path

import cv2
import numpy as np

from annotation.segment.base import Embedding, Segmenter
from annotation.segment.registry import make_segmenter
from core.formats import mask_to_rle


def person_click(truth: np.ndarray, mask: np.ndarray | None) -> tuple[float, float, int] | None:
    """The next click of a careful annotator, (x, y, label): the point deepest inside the true
    mask first, then the point deepest inside the largest wrong region (positive if it was
    missed, negative if wrongly included); None once the mask is exact."""
    wrong = truth if mask is None else truth ^ mask
    count, regions, stats, _ = cv2.connectedComponentsWithStats(wrong.astype(np.uint8), connectivity=8)
    if count <= 1:
        return None
    largest = regions == 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    depth = cv2.distanceTransform(np.pad(largest, 1).astype(np.uint8), cv2.DIST_L2, 5)[1:-1, 1:-1]
    y, x = np.unravel_index(int(np.argmax(depth)), depth.shape)
    return float(x), float(y), int(truth[y, x])


def _ms(fn: Callable[[], object]) -> float:
    start = time.perf_counter()
    fn()
    return (time.perf_counter() - start) * 1000.0


def bench_segmenter(segmenter: Segmenter, image: np.ndarray, truths: list[np.ndarray],
                    clicks: int) -> dict[str, float]:
    """Encode once (timed), then ``clicks`` predicts from a cached embedding, cycling the
    truths through 3-click annotation sessions; the RLE of the best mask is timed too."""
    encode_ms = _ms(lambda: segmenter.encode(image))
    stored = segmenter.encode(image).to_bytes()
    load_ms = _ms(lambda: Embedding.from_bytes(stored))
    embedding = Embedding.from_bytes(stored)
    predict, rle = [], []
    session = 0
    while len(predict) < clicks:
        truth = truths[session % len(truths)]
        session += 1
        points, labels, mask = [], [], None
        for _ in range(3):
            click = person_click(truth, mask)
            if click is None or len(predict) >= clicks:
                break
            points.append(click[:2])
            labels.append(click[2])
            start = time.perf_counter()
            mask = segmenter.predict(embedding, np.array(points), np.array(labels), prev_mask=mask)[0].mask
            predict.append((time.perf_counter() - start) * 1000.0)
            rle.append(_ms(partial(mask_to_rle, mask)))
    return {"encode_ms": encode_ms, "embedding_bytes": float(len(stored)), "load_ms": load_ms,
            "predict_p50_ms": float(np.percentile(predict, 50)),
            "predict_p95_ms": float(np.percentile(predict, 95)),
            "rle_p50_ms": float(np.percentile(rle, 50))}


def default_sam2_dir(root: Path) -> Path:
    """A saved Sam2Model with the default (hiera-tiny) architecture and random weights."""
    import torch
    from transformers import Sam2Config, Sam2Model

    torch.manual_seed(0)
    Sam2Model(Sam2Config()).save_pretrained(root)
    return root


def run_segment_bench(size: tuple[int, int] = (1920, 1080), clicks: int = 30,
                      sam2: bool = True) -> dict[str, dict[str, float]]:
    """Benchmark results per backend at ``size`` (width, height) pixels: encode_ms,
    embedding_bytes, load_ms (bytes to Embedding), predict_p50_ms, predict_p95_ms, rle_p50_ms."""
    from dataset.synthetic import render_video

    frame = render_video(0, n_frames=1, width=size[0], height=size[1]).frames[0]
    truths = [r.illusion for r in frame.regions]
    results = {"classical": bench_segmenter(make_segmenter("classical"), frame.left, truths, clicks)}
    if sam2:
        with tempfile.TemporaryDirectory() as tmp:
            segmenter = make_segmenter("sam2", model_path=default_sam2_dir(Path(tmp)))
            results["sam2"] = bench_segmenter(segmenter, frame.left, truths, clicks)
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clicks", type=int, default=30)
    parser.add_argument("--size", default="1920x1080", help="WIDTHxHEIGHT")
    parser.add_argument("--no-sam2", action="store_true")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.lower().split("x"))
    print(json.dumps(run_segment_bench((width, height), args.clicks, not args.no_sam2), indent=2))


if __name__ == "__main__":
    main()
