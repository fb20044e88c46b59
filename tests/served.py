"""The app under `serve`'s own server in this process, and raw HTTP/1.1 pieces to talk to it byte by byte."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from dataset.db import migrate, transaction
from dataset.services import users as user_service
from tests.conftest import make_settings
from webapp.cli.workspace import make_server
from webapp.runtime import Runtime


@contextmanager
def served_app(home: Path, threads: int) -> Iterator[tuple[int, dict[str, str]]]:
    """A fresh workspace at ``home`` served with ``threads`` workers on a free port of 127.0.0.1;
    yields (the port, a bearer token per role: annotator, curator)."""
    settings = make_settings(home)
    migrate(settings.database_url)
    rt = Runtime(settings)
    with transaction(rt.sessions) as s:
        tokens = {role: user_service.issue_token(s, user_service.create_user(s, role, role, "long-enough"))
                  for role in ("annotator", "curator")}
    server = make_server(settings, rt, "127.0.0.1", 0, threads=threads)
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    try:
        yield server.effective_port, tokens
    finally:
        server.close()
        thread.join(10)
        rt.close()


def head(method: str, path: str, headers: dict[str, str]) -> bytes:
    """A request's line and headers, up to the blank line."""
    lines = [f"{method} {path} HTTP/1.1", "Host: 127.0.0.1", *(f"{k}: {v}" for k, v in headers.items())]
    return ("\r\n".join(lines) + "\r\n\r\n").encode()


def chunk(data: bytes) -> bytes:
    """``data`` as one chunk of a chunked body."""
    return f"{len(data):x}\r\n".encode() + data + b"\r\n"
