"""Bad input gets a 400 or 404 with a reason, never a 500: hand-picked cases and a schemathesis run."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import pytest

from dataset.db import migrate, transaction
from dataset.services import users as user_service
from dataset.tables import Frame, FrameState, SourceKind, Video
from tests.conftest import PASSWORD, make_settings
from webapp.runtime import Runtime

BIG = "99999999999999999999"


@pytest.mark.parametrize("path", [f"/api/v1/jobs/{BIG}", f"/api/v1/frames/{BIG}", f"/api/v1/samples/{BIG}",
                                  f"/frames/{BIG}/preview", f"/api/v1/frames?video_id={BIG}"])
def test_ids_beyond_the_database_range_are_404_or_400(client, tokens, path: str) -> None:  # type: ignore[no-untyped-def]
    status = client.get(path, headers={"Authorization": f"Bearer {tokens['admin']}"}).status_code
    assert status == (400 if "?" in path else 404)


@pytest.mark.parametrize(("path", "ascii_path"), [("/api/v1/frames/５", "/api/v1/frames/5"),
                                                   ("/api/v1/frames/١", "/api/v1/frames/1"),
                                                   ("/annotate/５", "/annotate/5")])
def test_ids_in_urls_are_ascii_digits_only(client, runtime, tokens, path: str, ascii_path: str) -> None:  # type: ignore[no-untyped-def]
    """werkzeug's ``int`` takes any Unicode digit (``５`` is 5, ``١`` is 1); the app's takes ASCII only."""
    with transaction(runtime.sessions) as s:
        video = Video(name="v", source_kind=SourceKind.web, content_sha256="f" * 64)
        s.add(video)
        s.flush()
        s.add_all(Frame(video_id=video.id, index=i, time_s=i, width=8, height=8, content_sha256=f"{i:064d}",
                        media_key="k", state=FrameState.approved) for i in range(5))
    auth = {"Authorization": f"Bearer {tokens['annotator']}"}
    assert client.get(ascii_path, headers=auth).status_code == 200
    assert client.get(path, headers=auth).status_code == 404


@pytest.mark.parametrize("query", [f"offset={BIG}", "offset=1e30", "limit=0", "limit=-1",
                                   "offset=-1"])
def test_out_of_range_query_integers_are_400(client, tokens, query: str) -> None:  # type: ignore[no-untyped-def]
    for route in ("/api/v1/frames", "/api/v1/review/frames", "/api/v1/samples"):
        response = client.get(f"{route}?{query}", headers={"Authorization": f"Bearer {tokens['admin']}"})
        assert response.status_code == 400 and "query parameter" in response.json["error"], (route, query)


@pytest.mark.parametrize(("body", "reason"), [
    (b'{"decision": "approve", "revision": 1e400}', "out of range"),
    (b"[" * 100_000, "nested too deeply"),
    (b'{"decision": "approve", "revision": NaN}', "NaN is not JSON"),
    (b'{"decision": "approve", "revision": true}', "revision"),
    (b'{"decision": "approve", "revision": ' + BIG.encode() + b"}", "revision"),
    (b'{"decision": "reject", "reason": ["blurry"]}', "reason must be a string"),
])
def test_bad_json_bodies_are_400_with_a_reason(client, tokens, body: bytes, reason: str) -> None:  # type: ignore[no-untyped-def]
    response = client.post("/api/v1/frames/1/review", data=body, content_type="application/json",
                           headers={"Authorization": f"Bearer {tokens['curator']}"})
    assert response.status_code == 400 and reason in response.json["error"], response.json


def test_bulk_review_items_must_be_objects_with_integer_ids(client, tokens) -> None:  # type: ignore[no-untyped-def]
    items = [1, "x", None, {"id": True}, {"id": int(BIG)}, {"id": 5}]
    response = client.post("/api/v1/review/bulk", json={"items": items, "decision": "approve"},
                           headers={"Authorization": f"Bearer {tokens['curator']}"})
    assert response.status_code == 200
    statuses = [r["status"] for r in response.json["results"]]
    assert statuses == [400, 400, 400, 400, 400, 404]


def test_negative_pairs_huge_labels_and_boolean_ids_are_400(client, tokens) -> None:  # type: ignore[no-untyped-def]
    auth = {"Authorization": f"Bearer {tokens['admin']}"}
    assert client.post("/api/v1/prefilter", json={"video_id": True}, headers=auth).status_code == 400
    response = client.post("/api/v1/frames/1/propagate", json={"pair": -1, "kind": "illusion"}, headers=auth)
    assert response.status_code == 400 and "pair" in response.json["error"]
    response = client.post("/api/v1/frames/1/annotation", json={"version": True}, headers=auth)
    assert response.status_code == 400 and "version" in response.json["error"]


def test_a_png_renamed_mp4_is_refused_naming_the_file(client, tokens) -> None:  # type: ignore[no-untyped-def]
    import cv2
    import numpy as np

    png = cv2.imencode(".png", np.zeros((16, 16, 3), np.uint8))[1].tobytes()
    response = client.post("/api/v1/videos", data={"file": (io.BytesIO(png), "holiday.mp4")},
                           headers={"Authorization": f"Bearer {tokens['curator']}"}, content_type="multipart/form-data")
    assert response.status_code == 400, response.json
    assert "holiday.mp4" in response.json["error"] and "PNG image" in response.json["error"]
    assert "/" not in response.json["error"].replace("holiday.mp4", "")  # no server path


@pytest.fixture
def fuzz_app(db_url: str, tmp_path: Path):  # type: ignore[no-untyped-def]
    """An app on each database with one admin token; no worker runs, so queued jobs stay queued."""
    from webapp.app import create_app

    settings = make_settings(tmp_path / "fuzz", database_url=db_url)
    migrate(settings.database_url)
    runtime = Runtime(settings)
    with transaction(runtime.sessions) as s:
        token = user_service.issue_token(s, user_service.create_user(s, "fuzzer", "admin", PASSWORD))
    app = create_app(settings, runtime)
    yield app, {"Authorization": f"Bearer {token}"}
    runtime.close()


# None of the API's routes ends the caller's own session or token; a route that does goes here.
REVOKES_OWN_CREDENTIALS: set[tuple[str, str]] = set()


def documented_answer_checks() -> list[Any]:
    """schemathesis's checks that an answer's status and content type are documented for its operation."""
    from schemathesis.checks import content_type_conformance, status_code_conformance

    return [status_code_conformance, content_type_conformance]


@pytest.mark.slow
def test_no_input_the_openapi_document_allows_gets_a_server_error_or_an_undocumented_answer(fuzz_app) -> None:  # type: ignore[no-untyped-def]
    import schemathesis
    from hypothesis import HealthCheck, given, seed, settings
    from schemathesis.checks import not_a_server_error
    from schemathesis.core.failures import FailureGroup

    app, auth = fuzz_app
    schema = schemathesis.openapi.from_wsgi("/api/v1/openapi.json", app, headers=auth)
    checks = [not_a_server_error, *documented_answer_checks()]
    failures = []
    for result in schema.get_all_operations():
        operation = result.ok()
        if (operation.method.upper(), operation.path) in REVOKES_OWN_CREDENTIALS:
            continue

        @seed(13)
        @settings(max_examples=12, deadline=None, database=None, derandomize=True,
                  suppress_health_check=list(HealthCheck))
        @given(case=operation.as_strategy())
        def run(case) -> None:  # type: ignore[no-untyped-def]
            case.call_and_validate(headers=auth, checks=checks)

        try:
            run()
        except (Exception, FailureGroup) as exc:  # collect every operation's failure, then report them all
            failures.append(f"{operation.method.upper()} {operation.path}: {str(exc)[:400]}")
    assert not failures, "\n".join(failures)
