"""Any OpenAI-compatible chat-completions server (vLLM, SGLang, Ollama, … serving Qwen2-VL).

One request per frame: the JPEG frame as a data URL plus the prompt, temperature 0. Requests
run on a bounded thread pool sharing one keep-alive connection pool (httpx). Connection
errors, timeouts, 429 and 5xx are retried with exponential backoff and jitter (a numeric
Retry-After is honoured); other 4xx and unreadable bodies are not retried. Every failure
becomes a Verdict with ``error`` set, never an exception.
"""

from __future__ import annotations

import logging
import random
import time
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import httpx
import numpy as np

from annotation.vlm.backends.base import AskError
from annotation.vlm.dataurl import image_to_data_url
from annotation.vlm.prompt import ANSWER_TOKEN_BUDGET, PROMPT, PROMPT_VERSION
from annotation.vlm.rule import KeepRule
from annotation.vlm.verdict import Verdict, image_problem

logger = logging.getLogger(__name__)

_MAX_DELAY_S = 30.0  # cap on one backoff wait, Retry-After included
_SNIPPET = 300  # characters of an error body kept in a Verdict


@dataclass(frozen=True)
class _Outcome:
    content: str | None  # the assistant's reply, None on failure
    error: str | None
    attempts: int
    raw: str = ""


class OpenAICompatBackend:
    """Prefilter through ``POST {base_url}/chat/completions``."""

    name = "openai"
    prompt_version = PROMPT_VERSION

    def __init__(
        self,
        base_url: str,
        model: str,
        *,
        api_key: str = "",
        concurrency: int = 8,
        timeout_s: float = 60.0,
        max_retries: int = 3,
        backoff_s: float = 0.5,
        jpeg_quality: int = 90,
        rule: KeepRule | None = None,
    ) -> None:
        """``base_url`` like ``http://host:8000/v1``; ``backoff_s`` is the first retry's wait (doubling)."""
        if not base_url.startswith(("http://", "https://")):
            raise ValueError(f"openai backend needs an http(s) base URL like http://host:8000/v1, got {base_url!r}")
        if not model:
            raise ValueError("openai backend needs a model name (e.g. Qwen2-VL-72B-Instruct)")
        if concurrency < 1 or max_retries < 0 or timeout_s <= 0:
            raise ValueError("openai backend needs concurrency ≥ 1, max_retries ≥ 0 and timeout_s > 0")
        self.model_id = model
        self._url = base_url.rstrip("/") + "/chat/completions"
        self._max_retries = max_retries
        self._backoff_s = backoff_s
        self._jpeg_quality = jpeg_quality
        self._rule = rule or KeepRule()
        headers = {"Authorization": f"Bearer {api_key}"} if api_key else {}
        self._client = httpx.Client(
            headers=headers,
            timeout=timeout_s,
            limits=httpx.Limits(max_connections=concurrency, max_keepalive_connections=concurrency),
        )
        self._pool = ThreadPoolExecutor(max_workers=concurrency, thread_name_prefix="vlm-openai")

    def classify(self, images: Sequence[np.ndarray]) -> list[Verdict]:
        """One Verdict per RGB uint8 HxWx3 image, ``concurrency`` requests in flight at most."""
        return list(self._pool.map(self._classify_one, images))

    def ask(self, image: np.ndarray, prompt: str, max_tokens: int = 512) -> str:
        """The reply to a free ``prompt`` about ``image`` (same retries as ``classify``); AskError without one."""
        problem = image_problem(image)
        if problem:
            raise AskError(problem)
        outcome = self._ask(image, prompt, max_tokens)
        if outcome.content is None:
            raise AskError(outcome.error or "no answer")
        return outcome.content

    def close(self) -> None:
        """Stop the worker threads and close the connections."""
        self._pool.shutdown(wait=True)
        self._client.close()

    def __enter__(self) -> OpenAICompatBackend:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def _classify_one(self, image: np.ndarray) -> Verdict:
        problem = image_problem(image)
        if problem:
            return Verdict.failed(problem)
        started = time.perf_counter()
        try:
            outcome = self._ask(image, PROMPT, ANSWER_TOKEN_BUDGET)
        except Exception as exc:  # a bug here must cost one frame, not the batch
            logger.exception("prefilter request failed unexpectedly")
            outcome = _Outcome(None, f"unexpected {type(exc).__name__}: {exc}", 0)
        metrics = {"latency_s": time.perf_counter() - started, "attempts": float(outcome.attempts)}
        if outcome.content is None:
            return Verdict.failed(outcome.error or "no answer", raw=outcome.raw, metrics=metrics)
        return Verdict.from_text(outcome.content, self._rule, metrics=metrics)

    def _ask(self, image: np.ndarray, prompt: str, max_tokens: int) -> _Outcome:
        payload = {
            "model": self.model_id,
            "messages": [
                {
                    "role": "user",
                    "content": [
                        {"type": "image_url", "image_url": {"url": image_to_data_url(image, self._jpeg_quality)}},
                        {"type": "text", "text": prompt},
                    ],
                }
            ],
            "temperature": 0,
            "max_tokens": max_tokens,
        }
        problem, retry_after = "", None
        attempts = self._max_retries + 1
        for attempt in range(attempts):
            if attempt:
                time.sleep(self._delay(attempt, retry_after))
            try:
                response = self._client.post(self._url, json=payload)
            except httpx.TimeoutException as exc:
                problem, retry_after = f"timeout ({type(exc).__name__})", None
                continue
            except httpx.TransportError as exc:
                problem, retry_after = f"connection error ({type(exc).__name__}: {exc})", None
                continue
            if response.status_code == 429 or response.status_code >= 500:
                problem = f"HTTP {response.status_code}: {response.text[:_SNIPPET]}"
                retry_after = _seconds(response.headers.get("Retry-After"))
                logger.warning("prefilter server said %s (attempt %d of %d)", problem, attempt + 1, attempts)
                continue
            if not response.is_success:
                return _Outcome(None, f"HTTP {response.status_code}: {response.text[:_SNIPPET]}", attempt + 1)
            return _reply_text(response, attempt + 1)
        return _Outcome(None, f"{problem} (gave up after {attempts} attempts)", attempts)

    def _delay(self, attempt: int, retry_after: float | None) -> float:
        """Exponential backoff with jitter so that many clients do not retry in lockstep."""
        delay = self._backoff_s * 2 ** (attempt - 1) + random.uniform(0, self._backoff_s)
        return min(_MAX_DELAY_S, max(delay, retry_after or 0.0))


def _reply_text(response: httpx.Response, attempts: int) -> _Outcome:
    """The assistant message of a chat-completions body (string or list of text parts)."""
    try:
        content = response.json()["choices"][0]["message"]["content"]
        if isinstance(content, list):
            content = "".join(part.get("text", "") for part in content if isinstance(part, dict))
        if content is not None and not isinstance(content, str):
            raise TypeError(f"content is {type(content).__name__}")
    except (ValueError, KeyError, IndexError, TypeError) as exc:
        detail = f"{type(exc).__name__}: {exc}"
        return _Outcome(None, f"malformed response ({detail})", attempts, raw=response.text[:_SNIPPET])
    return _Outcome(content or "", None, attempts)


def _seconds(value: str | None) -> float | None:
    """A Retry-After header given in seconds (the HTTP-date form is ignored)."""
    try:
        return float(value) if value is not None else None
    except ValueError:
        return None
