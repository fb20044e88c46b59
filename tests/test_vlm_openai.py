"""The openai backend against the local OpenAI-compatible server, faults included."""

from __future__ import annotations

import time

import cv2
import httpx
import numpy as np
import pytest

from annotation.vlm import PROMPT, make_backend
from annotation.vlm.backends.openai_compat import OpenAICompatBackend
from benchmarks.prefilter import run_prefilter_bench
from benchmarks.vlm_server import ChatRequest, LocalVLMServer, Reply, ScriptedResponder, fixed_responder
from dataset.synthetic import render_video

KEEP = "no,yes,no,no,no,no,no,no,no,no,no,no"


@pytest.fixture(scope="module")
def frames() -> dict[str, np.ndarray]:
    sharp = render_video(0, n_frames=2, width=320, height=180).frames[0].left
    captioned = sharp.copy()
    cv2.rectangle(captioned, (0, 140), (320, 180), (0, 0, 0), -1)
    cv2.putText(captioned, "SUBTITLE TEXT HERE", (16, 167), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (255, 255, 255), 2)
    return {"sharp": sharp, "blurred": cv2.GaussianBlur(sharp, (0, 0), 3), "captioned": captioned}


def backend(server: LocalVLMServer, **options) -> OpenAICompatBackend:
    """A client with short waits, for fault tests."""
    defaults = {"concurrency": 4, "timeout_s": 5.0, "max_retries": 3, "backoff_s": 0.01}
    return OpenAICompatBackend(server.base_url, "local-qwen", **{**defaults, **options})


def test_answers_follow_the_image_and_the_request_is_what_servers_expect(frames) -> None:
    with LocalVLMServer() as server:
        client = make_backend("openai", base_url=server.base_url, model="Qwen2-VL-72B-Instruct", api_key="s3cret")
        try:
            verdicts = client.classify([frames["sharp"], frames["blurred"], frames["captioned"]])
        finally:
            client.close()
        request = server.last_request
    assert [v.keep for v in verdicts] == [True, False, False]
    assert all(v.parsed and v.error is None for v in verdicts)
    assert "Q9" in verdicts[1].reason and "Q7" in verdicts[2].reason
    assert verdicts[0].metrics["attempts"] == 1 and verdicts[0].metrics["latency_s"] > 0
    assert client.model_id == "Qwen2-VL-72B-Instruct" and client.name == "openai"
    assert request is not None
    assert request.headers["authorization"] == "Bearer s3cret"
    assert request.payload["model"] == "Qwen2-VL-72B-Instruct"
    assert request.payload["temperature"] == 0
    assert request.image_url.startswith("data:image/jpeg;base64,")
    assert request.text == PROMPT
    assert request.image().shape == (180, 320, 3)


def test_no_api_key_sends_no_authorization(frames) -> None:
    with LocalVLMServer(fixed_responder(KEEP)) as server, backend(server) as client:
        client.classify([frames["sharp"]])
        assert server.last_request is not None and "authorization" not in server.last_request.headers


def test_concurrent_answers_come_back_in_input_order() -> None:
    def by_brightness(request: ChatRequest) -> Reply:
        return Reply(KEEP if request.image().mean() > 127 else "no," * 11 + "no")

    images = [np.full((24, 32, 3), 230 if i % 3 == 0 else 20, np.uint8) for i in range(30)]
    with LocalVLMServer(by_brightness) as server, backend(server, concurrency=8) as client:
        verdicts = client.classify(images)
    assert [v.keep for v in verdicts] == [i % 3 == 0 for i in range(30)]


def test_server_errors_and_rate_limits_are_retried(frames) -> None:
    script = [Reply(status=500), Reply(status=429, retry_after_s=0), Reply(status=503)]
    with LocalVLMServer(ScriptedResponder(script, then=fixed_responder(KEEP))) as server, backend(server) as client:
        [verdict] = client.classify([frames["sharp"]])
        assert server.request_count == 4
    assert verdict.keep is True and verdict.metrics["attempts"] == 4


def test_persistent_server_errors_give_a_stored_error(frames) -> None:
    with LocalVLMServer(ScriptedResponder([Reply(status=502)] * 3)) as server:
        with backend(server, max_retries=2) as client:
            [verdict] = client.classify([frames["sharp"]])
        assert server.request_count == 3
    assert not verdict.parsed and verdict.keep is None and verdict.answers is None
    assert verdict.error is not None and verdict.error.startswith("HTTP 502")
    assert verdict.error.endswith("(gave up after 3 attempts)")


@pytest.mark.parametrize("status", [400, 401, 404])
def test_client_errors_are_not_retried(frames, status: int) -> None:
    with LocalVLMServer(ScriptedResponder([Reply("go away", status=status)])) as server, backend(server) as client:
        [verdict] = client.classify([frames["sharp"]])
        assert server.request_count == 1
    assert verdict.error is not None and verdict.error.startswith(f"HTTP {status}") and "go away" in verdict.error


def test_a_slow_answer_times_out_and_is_retried(frames) -> None:
    script = [Reply(KEEP, delay_s=1.0)]
    started = time.perf_counter()
    with (LocalVLMServer(ScriptedResponder(script, then=fixed_responder(KEEP))) as server,
          backend(server, timeout_s=0.2) as client):
        [verdict] = client.classify([frames["sharp"]])
    assert verdict.keep is True and verdict.metrics["attempts"] == 2
    assert time.perf_counter() - started < 1.0


def test_timeouts_every_time_give_a_stored_error(frames) -> None:
    with (LocalVLMServer(ScriptedResponder([Reply(KEEP, delay_s=0.5)] * 2)) as server,
          backend(server, timeout_s=0.1, max_retries=1) as client):
        [verdict] = client.classify([frames["sharp"]])
    assert verdict.error is not None and verdict.error.startswith("timeout") and verdict.keep is None


@pytest.mark.parametrize(
    ("reply", "reason"),
    [
        (Reply("I see a room with a mirror."), "no yes/no answer found"),
        (Reply("yes,no,no"), "expected 12 answers, found 3"),
        (Reply(""), "empty answer"),
    ],
)
def test_unreadable_answers_are_unparsed_not_errors(frames, reply: Reply, reason: str) -> None:
    with LocalVLMServer(ScriptedResponder([reply])) as server, backend(server) as client:
        [verdict] = client.classify([frames["sharp"]])
    assert not verdict.parsed and verdict.keep is None and verdict.error is None
    assert verdict.reason == reason and verdict.raw == reply.content


@pytest.mark.parametrize(
    "body", [b"<html>oops</html>", b'{"choices": []}', b'{"choices": [{"message": {"content": 7}}]}']
)
def test_malformed_bodies_give_a_stored_error(frames, body: bytes) -> None:
    with LocalVLMServer(ScriptedResponder([Reply(body=body)])) as server, backend(server) as client:
        [verdict] = client.classify([frames["sharp"]])
        assert server.request_count == 1
    assert verdict.error is not None and verdict.error.startswith("malformed response")
    assert verdict.raw == body.decode() and not verdict.parsed


def test_unreachable_server_gives_a_stored_error(frames) -> None:
    with LocalVLMServer() as server:
        url = server.base_url
    with OpenAICompatBackend(url, "m", max_retries=1, backoff_s=0.01, timeout_s=2.0) as client:
        verdicts = client.classify([frames["sharp"], frames["blurred"]])
    assert all(v.error is not None and v.error.startswith("connection error") for v in verdicts)


def test_a_bad_image_fails_alone(frames) -> None:
    with LocalVLMServer(fixed_responder(KEEP)) as server, backend(server) as client:
        verdicts = client.classify([frames["sharp"], np.zeros((8, 8, 3), np.float64), frames["blurred"]])
        assert server.request_count == 2
    assert [v.keep for v in verdicts] == [True, None, True]
    assert verdicts[1].error is not None and "invalid image" in verdicts[1].error


def test_local_server_rejects_what_real_servers_reject() -> None:
    with LocalVLMServer() as server:
        no_image = {"model": "m", "messages": [{"role": "user", "content": "hello"}]}
        assert httpx.post(server.base_url + "/chat/completions", json=no_image).status_code == 400
        assert httpx.post(server.base_url + "/chat/completions", content=b"{").status_code == 400
        assert httpx.post(server.base_url + "/embeddings", json=no_image).status_code == 404
        assert server.request_count == 0


def test_benchmark_reports_its_figures() -> None:
    result = run_prefilter_bench(frames=24, concurrency=4)
    assert set(result) == {"openai_client_fps", "frames", "concurrency", "reference_sequential_fps"}
    assert result["frames"] == 24 and result["concurrency"] == 4
    assert result["openai_client_fps"] > 0 and result["reference_sequential_fps"] > 0
