"""The app and its workers in processes of their own, as in production, for the benchmarks that
talk HTTP: ``illusion-studio serve`` on a free 127.0.0.1 port and ``illusion-studio worker``."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import httpx

HOST = "127.0.0.1"


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on right now."""
    with socket.socket() as s:
        s.bind((HOST, 0))
        return s.getsockname()[1]


def wait_until_up(client: httpx.Client, server: subprocess.Popen[bytes]) -> None:
    """Return once the server behind ``client`` answers its health check (60 s at most)."""
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if server.poll() is not None:
            raise RuntimeError("the benchmark server exited early")
        try:
            if client.get("/healthz").status_code == 200:
                return
        except httpx.TransportError:
            pass
        time.sleep(0.1)
    raise RuntimeError("the benchmark server did not come up in 60 s")


@contextmanager
def served_app(home: Path, threads: int = 8) -> Iterator[str]:
    """Serve the workspace ``home`` until the block ends; yields the base URL once it answers."""
    port = free_port()
    server = subprocess.Popen([sys.executable, "-m", "webapp.cli", "--data-dir", str(home), "serve", "--host", HOST,
                               "--port", str(port), "--threads", str(threads)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    base_url = f"http://{HOST}:{port}"
    try:
        with httpx.Client(base_url=base_url, timeout=10) as client:
            wait_until_up(client, server)
        yield base_url
    finally:
        stop(server)


def start_worker(home: Path, *args: str) -> subprocess.Popen[str]:
    """Start ``illusion-studio worker [ARGS…]`` on ``home``; returns once it listens for jobs."""
    proc = subprocess.Popen([sys.executable, "-m", "webapp.cli", "--data-dir", str(home), "worker", *args],
                            env={**os.environ, "PYTHONUNBUFFERED": "1"}, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    ready = threading.Event()

    def drain() -> None:  # keep reading, or a chatty worker would block on a full pipe
        for line in proc.stderr or ():
            if " ready" in line:
                ready.set()

    threading.Thread(target=drain, daemon=True).start()
    if not ready.wait(60):
        stop(proc)
        raise RuntimeError("the worker did not get ready within 60 s")
    return proc


def stop(proc: subprocess.Popen[str] | subprocess.Popen[bytes]) -> None:
    """Terminate ``proc`` and wait for it; kill it if it does not stop within 20 s."""
    if proc.poll() is None:
        proc.terminate()
    try:
        proc.wait(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
