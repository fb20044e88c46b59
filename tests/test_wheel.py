"""A wheel built from the repository serves the app whole: installed in a fresh environment that
cannot see the checkout, ``illusion-studio serve`` answers pages together with their scripts and styles.

The wheel is built the way ``python -m build`` builds it (sdist, then a wheel from the sdist), offline
and from a copy of the sources, so that nothing is written into the checkout. The fresh environment
borrows this one's installed dependencies through a ``.pth`` line and gets the wheel itself with
``pip install --no-deps``."""

from __future__ import annotations

import http.cookiejar
import importlib.util
import os
import re
import shutil
import site
import subprocess
import sys
import time
import urllib.parse
import urllib.request
from pathlib import Path

import pytest

from tests.browser import free_port, stop

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parent.parent
# What the sdist is made from: the build configuration, the packages and static/ (MANIFEST.in).
SOURCES = ("pyproject.toml", "setup.py", "MANIFEST.in", "README.md", "annotation", "core", "dataset", "model", "webapp",
           "benchmarks", "static")
PASSWORD = "wheel-test-pass"


def _env() -> dict[str, str]:
    """This environment without anything that would point the new one at the checkout or a workspace."""
    return {k: v for k, v in os.environ.items() if k != "PYTHONPATH" and not k.startswith("ILLUSION_STUDIO_")}


def _run(command: list[str | Path], cwd: Path, stdin: str = "", timeout: float = 120) -> str:
    """Run ``command``; its stdout, or a failure that shows what it printed."""
    result = subprocess.run([str(c) for c in command], cwd=cwd, env=_env(), input=stdin, capture_output=True, text=True,
                            timeout=timeout)
    assert result.returncode == 0, f"{command} exited {result.returncode}:\n{result.stdout}\n{result.stderr}"
    return result.stdout


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The wheel, built offline from an sdist of a copy of the sources."""
    if importlib.util.find_spec("setuptools") is None:
        pytest.skip("building the wheel offline (--no-build-isolation) needs setuptools in this environment")
    tmp = tmp_path_factory.mktemp("wheel")
    src = tmp / "src"
    src.mkdir()
    junk = shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info", "build")
    for name in SOURCES:
        if (ROOT / name).is_dir():
            shutil.copytree(ROOT / name, src / name, ignore=junk)
        else:
            shutil.copy2(ROOT / name, src / name)
    sdist = _run([sys.executable, "-c", "import sys; from setuptools import build_meta; "
                  "print(build_meta.build_sdist(sys.argv[1]))", tmp / "sdist"], cwd=src).strip().splitlines()[-1]
    _run([sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", "--no-build-isolation", "--no-index",
          "--disable-pip-version-check", "-w", tmp / "dist", tmp / "sdist" / sdist], cwd=tmp)
    (built,) = (tmp / "dist").glob("illusion_studio-*.whl")
    return built


@pytest.fixture(scope="module")
def venv(wheel: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fresh virtual environment holding the wheel; its dependencies are this environment's."""
    root = tmp_path_factory.mktemp("venv") / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", root], cwd=root.parent)
    python = root / "bin" / "python"
    # Installed before the .pth below exists: pip then sees no illusion-studio but the wheel's.
    _run([sys.executable, "-m", "pip", "--python", python, "install", "--quiet", "--no-deps", "--no-index",
          "--disable-pip-version-check", wheel], cwd=root.parent)
    purelib = Path(_run([python, "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"], cwd=root).strip())
    # Directories named in a .pth file join the path, but the .pth files in them are not run: the
    # editable install's, which maps the packages to the checkout, stays out.
    (purelib / "dependencies.pth").write_text("".join(f"{p}\n" for p in site.getsitepackages()))
    return root


def test_the_installed_package_is_the_wheel(venv: Path) -> None:
    code = "import webapp, webapp.app; print(webapp.__file__); print(webapp.app.static_dir())"
    package, static = _run([venv / "bin" / "python", "-c", code], cwd=venv.parent).split()
    assert Path(package).is_relative_to(venv), f"webapp comes from {package}, not the wheel"
    assert Path(static) == Path(package).parent / "static"
    assert (Path(static) / "css" / "app.css").read_bytes() == (ROOT / "static" / "css" / "app.css").read_bytes()


def test_serve_answers_pages_with_their_scripts_and_styles(venv: Path) -> None:
    cli = venv / "bin" / "illusion-studio"
    work = venv.parent  # outside the checkout: nothing found relative to the working directory
    home = work / "ws"
    assert "workspace ready" in _run([cli, "--data-dir", home, "init"], cwd=work)
    _run([cli, "--data-dir", home, "users", "create", "ada", "--role", "curator", "--password-stdin"], cwd=work,
         stdin=PASSWORD + "\n")
    port = free_port()
    log = (work / "serve.log").open("w")
    server = subprocess.Popen([str(cli), "--data-dir", str(home), "serve", "--host", "127.0.0.1", "--port", str(port)],
                              cwd=work, env=_env(), stdout=log, stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{port}"
    try:
        _wait_until_up(url, server, work / "serve.log")
        opener = urllib.request.build_opener(urllib.request.HTTPCookieProcessor(http.cookiejar.CookieJar()))
        login = _get(opener, f"{url}/login").decode()
        styles = re.findall(r'<link rel="stylesheet" href="(/static/[^"]+\.css)', login)
        assert styles, login
        token = re.search(r'name="csrf_token" type="hidden" value="([^"]+)"', login)
        assert token, login
        form = {"csrf_token": token.group(1), "name": "ada", "password": PASSWORD}
        with opener.open(f"{url}/login", data=urllib.parse.urlencode(form).encode(), timeout=30) as response:
            dashboard = response.read().decode()
        assert response.url.rstrip("/") == url, f"login did not reach the dashboard: {response.url}"
        scripts = re.findall(r'<script type="module" src="(/static/[^"]+\.js)"', dashboard)
        assert scripts, dashboard
        for path in (styles[0], scripts[0]):
            body = _get(opener, url + path)
            assert body and body == (ROOT / path.removeprefix("/")).read_bytes(), path
    finally:
        stop(server)
        log.close()


def _wait_until_up(url: str, server: subprocess.Popen[bytes], log: Path, timeout_s: float = 60) -> None:
    """Return once the server answers ``/healthz``; fail with its log if it exits or stays silent."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            with urllib.request.urlopen(f"{url}/healthz", timeout=2):
                return
        except OSError:
            assert server.poll() is None, f"serve exited {server.returncode}:\n{log.read_text()}"
            assert time.monotonic() < deadline, f"serve did not answer in {timeout_s:.0f} s:\n{log.read_text()}"
            time.sleep(0.3)


def _get(opener: urllib.request.OpenerDirector, url: str) -> bytes:
    """The body of a 200 answer to GET ``url``."""
    with opener.open(url, timeout=30) as response:
        assert response.status == 200, f"{url}: {response.status}"
        return response.read()
