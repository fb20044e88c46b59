"""A flood of slowed logins from one address keeps no one else out.

The served app, real connections: 16 of them post slowed logins (fresh names, wrong passwords) from
one address whose failures, and the admin account's, are past their slow-down limits. Meanwhile the
admin's right password from an address that has not been guessing gets in within
``login_slowdown_max_s`` + 1 s, and other routes keep answering — whether the app sees its
clients' own addresses (127.0.0.x here) or, behind a reverse proxy named in ``trusted_proxies``,
the addresses the proxy reports in X-Forwarded-For.
"""

from __future__ import annotations

import threading
import time
import uuid
from collections import Counter

import httpx
import pytest

from tests.conftest import PASSWORD, csrf_from
from tests.fixtures.login_flood import FLOOD, MAX_S, Served


def addresses(served: Served) -> tuple[str, str]:
    """(the attacker's, the owner's) address."""
    return ("203.0.113.9", "198.51.100.7") if served.proxied else ("127.0.0.9", "127.0.0.7")


def post_login(client: httpx.Client, token: str, name: str, password: str) -> int:
    return client.post("/login", data={"name": name, "password": password, "csrf_token": token}).status_code


def login_token(client: httpx.Client) -> str:
    return csrf_from(client.get("/login").text)


def test_a_flood_of_slowed_logins_from_one_address_keeps_neither_the_owner_nor_other_routes_out(served: Served) -> None:
    attacker, owner = addresses(served)
    with served.client(attacker) as setup:
        token = login_token(setup)
        # the admin account past its slow-down, then the attacker's address past its own
        for name in ("admin", "admin", "x1", "x2"):
            assert post_login(setup, token, name, "wrong-password") == 401

    stop = threading.Event()
    answers: Counter[int] = Counter()

    def flood() -> None:
        with served.client(attacker) as client:
            flood_token = login_token(client)
            while not stop.is_set():
                answers[post_login(client, flood_token, uuid.uuid4().hex[:12], "wrong-password")] += 1

    threads = [threading.Thread(target=flood, daemon=True) for _ in range(FLOOD)]
    for thread in threads:
        thread.start()
    try:
        time.sleep(2 * MAX_S)  # the attacker's waits have grown to their longest
        for _ in range(3):
            with served.client(owner) as admin:
                token = login_token(admin)
                started = time.monotonic()
                status = post_login(admin, token, "admin", PASSWORD)
                took = time.monotonic() - started
            assert status == 302 and took <= MAX_S + 1, (status, took, answers)
            with served.client(owner) as other:
                started = time.monotonic()
                assert other.get("/healthz").status_code == 200
                assert time.monotonic() - started < 1, answers
    finally:
        stop.set()
        for thread in threads:
            thread.join(timeout=10)
    assert set(answers) <= {401, 429} and answers[401] and answers[429], answers  # slowed, and refused past the cap


def guess_at_once(served: Served, address: str, connections: int, cookies: httpx.Cookies | None = None) -> Counter[int]:
    """``connections`` connections from ``address`` (with ``cookies``) post a wrong password for admin
    at the same moment; the statuses answered."""
    ready = threading.Barrier(connections)
    answers: Counter[int] = Counter()

    def guess() -> None:
        with served.client(address) as client:
            client.cookies.update(cookies or {})
            token = login_token(client)
            ready.wait(timeout=30)
            answers[post_login(client, token, "admin", "wrong-password")] += 1

    threads = [threading.Thread(target=guess) for _ in range(connections)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(timeout=60)
    return answers


@pytest.mark.password_hashing
def test_parallel_guesses_from_one_address_cannot_pass_its_limit_for_a_name(served: Served) -> None:
    """16 connections post wrong passwords for one name at once: only the pair's limit (3) have their
    passwords checked, the rest get 429. Each attempt is counted in the same atomic step that tests
    the limit, before its password is checked, so attempts in flight together cannot all pass."""
    attacker, _ = addresses(served)
    answers = guess_at_once(served, attacker, FLOOD)
    assert answers == {401: 3, 429: FLOOD - 3}, answers
