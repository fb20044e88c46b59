"""The classical (no-weights) segmenter on the synthetic illusion scenes: clicks placed as a
person would, box prompts, prompt validation and optical-flow propagation."""

from __future__ import annotations

import numpy as np
import pytest

from annotation.segment import Embedding, SegmentError, make_segmenter
from benchmarks.segment import person_click
from dataset.synthetic import render_video

SEEDS = range(5)
CLICK_SIZE = (1280, 720)


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max((a | b).sum(), 1))


@pytest.fixture(scope="module")
def segmenter():
    return make_segmenter("classical")


@pytest.fixture(scope="module")
def scenes() -> list:
    """First frames of five synthetic videos at 1280x720."""
    return [render_video(seed, n_frames=1, width=CLICK_SIZE[0], height=CLICK_SIZE[1]).frames[0]
            for seed in SEEDS]


@pytest.fixture(scope="module")
def embeddings(segmenter, scenes) -> list[Embedding]:
    return [segmenter.encode(frame.left) for frame in scenes]


def click_session(segmenter, embedding: Embedding, truth: np.ndarray, clicks: int = 3) -> list[float]:
    """IoU after each of up to ``clicks`` person clicks, each correcting the previous mask."""
    points, labels, mask, ious = [], [], None, []
    for _ in range(clicks):
        click = person_click(truth, mask)
        if click is None:
            break
        points.append(click[:2])
        labels.append(click[2])
        mask = segmenter.predict(embedding, np.array(points), np.array(labels), prev_mask=mask)[0].mask
        ious.append(iou(mask, truth))
    return ious


@pytest.mark.parametrize("kind", ["picture", "mirror"])
def test_person_reaches_iou_08_within_three_clicks(segmenter, scenes, embeddings, kind) -> None:
    results = {}
    for seed, frame, embedding in zip(SEEDS, scenes, embeddings):
        truth = next(r.illusion for r in frame.regions if r.kind == kind)
        results[seed] = click_session(segmenter, embedding, truth)
    print(kind, {seed: [round(v, 3) for v in ious] for seed, ious in results.items()})
    assert all(max(ious) >= 0.8 for ious in results.values()), results
    # the corrections must not make things worse overall
    assert all(ious[-1] >= ious[0] - 0.02 for ious in results.values()), results


def test_candidates_are_full_resolution_and_scored(segmenter, scenes, embeddings) -> None:
    truth = scenes[0].regions[0].illusion
    x, y, _ = person_click(truth, None)
    first = segmenter.predict(embeddings[0], np.array([[x, y]]), np.array([1]))
    assert 1 <= len(first) <= 3
    assert all(c.mask.dtype == bool and c.mask.shape == (720, 1280) for c in first)
    assert all(0.0 <= c.score <= 1.0 for c in first)
    assert first[0].mask[int(y), int(x)]
    # correcting with a negative click returns the alternative that ignores prev_mask as well
    nx, ny, label = person_click(truth, first[0].mask)
    assert label == 0
    second = segmenter.predict(embeddings[0], np.array([[x, y], [nx, ny]]), np.array([1, 0]),
                               prev_mask=first[0].mask)
    assert not second[0].mask[int(ny), int(nx)] and second[0].mask[int(y), int(x)]


def test_box_alone_segments_the_picture(segmenter, scenes, embeddings) -> None:
    for frame, embedding in zip(scenes[:3], embeddings[:3]):
        truth = frame.regions[0].illusion
        ys, xs = np.nonzero(truth)
        box = (xs.min() - 12.0, ys.min() - 12.0, xs.max() + 12.0, ys.max() + 12.0)
        mask = segmenter.predict(embedding, np.zeros((0, 2)), np.zeros(0, int), box=box)[0].mask
        assert iou(mask, truth) >= 0.7
        assert not mask[:, : int(box[0])].any() and not mask[:, int(box[2]) + 2:].any()


def test_embedding_round_trip_and_size(segmenter, scenes, embeddings) -> None:
    data = embeddings[1].to_bytes()
    assert len(data) < 3_000_000  # 1280x720: working image, gradient and a JPEG
    restored = Embedding.from_bytes(data)
    assert (restored.height, restored.width, restored.model_id) == (720, 1280, segmenter.model_id)
    points, labels = np.array([[640.0, 360.0], [100.0, 100.0]]), np.array([1, 0])
    a = segmenter.predict(embeddings[1], points, labels)
    b = segmenter.predict(restored, points, labels)
    assert all(np.array_equal(x.mask, y.mask) and x.score == y.score for x, y in zip(a, b))


@pytest.mark.parametrize(("points", "labels", "kwargs", "message"), [
    (np.zeros((0, 2)), np.zeros(0), {}, "nothing to segment"),
    (np.array([[10.0, 10.0]]), np.array([0]), {}, "nothing to segment"),
    (np.array([10.0, 10.0, 3.0]), np.array([1]), {}, r"\(N, 2\)"),
    (np.array([[10.0, 10.0]]), np.array([1, 0]), {}, "1 points but 2 labels"),
    (np.array([[10.0, 10.0]]), np.array([2]), {}, "labels must be 0 or 1"),
    (np.array([[1280.0, 10.0]]), np.array([1]), {}, "outside"),
    (np.array([[10.0, -3.0]]), np.array([1]), {}, "outside"),
    (np.array([[np.nan, 3.0]]), np.array([1]), {}, "outside"),
    (np.array([[10.0, 10.0]]), np.array([1]), {"box": (50, 50, 20, 80)}, "x0 < x1"),
    (np.array([[10.0, 10.0]]), np.array([1]), {"box": (2000, 50, 2100, 80)}, "outside"),
    (np.array([[10.0, 10.0]]), np.array([1]), {"prev_mask": np.zeros((10, 10), bool)}, "prev_mask"),
])
def test_bad_prompts_raise_segment_error(segmenter, embeddings, points, labels, kwargs, message) -> None:
    with pytest.raises(SegmentError, match=message):
        segmenter.predict(embeddings[0], points, labels, **kwargs)


def test_foreign_or_damaged_embeddings_are_refused(segmenter, embeddings) -> None:
    foreign = Embedding("sam2:other:123", 720, 1280, {})
    with pytest.raises(SegmentError, match="embedding made by"):
        segmenter.predict(foreign, np.array([[5.0, 5.0]]), np.array([1]))
    with pytest.raises(SegmentError, match="lacks"):
        segmenter.predict(Embedding(segmenter.model_id, 720, 1280, {}), np.array([[5.0, 5.0]]), np.array([1]))
    with pytest.raises(SegmentError, match="not a segmenter embedding"):
        Embedding.from_bytes(b"not an npz")
    with pytest.raises(SegmentError):
        segmenter.encode(np.zeros((10, 10), np.uint8))


@pytest.mark.parametrize("seed", [0, 3])
def test_flow_propagation_follows_the_camera(segmenter, seed) -> None:
    video = render_video(seed, n_frames=4, width=640, height=360)
    seen: list[float] = []
    for pair in (0, 1):
        truths = [f.regions[pair].illusion for f in video.frames]
        out = segmenter.propagate([f.left for f in video.frames], truths[0], progress=seen.append)
        assert len(out) == 3 and all(m.dtype == bool and m.shape == (360, 640) for m in out)
        assert all(iou(m, t) >= 0.8 for m, t in zip(out, truths[1:])), [iou(m, t) for m, t in zip(out, truths[1:])]
    assert seen[-1] == pytest.approx(1.0)
    assert segmenter.propagate([video.frames[0].left], truths[0]) == []
