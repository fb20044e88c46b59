"""A small OpenAI-compatible ``/v1/chat/completions`` server on 127.0.0.1, for tests and benchmarks.

It checks that requests look like what real servers (vLLM, SGLang, Ollama) accept — a user
message with an image data URL and the prompt — and answers through a *responder*:
``statistics_responder`` (the default) answers deterministically from the image,
``fixed_responder`` answers at once without decoding anything (benchmarks), and
``ScriptedResponder`` plays a queue of replies and faults (500, 429, slow, garbage) first.

    with LocalVLMServer() as server:
        backend = make_backend("openai", base_url=server.base_url, model="local")
"""

from __future__ import annotations

import json
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any

import numpy as np

from annotation.vlm.backends.heuristic import heuristic_answers
from annotation.vlm.dataurl import data_url_to_image
from annotation.vlm.measure import measure_frame
from annotation.vlm.parse import format_answers


@dataclass(frozen=True)
class ChatRequest:
    """A received chat-completions request: its JSON payload, headers (lower-case names), image and text."""

    payload: dict[str, Any]
    headers: dict[str, str]
    image_url: str
    text: str

    @classmethod
    def from_body(cls, body: bytes, headers: dict[str, str]) -> ChatRequest:
        """Validate a request body; ValueError says what a real server would reject."""
        try:
            payload = json.loads(body)
        except ValueError as exc:
            raise ValueError(f"body is not JSON: {exc}") from None
        if not isinstance(payload, dict) or not isinstance(payload.get("model"), str) or not payload["model"]:
            raise ValueError("'model' must be a non-empty string")
        messages = payload.get("messages")
        if not isinstance(messages, list) or not messages:
            raise ValueError("'messages' must be a non-empty list")
        image_urls: list[str] = []
        texts: list[str] = []
        for message in messages:
            content = message.get("content") if isinstance(message, dict) else None
            for part in content if isinstance(content, list) else [{"type": "text", "text": content}]:
                if not isinstance(part, dict):
                    raise ValueError("content parts must be objects")
                if part.get("type") == "image_url":
                    image_url = part.get("image_url")
                    image_urls.append(str(image_url.get("url", "")) if isinstance(image_url, dict) else "")
                elif part.get("type") == "text" and isinstance(part.get("text"), str):
                    texts.append(part["text"])
        if len(image_urls) != 1 or not image_urls[0].startswith("data:image/"):
            raise ValueError("expected exactly one image_url part holding a data:image/… URL")
        return cls(payload, headers, image_urls[0], "\n".join(texts))

    def image(self) -> np.ndarray:
        """The decoded image, RGB uint8 HxWx3."""
        return data_url_to_image(self.image_url)


@dataclass(frozen=True)
class Reply:
    """What the server sends back: the assistant's ``content`` with ``status`` 200, an error status,
    or a raw ``body`` (malformed responses); after waiting ``delay_s``."""

    content: str = ""
    status: int = 200
    delay_s: float = 0.0
    body: bytes | None = None
    retry_after_s: float | None = None


Responder = Callable[[ChatRequest], Reply]


def statistics_responder(request: ChatRequest) -> Reply:
    """A deterministic stand-in VLM: the heuristic's measured answers (unknown → 'no'), and 'yes' to
    Q4 (the synthetic rooms hold a mirror). Sharp clean frames are kept; blurred or captioned ones are not."""
    try:
        answers = [bool(a) for a in heuristic_answers(measure_frame(request.image()))]
    except ValueError as exc:
        return Reply(content=str(exc), status=400)
    answers[4 - 1] = True
    return Reply(format_answers(answers))


def fixed_responder(content: str) -> Responder:
    """Answer ``content`` at once to every request, without decoding the image."""
    reply = Reply(content)
    return lambda request: reply


class ScriptedResponder:
    """Play ``replies`` in order, one per request, then defer to ``then``."""

    def __init__(self, replies: Iterable[Reply], then: Responder = statistics_responder) -> None:
        self._queue = deque(replies)
        self._then = then
        self._lock = threading.Lock()

    def __call__(self, request: ChatRequest) -> Reply:
        with self._lock:
            scripted = self._queue.popleft() if self._queue else None
        return scripted if scripted is not None else self._then(request)


class LocalVLMServer:
    """Threaded server on 127.0.0.1 and a free port; a context manager that starts and stops it."""

    def __init__(self, responder: Responder = statistics_responder) -> None:
        self.responder = responder
        self.request_count = 0
        self.last_request: ChatRequest | None = None
        self._lock = threading.Lock()
        self._server: _Server | None = None
        self._thread: threading.Thread | None = None

    @property
    def base_url(self) -> str:
        """``http://127.0.0.1:<port>/v1``, what the openai backend takes as ``base_url``."""
        if self._server is None:
            raise RuntimeError("the server is not running")
        return f"http://127.0.0.1:{self._server.server_address[1]}/v1"

    def __enter__(self) -> LocalVLMServer:
        self._server = _Server(self)
        # A short poll interval: stopping waits for the loop's next poll.
        self._thread = threading.Thread(
            target=self._server.serve_forever, kwargs={"poll_interval": 0.02}, name="local-vlm", daemon=True
        )
        self._thread.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        if self._server is not None and self._thread is not None:
            self._server.shutdown()
            self._server.server_close()
            self._thread.join()
        self._server = self._thread = None

    def _record(self, request: ChatRequest) -> int:
        """Count a request; returns its number (1, 2, …)."""
        with self._lock:
            self.request_count += 1
            self.last_request = request
            return self.request_count


class _Server(ThreadingHTTPServer):
    daemon_threads = True
    request_queue_size = 128  # benchmarks open many connections at once

    def __init__(self, owner: LocalVLMServer) -> None:
        super().__init__(("127.0.0.1", 0), _Handler)
        self.owner = owner


class _Handler(BaseHTTPRequestHandler):
    server: _Server
    protocol_version = "HTTP/1.1"  # keep-alive, as real servers do
    # Headers and body go out in two writes; with Nagle's algorithm the second waits for the
    # client's delayed ACK (~40 ms), which would cap a sequential client at ~25 requests/s.
    disable_nagle_algorithm = True

    def do_POST(self) -> None:
        body = self.rfile.read(int(self.headers.get("Content-Length") or 0))
        if self.path.rstrip("/") != "/v1/chat/completions":
            self._send_json(HTTPStatus.NOT_FOUND, _error(f"no route {self.path}"))
            return
        headers = {name.lower(): value for name, value in self.headers.items()}
        try:
            request = ChatRequest.from_body(body, headers)
        except ValueError as exc:
            self._send_json(HTTPStatus.BAD_REQUEST, _error(str(exc)))
            return
        owner = self.server.owner
        number = owner._record(request)
        reply = owner.responder(request)
        if reply.delay_s:
            time.sleep(reply.delay_s)
        extra = {"Retry-After": f"{reply.retry_after_s:g}"} if reply.retry_after_s is not None else {}
        if reply.body is not None:
            self._send(reply.status, reply.body, "application/json", extra)
        elif reply.status != HTTPStatus.OK:
            self._send_json(reply.status, _error(reply.content or HTTPStatus(reply.status).phrase), extra)
        else:
            self._send_json(HTTPStatus.OK, _completion(request.payload["model"], reply.content, number))

    def log_message(self, format: str, *args: object) -> None:
        """Silent: tests and benchmarks send thousands of requests."""

    def _send_json(self, status: int, payload: dict[str, Any], headers: dict[str, str] | None = None) -> None:
        self._send(status, json.dumps(payload).encode(), "application/json", headers or {})

    def _send(self, status: int, body: bytes, content_type: str, headers: dict[str, str]) -> None:
        try:
            self.send_response(status)
            self.send_header("Content-Type", content_type)
            self.send_header("Content-Length", str(len(body)))
            for name, value in headers.items():
                self.send_header(name, value)
            self.end_headers()
            self.wfile.write(body)
        except ConnectionError:
            pass  # the client gave up (its timeout); nothing to tell it


def _completion(model: str, content: str, number: int) -> dict[str, Any]:
    return {
        "id": f"chatcmpl-local-{number}",
        "object": "chat.completion",
        "created": int(time.time()),
        "model": model,
        "choices": [{"index": 0, "message": {"role": "assistant", "content": content}, "finish_reason": "stop"}],
    }


def _error(message: str) -> dict[str, Any]:
    return {"error": {"message": message, "type": "invalid_request_error"}}
