"""The app behind Debian's nginx, configured as docs/security.md's deployment section shows: bodies buffered by
the proxy (``proxy_request_buffering on``), the client's address passed on and trusted. Slow clients cost
the app nothing there either, a login counts the client's own address, and an upload passes whole."""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import statistics
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from dataset.db import migrate, transaction
from dataset.services import users as user_service
from tests.conftest import PASSWORD, csrf_from, make_settings
from webapp.cli.workspace import make_server
from webapp.runtime import Runtime

NGINX = shutil.which("nginx") or ("/usr/sbin/nginx" if Path("/usr/sbin/nginx").exists() else None)
pytestmark = [pytest.mark.serial, pytest.mark.skipif(NGINX is None, reason="Debian's nginx is not installed "
                                                                       "(apt-get install nginx-light; .ci/run installs it)")]
SLOW = 32

# docs/security.md's deployment block, with the test's ports and folders filled in.
SITE = """
server {{
    listen 127.0.0.1:{port};
    client_max_body_size 2049m;      # max_upload_mb + 1 MiB
    client_body_timeout 10s;         # a body that stops arriving is dropped by nginx
    client_header_timeout 10s;
    location / {{
        proxy_pass http://127.0.0.1:{app_port};
        proxy_request_buffering on;  # nginx takes the whole body before the app sees the request
        proxy_http_version 1.1;
        proxy_set_header Host $host;
        proxy_set_header X-Forwarded-For $proxy_add_x_forwarded_for;
        proxy_set_header X-Forwarded-Proto $scheme;
    }}
}}
"""


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def nginx_conf(prefix: Path, port: int, app_port: int) -> Path:
    temp = "\n".join(f"    {kind}_temp_path {prefix / kind};" for kind in ("client_body", "proxy", "fastcgi", "uwsgi", "scgi"))
    conf = prefix / "nginx.conf"
    conf.write_text(("user root;\n" if os.geteuid() == 0 else "") + f"""
daemon off;
pid {prefix / "nginx.pid"};
error_log {prefix / "error.log"} warn;
events {{ worker_connections 512; }}
http {{
    access_log off;
{temp}
{SITE.format(port=port, app_port=app_port)}
}}
""")
    return conf


@pytest.fixture(scope="module")
def proxied(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, dict[str, str]]]:
    """(the proxy's URL, a token per role) for the app served behind nginx."""
    home = tmp_path_factory.mktemp("nginx")
    settings = make_settings(home / "ws", trusted_proxies=["127.0.0.1/32"])
    migrate(settings.database_url)
    rt = Runtime(settings)
    with transaction(rt.sessions) as s:
        tokens = {role: user_service.issue_token(s, user_service.create_user(s, role, role, PASSWORD))
                  for role in ("annotator", "curator")}
    server = make_server(settings, rt, "127.0.0.1", 0, threads=8)
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    port = free_port()
    assert NGINX is not None
    proxy = subprocess.Popen([NGINX, "-c", str(nginx_conf(home, port, server.effective_port)), "-p", str(home)],
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 10
        while True:
            try:
                httpx.get(f"http://127.0.0.1:{port}/healthz", timeout=1)
                break
            except httpx.HTTPError:
                assert proxy.poll() is None, proxy.stderr.read().decode() if proxy.stderr else "nginx stopped"
                assert time.monotonic() < deadline, (home / "error.log").read_text()
                time.sleep(0.1)
        yield f"http://127.0.0.1:{port}", tokens
    finally:
        proxy.terminate()
        proxy.wait(10)
        server.close()
        thread.join(10)
        rt.close()


def test_slow_clients_behind_nginx_cost_the_app_nothing(proxied) -> None:  # type: ignore[no-untyped-def]
    url, tokens = proxied
    port = int(url.rsplit(":", 1)[1])
    slow = []
    for n in range(SLOW):
        sock = socket.create_connection(("127.0.0.1", port))
        if n % 2:
            sock.sendall(b"POST /login HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: chunked\r\n"
                         b"Content-Type: application/x-www-form-urlencoded\r\n\r\n" + b"7530\r\n" + b"a" * 30_000)
        else:
            sock.sendall(f"POST /api/v1/frames/1/segment HTTP/1.1\r\nHost: x\r\nContent-Length: 1000000\r\n"
                         f"Authorization: Bearer {tokens['annotator']}\r\n\r\n".encode() + b" " * 40_000)
        slow.append(sock)
    latencies = []
    try:
        with httpx.Client(base_url=url, headers={"Authorization": f"Bearer {tokens['annotator']}"}, timeout=20) as user:
            until = time.monotonic() + 4
            while time.monotonic() < until:
                for path in ("/healthz", "/api/v1/me"):
                    t0 = time.monotonic()
                    assert user.get(path).status_code == 200
                    latencies.append(time.monotonic() - t0)
                for sock in slow:
                    with contextlib.suppress(OSError):  # nginx may have dropped it: what matters is the app
                        sock.send(b" ")
                time.sleep(0.1)
    finally:
        for sock in slow:
            sock.close()
    assert statistics.quantiles(latencies, n=20)[-1] < 2.0


def test_a_login_through_nginx_counts_the_clients_address_and_gets_in(proxied) -> None:  # type: ignore[no-untyped-def]
    url, _ = proxied
    with httpx.Client(base_url=url, timeout=20, follow_redirects=False) as browser:
        token = csrf_from(browser.get("/login").text)
        answer = browser.post("/login", data={"name": "curator", "password": PASSWORD, "csrf_token": token})
        assert answer.status_code in (302, 303), answer.text[:300]
        assert browser.get("/api/v1/me").json()["name"] == "curator"


def test_a_large_body_passes_nginx_whole(proxied) -> None:  # type: ignore[no-untyped-def]
    """A 3 MB draft (past what the app keeps in memory) through nginx: judged on its content."""
    url, tokens = proxied
    body = b'{"version": 0, "submit": false, "regions": [], "pad": "' + b"x" * (3 << 20) + b'"}'
    answer = httpx.post(f"{url}/api/v1/frames/1/annotation", content=body, timeout=30,
                        headers={"Authorization": f"Bearer {tokens['annotator']}", "Content-Type": "application/json"})
    assert answer.status_code == 404 and "frame" in answer.json()["error"], answer.text[:300]
