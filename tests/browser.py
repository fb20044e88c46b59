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


# Where the once-per-run demo templates go: set by `_demo_templates_home` below for each test process.
_tmp_path_factory: pytest.TempPathFactory | None = None


@pytest.fixture(scope="session", autouse=True)
def _demo_templates_home(tmp_path_factory: pytest.TempPathFactory) -> None:
    global _tmp_path_factory
    _tmp_path_factory = tmp_path_factory


def _templates_root() -> Path:
    """A folder shared by this run's test processes: under xdist, the parent of the workers' base temps
    (one per run, removed with pytest's old temp dirs); otherwise this process's own base temp."""
    if _tmp_path_factory is None:  # used outside pytest: a folder of this process's own
        root = Path(tempfile.mkdtemp(prefix="demo-templates-"))
        atexit.register(shutil.rmtree, root, True)
        return root
    base = _tmp_path_factory.getbasetemp()
    return base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base


@functools.cache
def demo_template(videos: int) -> Path:
    """A demo workspace as `illusion-studio demo --no-serve` leaves it (built by that command, once per test
    run, under a file lock the xdist workers share): a workspace to copy, never to serve or change.
    Only for demos too small for a training run (one video), where `--no-serve` stops where `demo` starts
    its server, so a copy is what each test's demo would have prepared itself."""
    from filelock import FileLock

    assert videos == 1, "a demo of several videos trains its run under --no-serve: not a template to copy"
    root = _templates_root()
    template = root / f"demo-template-{videos}"
    done = template / ".template-built"
    with FileLock(str(root / f"demo-template-{videos}.lock")):
        if not done.is_file():
            shutil.rmtree(template, ignore_errors=True)
            env = {k: v for k, v in os.environ.items() if not k.startswith("ILLUSION_STUDIO_")}
            result = subprocess.run([sys.executable, "-m", "webapp.cli", "--data-dir", str(template), "demo",
                                     "--no-serve", "--videos", str(videos)], cwd=ROOT, env=env,
                                    stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=600)
            assert result.returncode == 0, f"the demo template did not build:\n{result.stdout}"
            done.write_text("", encoding="utf-8")
    return template


def copy_demo_workspace(template: Path, home: Path) -> None:
    """Copy the demo ``template`` to the new ``home`` and point what its database holds of the template's
    absolute paths (the ingested videos' ``original_path`` and their ingest jobs' ``path``) at ``home``:
    else the demo would take the copy's videos for new ones and ingest them again."""
    from sqlalchemy import select

    from dataset.db import make_engine, make_session_factory, transaction
    from dataset.settings import load_settings
    from dataset.tables import Job, Video

    shutil.copytree(template, home, ignore=shutil.ignore_patterns(".template-built"))

    def moved(path: str) -> str:
        return str(home / Path(path).relative_to(template)) if Path(path).is_relative_to(template) else path

    # The demo runs without the ILLUSION_STUDIO_* variables, so on the workspace's own SQLite database.
    engine = make_engine(load_settings(home, database_url="").database_url)
    try:
        with transaction(make_session_factory(engine)) as s:
            for video in s.scalars(select(Video)):
                video.original_path = moved(video.original_path)
            for job in s.scalars(select(Job)):
                if isinstance(job.params.get("path"), str):
                    job.params = {**job.params, "path": moved(job.params["path"])}
        with make_session_factory(engine)() as s:
            left = [p for p in [*s.scalars(select(Video.original_path)),
                                *(job.params.get("path") for job in s.scalars(select(Job)))]
                    if isinstance(p, str) and str(template) in p]
        assert not left, f"the copy of {template} still points into it: {left}"
    finally:
        engine.dispose()


@contextmanager
def running_demo(home: Path, videos: int = 1) -> Iterator[str]:
    """`illusion-studio demo` in a subprocess (worker + server), as `make demo` runs it; yields its URL.
    A new ``home`` of a one-video demo starts as a copy of the run's demo template (what the demo
    prepares before it serves); the demo finds it prepared and serves it."""
    from webapp.cli.demo import DEMO_MARKER

    if not (home / DEMO_MARKER).is_file():
        assert not home.exists() or not any(home.iterdir()), f"{home} is not a new workspace"
        if videos == 1:
            if home.exists():
                home.rmdir()
            copy_demo_workspace(demo_template(videos), home)
        else:  # a demo that trains: the demo renders and prepares it all itself
            home.mkdir(parents=True, exist_ok=True)
            (home / DEMO_MARKER).write_text("Made for a test, as `illusion-studio demo` makes it.\n", encoding="utf-8")
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
