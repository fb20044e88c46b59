"""Playwright driving the system's Chromium (Debian package `chromium`), shared by browser tests."""

from __future__ import annotations

import atexit
import functools
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
# Without the background-networking flags Chromium keeps dialling out on a closed network.
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
                 "--disable-sync", "--no-first-run"]
ROOT = Path(__file__).resolve().parent.parent


def require_chromium() -> None:
    if not Path(CHROMIUM).exists():
        if os.environ.get("ILLUSION_TEST_REQUIRE_BROWSER"):
            pytest.fail("Chromium is required here (ILLUSION_TEST_REQUIRE_BROWSER) but not installed")
        pytest.skip("browser tests need the system's Chromium: apt-get install chromium")


# One Chromium per test module, not per session: with ``--dist loadfile`` a worker goes on to other modules,
# and Playwright's sync API (an asyncio loop run under greenlets) should not stay alive under their threads.
@pytest.fixture(scope="module")
def browser():  # type: ignore[no-untyped-def]
    require_chromium()
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        instance = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        yield instance
        instance.close()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def stop(proc: subprocess.Popen[str] | subprocess.Popen[bytes]) -> None:
    """Terminate a server process, killing it if it has not gone in 30 s."""
    proc.terminate()
    try:
        proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()


@functools.cache
def _demo_videos(videos: int) -> Path:
    """The demo's synthetic videos, rendered once per test process as `demo` renders them (seed 0, with
    its spoilt frames): rendering is half of a demo's start, and the files are the same each time."""
    from dataset.synthetic import write_synthetic_dataset

    root = Path(tempfile.mkdtemp(prefix="demo-videos-"))
    atexit.register(shutil.rmtree, root, True)
    write_synthetic_dataset(root / "synthetic", videos=videos, seed=0, defects=True)
    return root / "synthetic"


@contextmanager
def running_demo(home: Path, videos: int = 1) -> Iterator[str]:
    """`illusion-studio demo` in a subprocess (worker + server), as `make demo` runs it; yields its URL.
    A new ``home`` gets the demo's mark and its rendered videos first; the demo does the rest."""
    from webapp.cli.demo import DEMO_MARKER

    if not (home / DEMO_MARKER).is_file():
        assert not home.exists() or not any(home.iterdir()), f"{home} is not a new workspace"
        home.mkdir(parents=True, exist_ok=True)
        (home / DEMO_MARKER).write_text("Made for a test, as `illusion-studio demo` makes it.\n", encoding="utf-8")
    if not (home / "synthetic").exists():
        shutil.copytree(_demo_videos(videos), home / "synthetic")
    port = free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("ILLUSION_STUDIO_")}
    proc = subprocess.Popen([sys.executable, "-m", "webapp.cli", "--data-dir", str(home), "demo", "--port", str(port),
                             "--videos", str(videos)], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 180
        while True:
            if proc.poll() is not None:
                raise AssertionError(f"demo exited early:\n{proc.stdout.read()}")
            try:
                with urllib.request.urlopen(f"{url}/healthz", timeout=2) as response:
                    if response.status == 200:
                        break
            except OSError:
                pass
            if time.monotonic() > deadline:
                raise AssertionError("demo server did not come up in 180 s")
            time.sleep(0.3)
        yield url
    finally:
        stop(proc)


@contextmanager
def serving(home: Path, timeout_s: float = 60, *, train_worker: bool = False) -> Iterator[str]:
    """`illusion-studio serve` of the workspace ``home`` in a subprocess (and a `worker --queue train`
    beside it when ``train_worker``); yields its URL once it answers."""
    port = free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("ILLUSION_STUDIO_")}
    cli = [sys.executable, "-m", "webapp.cli", "--data-dir", str(home)]
    commands = [[*cli, "serve", "--port", str(port)], *([[*cli, "worker", "--queue", "train"]] if train_worker else [])]
    procs = [subprocess.Popen(command, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
             for command in commands]
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                with urllib.request.urlopen(f"{url}/healthz", timeout=2):
                    break
            except OSError:
                assert procs[0].poll() is None and time.monotonic() < deadline, "server did not come up"
                time.sleep(0.3)
        yield url
    finally:
        for proc in procs:
            stop(proc)


def login(page, url: str, name: str, password: str) -> None:  # type: ignore[no-untyped-def]
    """Log in through the login form, as a person does, and land on the dashboard."""
    page.goto(url + "/login")
    page.fill("input[name=name]", name)
    page.fill("input[name=password]", password)
    page.click("button[type=submit]")
    page.wait_for_url(url + "/")


def page_with_errors(browser):  # type: ignore[no-untyped-def]
    """A 1366×768 page and the list its JavaScript errors and console errors are collected in."""
    page = browser.new_page(viewport={"width": 1366, "height": 768})
    return page, collect_errors(page)


def collect_errors(page) -> list[str]:  # type: ignore[no-untyped-def]
    """The list ``page``'s uncaught script errors and console errors are appended to."""
    errors: list[str] = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    return errors
