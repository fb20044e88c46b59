"""Answers are JSON a strict parser reads (NaN and infinities as null), and a null byte in a URL is a
400 with its reason on every route, never a 500 from the file system; uploads are limited to
max_upload_mb exactly, by the app alone."""

from __future__ import annotations

import io
import json
import math
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from flask import Flask

from dataset.db import migrate, transaction
from dataset.services import training
from dataset.services import users as user_service
from dataset.tables import Evaluation, TrainingRun
from tests.conftest import make_settings
from webapp.app import create_app
from webapp.runtime import Runtime


def _strict(text: str) -> Any:
    def refuse(constant: str) -> None:
        raise ValueError(f"not JSON: {constant}")

    return json.loads(text, parse_constant=refuse)


def test_a_route_returning_nan_answers_null(app: Flask, tokens: dict[str, str]) -> None:
    from dataset.tables import Role
    from webapp.auth import requires

    @requires(Role.annotator)
    def nan_probe() -> dict[str, Any]:
        return {"nan": math.nan, "inf": [math.inf, -math.inf, 1.5], "nested": {"t": (math.nan, 2.0)}}

    app.add_url_rule("/api/v1/nan-probe", "nan_probe", nan_probe)
    response = app.test_client().get("/api/v1/nan-probe", headers={"Authorization": f"Bearer {tokens['annotator']}"})
    assert response.status_code == 200
    assert _strict(response.get_data(as_text=True)) == {"nan": None, "inf": [None, None, 1.5],
                                                        "nested": {"t": [None, 2.0]}}


def test_a_run_that_stored_nan_reads_back_as_json(client, runtime: Runtime, tokens: dict[str, str]) -> None:  # type: ignore[no-untyped-def]
    """SQLite keeps NaN inside a JSON column (`{"lr": "NaN"}` once reached a run's config); the answer stays JSON."""
    with transaction(runtime.sessions) as s:
        run = TrainingRun(preset="lite", config={"train": {"lr": math.nan, "steps": 10}}, launch={"data": {}})
        s.add(run)
        s.flush()
        run_id = run.id
    response = client.get(f"/api/v1/runs/{run_id}", headers={"Authorization": f"Bearer {tokens['curator']}"})
    assert response.status_code == 200
    assert _strict(response.get_data(as_text=True))["config"]["train"]["lr"] is None


@pytest.mark.parametrize("url", ["/api/v1/evaluations/{evaluation}/files/..%00/etc/passwd",
                                 "/models/runs/{run}/files/..%00/x", "/api/v1/evaluations/{evaluation}/files/a%00.png",
                                 "/api/v1/evaluations?x=%00"])
def test_a_null_byte_in_a_url_is_a_400_with_its_reason(client, runtime: Runtime, tokens: dict[str, str],  # type: ignore[no-untyped-def]
                                                       tmp_path: Path, url: str) -> None:
    report = tmp_path / "report"
    report.mkdir()
    (report / "report.json").write_text("{}")
    with transaction(runtime.sessions) as s:
        evaluation = Evaluation(dataset="test split", params={}, report_dir=str(report))
        run = TrainingRun(preset="lite", launch={"data": {}})
        s.add_all([evaluation, run])
        s.flush()
        ids = {"evaluation": evaluation.id, "run": run.id}
    (training.run_dir(runtime.settings.runs_dir, ids["run"]) / "val").mkdir(parents=True)
    response = client.get(url.format(**ids), headers={"Authorization": f"Bearer {tokens['admin']}"})
    assert response.status_code == 400, response.get_data(as_text=True)[:300]
    assert "null byte" in response.get_data(as_text=True)
    if url.startswith("/api/"):
        assert "null byte" in response.json["error"]


@pytest.fixture
def small_upload_server(tmp_path: Path) -> Iterator[tuple[str, str]]:
    """The app under `serve`'s server, on a workspace whose max_upload_mb is 1; (URL, curator token)."""
    from webapp.cli.workspace import make_server, server_url

    settings = make_settings(tmp_path / "ws", max_upload_mb=1)
    migrate(settings.database_url)
    rt = Runtime(settings)
    with transaction(rt.sessions) as s:
        token = user_service.issue_token(s, user_service.create_user(s, "c", "curator", "long-enough"))
    server = make_server(settings, rt, "127.0.0.1", 0, threads=2)
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    try:
        yield server_url(server).rstrip("/"), token
    finally:
        server.close()
        rt.close()


def _post_file(url: str, token: str, size: int) -> tuple[int, str, str]:
    boundary = "----probe"
    body = (f"--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"clip.avi\"\r\n"
            f"Content-Type: application/octet-stream\r\n\r\n").encode() + b"RIFF" + b"\0" * (size - 4) \
        + f"\r\n--{boundary}--\r\n".encode()
    # httpx reads the answer when the server hangs up on a body it refused unread (urllib would report the reset)
    response = httpx.post(f"{url}/api/v1/videos", content=body, timeout=30, headers={
        "Authorization": f"Bearer {token}", "Content-Type": f"multipart/form-data; boundary={boundary}"})
    return response.status_code, response.headers.get("Content-Type", ""), response.text


def test_upload_limits_follow_max_upload_mb(small_upload_server: tuple[str, str]) -> None:
    url, token = small_upload_server
    # a file of exactly max_upload_mb passes the size limits (and is then judged as a video)
    status, _, text = _post_file(url, token, 1 << 20)
    assert status != 413, text
    # one byte more is refused: the limit is on the file, not on the request around it
    status, content_type, text = _post_file(url, token, (1 << 20) + 1)
    assert status == 413 and content_type.startswith("application/json"), (status, content_type, text)
    assert "at most 1 MiB" in json.loads(text)["error"]
    # a body far over it is refused from its Content-Length, in the app's JSON
    status, content_type, text = _post_file(url, token, (1 << 20) + (2 << 20))
    assert status == 413 and content_type.startswith("application/json"), (status, content_type, text)
    assert "error" in json.loads(text)


def test_the_server_leaves_body_limits_to_the_app(tmp_path: Path) -> None:
    """waitress's own limit (1 GiB by default) sat below the default max_upload_mb (2048); the
    server now has none, and the upload route's is the app's."""
    from webapp.bodies import UPLOAD_ENDPOINT, body_limit, upload_body_limit
    from webapp.cli.workspace import make_server

    settings = make_settings(tmp_path / "ws")
    migrate(settings.database_url)
    assert settings.max_upload_mb == 2048
    rt = Runtime(settings)
    server = make_server(settings, rt, "127.0.0.1", 0, threads=1)
    try:
        assert server.max_request_body_size == 0
        app = create_app(settings, rt)
        assert body_limit(app, UPLOAD_ENDPOINT, settings) == upload_body_limit(settings) > 2048 * (1 << 20)
    finally:
        server.close()
        rt.close()


def test_upload_of_the_full_size_passes_the_apps_limit(tmp_path: Path) -> None:
    settings = make_settings(tmp_path / "ws", max_upload_mb=1)
    migrate(settings.database_url)
    app = create_app(settings)
    with transaction(app.extensions["runtime"].sessions) as s:
        token = user_service.issue_token(s, user_service.create_user(s, "c", "curator", "long-enough"))
    response = app.test_client().post("/api/v1/videos", headers={"Authorization": f"Bearer {token}"},
                                      data={"file": (io.BytesIO(b"RIFF" + b"\0" * ((1 << 20) - 4)), "full.avi")})
    assert response.status_code != 413, response.json
