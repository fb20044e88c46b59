"""A draft's memory is bounded by its size: a near-limit draft of list-form RLE masks takes at most
three times its body while it is handled (the test client's copy of the body included), and gives it
all back afterwards. List counts are read as the compressed strings of the same runs."""

from __future__ import annotations

import gc
import json
import tracemalloc
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pycocotools import mask as coco_mask

from core.formats import FormatError, rle_to_mask
from core.formats.rle import MAX_PIXELS, compact_list_counts
from dataset.db import transaction
from dataset.services.annotate import DRAFT_VALUES, MAX_REGIONS
from dataset.tables import Frame, FrameState, SourceKind, Video
from webapp.api.blueprint import too_many_values
from webapp.bodies import DRAFT_BODY_BYTES
from webapp.runtime import Runtime

W, H = 1920, 1080
CLICKS = [{"x": 1919.2534912109375, "y": 1079.4967041015625, "label": 1}] * 1000


@pytest.fixture
def frame_id(runtime: Runtime) -> int:
    """An approved 1920x1080 frame (a draft reads only its size)."""
    with transaction(runtime.sessions) as s:
        video = Video(name="v", source_kind=SourceKind.web, content_sha256="0" * 64, width=W, height=H)
        s.add(video)
        s.flush()
        frame = Frame(video_id=video.id, index=0, time_s=0.0, width=W, height=H, content_sha256="0" * 64,
                      media_key="0" * 64 + ".png", state=FrameState.approved)
        s.add(frame)
        s.flush()
        return frame.id


def runs_of_text(chars: int, total: int, rng: np.random.Generator) -> list[int]:
    """Valid column-major runs of an H x W mask whose list text is about ``chars`` characters: two-digit
    runs (Python's small ints, the least memory per run once parsed) and one long run closing the mask."""
    runs = rng.integers(10, 36, size=chars // 3).tolist()  # 22.5 on average: within 1920x1080
    runs.append(total - sum(runs))
    return runs


def big_runs(chars: int) -> list[int]:
    """Runs no mask adds up to, each a separate int object once parsed (the most memory per character)."""
    return list(range(100_000, 100_000 + chars // 7))


def draft(runs_of: Callable[[int], list[int]], version: int) -> bytes:
    """A draft of MAX_REGIONS regions, each with its 1000 clicks and list counts filling the body limit."""
    per_region = (DRAFT_BODY_BYTES - 4096) // MAX_REGIONS - len(json.dumps(CLICKS)) - 200
    regions = [{"pair": n // 2, "kind": ("illusion", "support")[n % 2], "clicks": CLICKS,
                "mask": {"size": [H, W], "counts": runs_of(per_region)}} for n in range(MAX_REGIONS)]
    body = json.dumps({"version": version, "submit": False, "regions": regions}, separators=(",", ":")).encode()
    assert DRAFT_BODY_BYTES * 0.95 < len(body) <= DRAFT_BODY_BYTES
    return body


def valid_draft(version: int) -> bytes:
    return draft(lambda chars: runs_of_text(chars, W * H, np.random.default_rng(chars)), version)


def traced(call: Callable[[], Any]) -> tuple[Any, int, int]:
    """``call()``'s result, the most memory traced while it ran and what it left allocated (bytes over
    what was allocated before)."""
    gc.collect()
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        result = call()
        peak = tracemalloc.get_traced_memory()[1] - before
        gc.collect()
        left = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    return result, peak, left


def post(client: Any, tokens: dict[str, str], frame_id: int, body: bytes) -> Any:
    return client.post(f"/api/v1/frames/{frame_id}/annotation", data=body, content_type="application/json",
                       headers={"Authorization": f"Bearer {tokens['annotator']}"})


def warm_up(client: Any, tokens: dict[str, str], frame_id: int) -> None:
    """One small draft first: the app's first request fills caches (SQL statements) for good."""
    small = {"version": 0, "submit": False, "regions": []}
    assert post(client, tokens, frame_id, json.dumps(small).encode()).status_code == 200


def assert_bounded(body: bytes, peak: int, left: int, decoded: int = 0) -> None:
    """At most three times the body (and the ``decoded`` bytes of a mask) at once; nothing left after."""
    assert peak <= 3 * len(body) + decoded, f"peak {peak / 2**20:.1f} MiB for a {len(body) / 2**20:.1f} MiB draft"
    assert left <= len(body) // 20, f"{left / 2**20:.1f} MiB still allocated after the request"


def test_a_near_limit_draft_of_list_masks_takes_at_most_three_times_its_size(client, tokens, frame_id) -> None:  # type: ignore[no-untyped-def]
    """Measured over the draft before it too: its masks and clicks are not read back to be replaced."""
    warm_up(client, tokens, frame_id)
    assert post(client, tokens, frame_id, valid_draft(1)).status_code == 200
    body = valid_draft(2)
    response, peak, left = traced(lambda: post(client, tokens, frame_id, body))
    assert response.status_code == 200, response.json
    assert_bounded(body, peak, left)


def test_an_invalid_draft_of_large_runs_is_refused_within_the_same_bound(client, tokens, frame_id) -> None:  # type: ignore[no-untyped-def]
    warm_up(client, tokens, frame_id)
    body = draft(big_runs, 1)
    response, peak, left = traced(lambda: post(client, tokens, frame_id, body))
    assert response.status_code == 400 and "region 0: RLE runs do not add up" in response.json["error"], response.json
    assert_bounded(body, peak, left)


def test_a_draft_of_more_entries_than_any_is_refused_unparsed(client, tokens, frame_id) -> None:  # type: ignore[no-untyped-def]
    """``{},`` is 3 bytes of JSON and 72 of parsed objects: a draft of them was never parsed whole."""
    warm_up(client, tokens, frame_id)
    region = {"pair": 0, "kind": "illusion", "mask": {"size": [H, W], "counts": []}, "clicks": [{}] * 6_900_000}
    body = json.dumps({"version": 1, "submit": False, "regions": [region]}, separators=(",", ":")).encode()
    assert DRAFT_BODY_BYTES * 0.95 < len(body) <= DRAFT_BODY_BYTES
    response, peak, left = traced(lambda: post(client, tokens, frame_id, body))
    assert response.status_code == 400 and f"more than {DRAFT_VALUES} values" in response.json["error"], response.json
    assert_bounded(body, peak, left)


def test_a_long_compressed_mask_is_checked_a_chunk_at_a_time(client, tokens, frame_id) -> None:  # type: ignore[no-untyped-def]
    """A run per character of 1920x1080: its check took some 40 bytes a character at once."""
    warm_up(client, tokens, frame_id)
    stripes = np.zeros((H, W), bool)
    stripes[::2] = True
    counts = coco_mask.encode(np.asfortranarray(stripes.astype(np.uint8)))["counts"].decode()
    regions = [{"pair": 0, "kind": "illusion", "mask": {"size": [H, W], "counts": counts}},
               {"pair": 0, "kind": "support", "mask": {"size": [H, W], "counts": "0" * (W * H)}}]
    for version, region, status in ((1, regions[0], 200), (2, regions[1], 400)):
        body = json.dumps({"version": version, "submit": False, "regions": [region]}).encode()
        response, peak, left = traced(lambda body=body: post(client, tokens, frame_id, body))
        assert response.status_code == status, response.json
        assert_bounded(body, peak, left, decoded=2 * W * H)  # a byte a pixel, and its encoding


def test_the_saved_draft_keeps_every_mask_as_sent(client, tokens, frame_id) -> None:  # type: ignore[no-untyped-def]
    """The compact form the server reads list counts into decodes to the same masks."""
    rng = np.random.default_rng(3)
    masks = [rng.random((H, W)) < p for p in (0.001, 0.5)]
    regions = [{"pair": 0, "kind": kind, "mask": {"size": [H, W], "counts": _list_counts(mask)}}
               for kind, mask in zip(("illusion", "support"), masks, strict=True)]
    response = post(client, tokens, frame_id, json.dumps({"version": 0, "submit": False, "regions": regions}).encode())
    assert response.status_code == 200, response.json
    stored = client.get(f"/api/v1/frames/{frame_id}", headers={"Authorization": f"Bearer {tokens['annotator']}"}).json
    for region, mask in zip(stored["regions"], masks, strict=True):
        assert np.array_equal(rle_to_mask(region["mask"], (H, W)), mask)


def _list_counts(mask: np.ndarray) -> list[int]:
    """The uncompressed (list) COCO counts of ``mask``."""
    flat = mask.ravel(order="F").astype(np.int8)
    runs = np.diff(np.r_[0, np.flatnonzero(np.diff(flat)) + 1, flat.size]).tolist()
    return [0, *runs] if flat[0] else runs


runs_lists = st.lists(st.one_of(st.integers(0, 40), st.integers(0, MAX_PIXELS)), max_size=300)


@settings(max_examples=300, deadline=None)
@given(runs_lists)
def test_list_counts_become_pycocotools_compressed_strings(runs: list[int]) -> None:
    text = json.dumps({"mask": {"size": [1, max(sum(runs), 1)], "counts": runs}, "counts": runs}).encode()
    compact = json.loads(compact_list_counts(text))
    assert compact["counts"] == compact["mask"]["counts"]
    if runs and 0 < sum(runs) < 1 << 32:
        coded = coco_mask.frPyObjects({"size": [1, sum(runs)], "counts": runs}, 1, sum(runs))
        assert compact["counts"] == coded["counts"].decode()


@pytest.mark.parametrize("runs", [[5] * 40_000, [0, 1, 2, 3] * 20_000, [MAX_PIXELS, 0] * 10_000])
def test_long_lists_read_in_chunks_keep_their_runs(runs: list[int]) -> None:
    compact = json.loads(compact_list_counts(json.dumps({"counts": runs}).encode()))["counts"]
    shape = (1, sum(runs))
    if shape[1] <= MAX_PIXELS:
        assert np.array_equal(rle_to_mask({"size": list(shape), "counts": compact}, shape),
                              rle_to_mask({"size": list(shape), "counts": runs}, shape))
    else:  # only the runs can be compared
        assert coco_mask.frPyObjects({"size": [1, 2**31], "counts": runs}, 1, 2**31)["counts"].decode() == compact


@pytest.mark.parametrize(("text", "read_as"), [
    (b'{"counts": [1, -5, 3]}', {"counts": [-1]}),  # out of range either way
    (b'{"counts": [1, 99999999999999999999999]}', {"counts": [-1]}),
    (b'{"counts": []}', {"counts": ""}),
    (b'{"x \\"counts": [1]}', {'x "counts': [1]}),  # a key that ends in counts is no counts
    (b'{"counts": [1.5, 2]}', {"counts": [1.5, 2]}),  # left to the parser (and the mask's check)
    (b'{"counts": "0"}', {"counts": "0"}),
])
def test_what_list_counts_are_read_as(text: bytes, read_as: dict[str, Any]) -> None:
    assert json.loads(compact_list_counts(text)) == read_as


@pytest.mark.parametrize("text", [b'{"counts": [1,,2]}', b'{"counts": [1,2,]}', b'{"counts": [01]}',
                                  b'{"counts": [1 2]}', b'{"counts": [-]}', b'{"counts": [' + b"1," * 50_000 + b"]}"])
def test_a_list_that_is_not_json_is_refused(text: bytes) -> None:
    with pytest.raises(ValueError, match="counts list at byte 11"):
        compact_list_counts(text)


def test_the_masks_check_refuses_what_it_refused() -> None:
    for counts, message in ((["0" * 20 + "`0"], "more runs than 4x4"), (["o" * 6 + "0"], "too long"),
                            (["0o"], "ends inside a number"), (["0é"], "ASCII"), (["1"], "add up")):
        with pytest.raises(FormatError, match=message):
            rle_to_mask({"size": [4, 4], "counts": counts[0]}, (4, 4))


def test_values_are_counted_outside_masks_counts() -> None:
    clicks = json.dumps([{"x": 1.5, "y": 2, "label": 1}] * 10)
    assert not too_many_values(clicks.encode(), 71) and too_many_values(clicks.encode(), 70)
    colons = json.dumps({"mask": {"counts": ":[" * 1000}, "clicks": json.loads(clicks)}).encode()
    assert not too_many_values(colons, 80)
    assert too_many_values(b"[" + b'"",' * 100 + b'""]', 100)  # strings are values too
