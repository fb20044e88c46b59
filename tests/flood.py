"""A login flood from another process, as an attacker's machine would send it: connections from given
addresses post wrong passwords for random names (a share of them for one name) until stdin closes
or a time limit, then print the statuses they got as JSON.

Another process, so that the flood's work does not hold the served app's GIL, as a flood from the
test's own threads would; and plain sockets with prepared requests, so that on a machine of two
cores the attacker's own CPU, which would be another machine's, takes little from the server's.
Run ``python -m tests.flood --help`` from the repository's root.
"""

from __future__ import annotations

import argparse
import json
import random
import re
import socket
import sys
import threading
import uuid
from collections import Counter
from urllib.parse import urlencode, urlsplit

READY = "ready"  # printed once every connection holds a login form's CSRF token
_LENGTH = re.compile(rb"\r\ncontent-length:\s*(\d+)", re.IGNORECASE)
_CLOSE = re.compile(rb"\r\nconnection:\s*close", re.IGNORECASE)
_SESSION = re.compile(rb"\r\nset-cookie:\s*(session=[^;\r\n]*)", re.IGNORECASE)
_TOKEN = re.compile(rb'name="csrf_token"[^>]*value="([^"]+)"')


class Connection:
    """One keep-alive HTTP/1.1 connection to ``url`` that the app counts as coming from ``address``:
    bound to it (127.0.0.0/8), or behind a trusted proxy, naming it in X-Forwarded-For."""

    def __init__(self, url: str, address: str, proxied: bool) -> None:
        parts = urlsplit(url)
        self.server = (parts.hostname or "127.0.0.1", parts.port or 80)
        self.address, self.proxied = address, proxied
        self.extra = f"X-Forwarded-For: {address}\r\n" if proxied else ""
        self.sock: socket.socket | None = None
        self.buffer = b""

    def _connect(self) -> socket.socket:
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.settimeout(30)
        if not self.proxied:
            sock.bind((self.address, 0))
        sock.connect(self.server)
        self.buffer = b""
        return sock

    def exchange(self, request: bytes) -> tuple[int, bytes, bytes]:
        """Send ``request``; the answer's status, head and body (reconnecting when the server closed)."""
        for _ in range(2):
            self.sock = self.sock or self._connect()
            try:
                self.sock.sendall(request)
                return self._read()
            except (ConnectionError, TimeoutError, ValueError):
                self.close()
        raise ConnectionError("the server answered neither on the open connection nor on a new one")

    def _read(self) -> tuple[int, bytes, bytes]:
        assert self.sock is not None
        while b"\r\n\r\n" not in self.buffer:
            self._receive()
        head, self.buffer = self.buffer.split(b"\r\n\r\n", 1)
        match = _LENGTH.search(head)
        length = int(match.group(1)) if match else 0
        while len(self.buffer) < length:
            self._receive()
        body, self.buffer = self.buffer[:length], self.buffer[length:]
        if _CLOSE.search(head):
            self.close()
        return int(head.split(b" ", 2)[1]), head, body

    def _receive(self) -> None:
        assert self.sock is not None
        data = self.sock.recv(65536)
        if not data:
            raise ConnectionError("closed")
        self.buffer += data

    def close(self) -> None:
        if self.sock is not None:
            self.sock.close()
            self.sock = None

    def get(self, path: str) -> tuple[int, bytes, bytes]:
        return self.exchange(f"GET {path} HTTP/1.1\r\nHost: {self.server[0]}\r\n{self.extra}\r\n".encode())

    def post(self, path: str, form: dict[str, str], cookie: str) -> int:
        body = urlencode(form).encode()
        head = (f"POST {path} HTTP/1.1\r\nHost: {self.server[0]}\r\n{self.extra}Cookie: {cookie}\r\n"
                f"Content-Type: application/x-www-form-urlencoded\r\nContent-Length: {len(body)}\r\n\r\n")
        return self.exchange(head.encode() + body)[0]


def flood(args: argparse.Namespace) -> Counter[int]:
    """Post wrong passwords on ``args.connections`` connections spread over ``args.address`` until
    stdin closes or ``args.seconds`` pass; the statuses answered."""
    stop, ready = threading.Event(), threading.Barrier(args.connections + 1, timeout=60)
    answers: Counter[int] = Counter()
    lock = threading.Lock()

    def run(address: str) -> None:
        connection = Connection(args.url, address, args.proxied)
        try:
            _, head, body = connection.get("/login")
            cookie, token = _SESSION.search(head), _TOKEN.search(body)
            assert cookie and token, "the login page set no session or carries no CSRF token"
            ready.wait()
            while not stop.is_set() and args.get:
                status = connection.get(args.get)[0]
                with lock:
                    answers[status] += 1
            while not stop.is_set():
                name = args.name if random.random() < args.share else uuid.uuid4().hex[:12]
                form = {"name": name, "password": "wrong-password", "csrf_token": token.group(1).decode()}
                status = connection.post("/login", form, cookie.group(1).decode())
                with lock:
                    answers[status] += 1
        finally:
            connection.close()

    threads = [threading.Thread(target=run, args=(args.address[i % len(args.address)],), daemon=True)
               for i in range(args.connections)]
    for thread in threads:
        thread.start()
    ready.wait()
    print(READY, flush=True)
    threading.Thread(target=lambda: (sys.stdin.read(), stop.set()), daemon=True).start()
    stop.wait(timeout=args.seconds)
    stop.set()
    for thread in threads:
        thread.join(timeout=35)
    return answers


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("url")
    parser.add_argument("--address", action="append", required=True, help="the flood's client addresses (repeatable)")
    parser.add_argument("--connections", type=int, default=16)
    parser.add_argument("--name", default="admin", help="the user name a share of the guesses are for")
    parser.add_argument("--share", type=float, default=0.0, help="that share (0 to 1); the rest are random names")
    parser.add_argument("--seconds", type=float, default=60.0, help="the longest the flood lasts")
    parser.add_argument("--get", metavar="PATH", help="get this page instead of posting logins (a baseline)")
    parser.add_argument("--proxied", action="store_true", help="name the address in X-Forwarded-For")
    print(json.dumps(flood(parser.parse_args())), flush=True)


if __name__ == "__main__":
    main()
