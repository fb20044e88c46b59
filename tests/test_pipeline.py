"""What runs after what (dataset.services.pipeline): the jobs each step of a frame's way queues, with
typed parameters, whoever calls it (views, the demo, the benchmarks)."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest

from dataset.services import leases, pipeline, proposals, segmentation
from dataset.services.errors import Unavailable


class Queue:
    """A submit that records what it was asked to queue, refusing every kind in ``down``."""

    def __init__(self, down: tuple[str, ...] = ()) -> None:
        self.jobs: list[tuple[str, dict[str, Any], Any]] = []
        self.down = down

    def __call__(self, _session: Any, kind: str, params: dict[str, Any], user: Any) -> Any:
        if kind in self.down:
            raise Unavailable("the queue is down")
        self.jobs.append((kind, params, user))
        return SimpleNamespace(kind=kind, params=params)


def test_a_submit_queues_its_generate_with_the_version_it_saw() -> None:
    queue = Queue()
    pipeline.submitted(None, queue, pipeline.GenerateParams(7, 3), "ann")
    pipeline.submitted(None, queue, pipeline.GenerateParams(8), None)
    assert queue.jobs == [("generate", {"frame_id": 7, "annotation_version": 3}, "ann"),
                          ("generate", {"frame_id": 8}, None)]


def test_approved_frames_get_their_proposals_in_chunks_and_a_down_queue_costs_nothing(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(proposals, "frames_to_scan", lambda _s, _settings, ids: [i for i in ids if i != 2])
    monkeypatch.setattr(proposals, "propose_chunks", lambda ids: [ids[:2], ids[2:]])
    queue = Queue()
    queued = pipeline.approved(None, queue, None, [1, 2, 3, 4], "cur")
    assert queue.jobs == [("propose", {"frame_ids": [1, 3]}, "cur"), ("propose", {"frame_ids": [4]}, "cur")]
    assert len(queued) == 2
    assert pipeline.approved(None, Queue(down=("propose",)), None, [1], "cur") == []


def test_a_leased_frame_and_the_next_ones_get_embeddings_then_proposals(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(leases, "prefetch_ids", lambda _s, frame: [frame.id, frame.id + 1])
    monkeypatch.setattr(segmentation, "frames_to_encode", lambda _s, _settings, ids: ids[1:])
    monkeypatch.setattr(proposals, "frames_to_scan", lambda _s, _settings, ids: ids)
    monkeypatch.setattr(proposals, "propose_chunks", lambda ids: [ids])
    queue = Queue()
    pipeline.leased(None, queue, None, SimpleNamespace(id=5), "ann")
    assert queue.jobs == [("encode", {"frame_ids": [6]}, "ann"), ("propose", {"frame_ids": [5, 6]}, "ann")]
    # an encode the queue cannot take is the request's error, as before: the annotator is told
    with pytest.raises(Unavailable):
        pipeline.leased(None, Queue(down=("encode",)), None, SimpleNamespace(id=5), "ann")


def test_no_caller_queues_the_pipelines_kinds_itself() -> None:
    """The order is written once: outside the pipeline, nothing submits generate, propose or encode by name."""
    import re
    from pathlib import Path

    root = Path(__file__).resolve().parent.parent
    by_name = re.compile(r"submit\([^)]*[\"'](generate|propose|encode)[\"']")
    offenders = [str(path.relative_to(root)) for package in ("webapp", "dataset", "benchmarks", "model", "annotation")
                 for path in (root / package).rglob("*.py")
                 if path.name != "pipeline.py" and by_name.search(path.read_text(encoding="utf-8"))]
    assert offenders == []
