"""Masks and stored free-form fields from requests have bounds: an RLE's size is checked against its frame
before anything is decoded (a 16384² mask in 70 bytes is refused in milliseconds), region clicks are the
entries the page sends and no more, and reasons and passwords have a length limit."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import pytest
from sqlalchemy import select

from core.formats import FormatError, mask_to_rle, rle_to_mask
from dataset.db import transaction
from dataset.services import users as user_service
from dataset.services.validate import REASON_CHARS
from dataset.tables import Annotation, Frame, FrameState, Sample, SampleState
from tests.fixtures.annotate import H, W
from tests.test_annotate import auth

HUGE = {"size": [16384, 16384], "counts": [16384 * 16384]}  # 2^28 pixels in 40 bytes of JSON
HUGE_TEXT = mask_to_rle(np.zeros((1, 1), bool)) | {"size": [16384, 16384], "counts": "0" + "o" * 5 + "0"}


def test_the_size_is_checked_against_the_frame_before_decoding() -> None:
    for rle in (HUGE, HUGE_TEXT):
        started = time.perf_counter()
        with pytest.raises(FormatError, match="RLE size is 16384x16384, the frame 320x180"):
            rle_to_mask(rle, (H, W))
        assert time.perf_counter() - started < 0.05
    mask = np.zeros((H, W), bool)
    mask[10:20, 30:40] = True
    assert np.array_equal(rle_to_mask(mask_to_rle(mask), (H, W)), mask)


@pytest.mark.parametrize(("rle", "message"), [
    ({"size": [4, 4], "counts": [0] * 20 + [16]}, "more runs than 4x4 pixels"),
    ({"size": [4, 4], "counts": "0" * 20 + "`0"}, "more runs than 4x4 pixels"),
    ({"size": [4.9, 4], "counts": [16]}, "integers"),
    ({"size": [True, 16], "counts": [16]}, "integers"),
    ({"size": [4, 4], "counts": "o" * 6 + "0"}, "a number too long"),  # 7 groups: beyond pycocotools' C
    ({"size": [4, 4], "counts": [15, True]}, "integers"),
    ({"size": [4, 4], "counts": [15, 1 << 80]}, "add up"),
    ({"size": [4, 4], "counts": [(1 << 63) - 1, (1 << 63) - 1, 18]}, "add up"),  # int64 sum wraps to 16
])
def test_runs_are_checked_cheaply(rle: dict[str, Any], message: str) -> None:
    with pytest.raises(FormatError, match=message):
        rle_to_mask(rle, (4, 4))


def test_a_worst_case_mask_of_the_frame() -> None:
    stripes = np.zeros((1080, 1920), bool)
    stripes[::2] = True  # a run per pixel: the most runs a 1080p mask can have
    assert np.array_equal(rle_to_mask(mask_to_rle(stripes), (1080, 1920)), stripes)


def _frame_id(client, tokens) -> int:  # type: ignore[no-untyped-def]
    return client.post("/api/v1/queue/annotate/next", headers=auth(tokens)).json["frame_id"]


def _region(mask: Any, clicks: Any = None) -> dict[str, Any]:
    return {"pair": 0, "kind": "illusion", "mask": mask, **({"clicks": clicks} if clicks is not None else {})}


def test_every_route_taking_a_mask_refuses_another_size_at_once(client, tokens, scene) -> None:  # type: ignore[no-untyped-def]
    frame_id = _frame_id(client, tokens)
    requests = [
        ("propagate", {"pair": 0, "kind": "illusion", "mask": HUGE, "count": 2}),
        ("segment", {"points": [[5, 5]], "labels": [1], "prev_mask": HUGE}),
        ("annotation", {"version": 0, "regions": [_region(HUGE)], "submit": False}),
        ("annotation", {"version": 0, "regions": [_region(HUGE_TEXT)], "illusion_type": "picture", "submit": True}),
    ]
    for route, body in requests:
        started = time.perf_counter()
        answer = client.post(f"/api/v1/frames/{frame_id}/{route}", headers=auth(tokens), json=body)
        took = time.perf_counter() - started
        assert answer.status_code == 400 and "RLE size is 16384x16384, the frame 320x180" in answer.json["error"], answer.json
        assert took < 0.5, (route, took)


def test_propagation_keeps_the_mask_in_its_compressed_form(client, tokens, scene) -> None:  # type: ignore[no-untyped-def]
    frame_id = _frame_id(client, tokens)
    mask = np.zeros((H, W), bool)
    mask[40:80, 100:200] = True
    runs = [int(v) for v in np.diff(np.flatnonzero(np.diff(np.r_[-1, mask.T.ravel().astype(int), -1])))]
    job = client.post(f"/api/v1/frames/{frame_id}/propagate", headers=auth(tokens),
                      json={"pair": 0, "kind": "illusion", "mask": {"size": [H, W], "counts": runs}, "count": 1})
    assert job.status_code == 202 and job.json["params"]["mask"] == mask_to_rle(mask)


GOOD_CLICKS = [{"x": 1, "y": 2, "label": 1}, {"x": 319.0, "y": 179, "label": 0}, {"box": [0, 0, 320, 180]},
               {"proposal_id": 7}, {"propagated_from": 3}, {"from": "ground truth"}]


@pytest.mark.parametrize(("clicks", "message"), [
    ([{"x": 1, "y": 2, "label": 1, "note": "x" * 100_000}], "clicks entry 0"),
    ([{"blob": ["x" * 1000] * 1000}], "clicks entry 0"),
    ([{"x": 1, "y": 2, "label": 2}], "clicks entry 0"),
    ([{"x": 1, "y": 2, "label": True}], "clicks entry 0"),
    ([{"x": "1", "y": 2, "label": 1}], "clicks entry 0"),
    ([{"x": 1, "y": 2, "label": 1}, {"box": [0, 0, 10]}], "clicks entry 1"),
    ([{"proposal_id": "1"}], "clicks entry 0"),
    ([{"proposal_id": 2**40}], "clicks entry 0"),
    ([{"from": "y" * 65}], "clicks entry 0"),
    (["a click"], "clicks entry 0"),
    ([{"x": 320, "y": 2, "label": 1}], "outside the 320x180 frame"),
    ([{"x": -1, "y": 2, "label": 1}], "clicks entry 0"),
    ([{"box": [0, 0, 321, 10]}], "outside the 320x180 frame"),
    ([{"x": 1, "y": 1, "label": 1}] * 1001, "at most 1000"),
    ({"x": 1}, "must be a list"),
])
def test_clicks_are_what_the_page_sends(client, tokens, scene, clicks: Any, message: str) -> None:  # type: ignore[no-untyped-def]
    frame_id = _frame_id(client, tokens)
    mask = mask_to_rle(np.ones((H, W), bool))
    answer = client.post(f"/api/v1/frames/{frame_id}/annotation", headers=auth(tokens),
                         json={"version": 0, "regions": [_region(mask, clicks)], "submit": False})
    assert answer.status_code == 400 and message in answer.json["error"], answer.json


def test_the_clicks_the_page_sends_are_stored_as_sent(client, tokens, scene) -> None:  # type: ignore[no-untyped-def]
    frame_id = _frame_id(client, tokens)
    mask = mask_to_rle(np.ones((H, W), bool))
    saved = client.post(f"/api/v1/frames/{frame_id}/annotation", headers=auth(tokens),
                        json={"version": 0, "regions": [_region(mask, GOOD_CLICKS)], "submit": False})
    assert saved.status_code == 200, saved.json
    assert client.get(f"/api/v1/frames/{frame_id}", headers=auth(tokens)).json["regions"][0]["clicks"] == GOOD_CLICKS


def test_reasons_have_a_bound(client, tokens, scene, runtime) -> None:  # type: ignore[no-untyped-def]
    frame_id = _frame_id(client, tokens)
    long = "r" * (REASON_CHARS + 1)
    with transaction(runtime.sessions) as s:
        frame = s.get(Frame, frame_id)
        frame.state = FrameState.generated
        s.add(Sample(frame_id=frame_id, annotation_version=0, state=SampleState.generated))
    with runtime.sessions() as s:
        sample_id = s.scalar(select(Sample.id).where(Sample.frame_id == frame_id))
        assert s.scalar(select(Annotation.version).where(Annotation.frame_id == frame_id)) == 0
    for url, body in ((f"/api/v1/samples/{sample_id}/review", {"decision": "reject", "reason": long}),
                      (f"/api/v1/frames/{frame_id}/review", {"decision": "reject", "reason": long}),
                      ("/api/v1/review/bulk", {"items": [{"id": frame_id}], "decision": "reject", "reason": long})):
        answer = client.post(url, headers=auth(tokens, "curator"), json=body)
        assert answer.status_code == 400 and f"at most {REASON_CHARS} characters" in answer.json["error"], (url, answer.json)
    fine = client.post(f"/api/v1/samples/{sample_id}/review", headers=auth(tokens, "curator"),
                       json={"decision": "reject", "reason": "see /usr/share/doc " + "r" * (REASON_CHARS - 19)})
    assert fine.status_code == 200, fine.json


def test_free_text_fields_have_a_bound(client, tokens, runtime) -> None:  # type: ignore[no-untyped-def]
    answer = client.post("/api/v1/users", headers=auth(tokens, "admin"),
                         json={"name": "newbie", "role": "annotator", "password": "p" * 10_000})
    assert answer.status_code == 400 and "password" in answer.json["error"], answer.json
    answer = client.post("/api/v1/users", headers=auth(tokens, "admin"),
                         json={"name": "newbie", "role": "annotator" * 1000, "password": "long enough"})
    assert answer.status_code == 400 and len(answer.json["error"]) < 200, answer.json  # not the role echoed back
    with transaction(runtime.sessions) as s, pytest.raises(Exception, match="password"):
        user_service.reset_password(s, None, user_service.get_user(s, "annotator"), "p" * 10_000)
