"""Device cookies (OWASP's "Slow Down Online Guessing Attacks with Device Cookies"): a login leaves its
browser a signed cookie for that user; a later login for the name carrying it is counted only against
the cookie, so strangers' failures neither refuse nor slow it, and the cookie itself is locked after
its own failures. Served-app floods check that this holds on real connections, and that a flood of
slowed logins from one address leaves clean addresses' logins no more than twice as slow.
"""

from __future__ import annotations

import hashlib
import json
import signal
import statistics
import subprocess
import sys
import time
import uuid
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx
import pytest
from flask import Flask
from itsdangerous import TimestampSigner, URLSafeTimedSerializer

from dataset.db import migrate
from dataset.services import users as user_service
from dataset.settings import Settings
from tests.conftest import PASSWORD, TEST_REDIS_URL, csrf_from, make_settings
from tests.fixtures.login_flood import FLOOD, MAX_S, Served, serve
from tests.flood import READY
from tests.test_login_flood import guess_at_once, login_token, post_login
from webapp import throttle
from webapp.runtime import Runtime, runtime

LIMIT = 3  # login_limit_per_account_address here and in serve(), and so a device cookie's failures
YEAR_S = 365 * 86400
ROOT = Path(__file__).resolve().parent.parent
DEPLOYED_MAX_S = Settings.model_fields["login_slowdown_max_s"].default


@pytest.fixture(params=["sqlite", "redis"])
def settings(request: pytest.FixtureRequest, tmp_path: Path) -> Settings:
    """Small limits: a pair is refused past 3 failures, a name slows down past 4, an address past 6."""
    queue: dict[str, str] = {}
    if request.param == "redis":
        if not TEST_REDIS_URL:
            pytest.skip("Redis counters need TEST_REDIS_URL (e.g. redis://127.0.0.1:6379/0)")
        queue = {"queue_url": TEST_REDIS_URL, "queue_name": f"device-{uuid.uuid4().hex[:12]}"}
    s = make_settings(tmp_path / "ws", **queue, login_limit_per_account_address=f"{LIMIT} per 15 minutes",
                      login_slowdown_per_account="4 per 15 minutes", login_slowdown_per_address="6 per 15 minutes",
                      login_slowdown_max_s=1.0)
    migrate(s.database_url)
    return s


@pytest.fixture
def waits(monkeypatch: pytest.MonkeyPatch) -> list[float]:
    """The slow-down's waits, recorded instead of slept."""
    seen: list[float] = []
    monkeypatch.setattr("webapp.throttle.time.sleep", seen.append)
    return seen


def browser(app, address: str):  # type: ignore[no-untyped-def]
    """A browser (its own cookie jar) at ``address``."""
    client = app.test_client()
    client.environ_base["REMOTE_ADDR"] = address
    return client


def login(client, name: str, password: str = PASSWORD):  # type: ignore[no-untyped-def]
    """Log in as ``name``, logging the browser out first when it is logged in (its cookies stay)."""
    page = client.get("/login")
    if page.status_code == 302:
        client.post("/logout", data={"csrf_token": csrf_from(client.get("/").get_data(as_text=True))})
        page = client.get("/login")
    return client.post("/login", data={"name": name, "password": password,
                                       "csrf_token": csrf_from(page.get_data(as_text=True))})


def device_cookie(client, name: str):  # type: ignore[no-untyped-def]
    return client.get_cookie(throttle.device_cookie_name(name), path="/login")


def counts(app, address: str, name: str) -> tuple[int, int, int]:  # type: ignore[no-untyped-def]
    """The (name, address), name and address counters' failures."""
    with app.test_request_context(environ_base={"REMOTE_ADDR": address}):
        counters = throttle.LoginCounters.of(runtime().settings, name)
        return counters.pair.count(), counters.account.count(), counters.address.count()


class YearAndADayAgo(TimestampSigner):
    """Signs as if a year and a day ago."""

    def get_timestamp(self) -> int:
        return int(time.time()) - YEAR_S - 86400


def device_signer(key: str, **options: Any) -> URLSafeTimedSerializer:
    """Signs as the app signs device cookies."""
    return URLSafeTimedSerializer(key, salt=throttle.DEVICE_COOKIE_SALT, signer_kwargs={"digest_method": hashlib.sha256},
                                  **options)


@contextmanager
def app_with(settings: Settings, **overrides: object) -> Iterator[Flask]:
    """The app on ``settings``' data dir, with ``overrides``."""
    from webapp.app import create_app

    rt = Runtime(make_settings(settings.home, **overrides))
    try:
        yield create_app(rt.settings, rt)
    finally:
        rt.close()


def test_a_login_leaves_a_signed_device_cookie_for_the_login_page_only(app) -> None:  # type: ignore[no-untyped-def]
    client = browser(app, "198.51.100.7")
    response = login(client, "admin")
    assert response.status_code == 302
    header = next(h for h in response.headers.getlist("Set-Cookie") if h.startswith("device_"))
    attributes = {part.strip().split("=")[0].lower() for part in header.split(";")}
    assert {"httponly", "path", "max-age", "samesite"} <= attributes and "secure" not in attributes
    assert f"Max-Age={YEAR_S}" in header and "Path=/login" in header and "SameSite=Lax" in header
    cookie = device_cookie(client, "admin")
    owner, nonce = device_signer(app.secret_key).loads(cookie.value)
    assert owner == "admin" and len(nonce) >= 16
    assert login(client, "admin").status_code == 302
    assert device_cookie(client, "admin").value != cookie.value  # a new nonce each login
    assert login(client, "curator").status_code == 302 and device_cookie(client, "admin")  # one cookie per user


def test_the_device_cookie_is_secure_when_served_over_https(settings: Settings, tokens) -> None:  # type: ignore[no-untyped-def]
    with app_with(settings, https=True) as app:
        response = login(app.test_client(), "admin")
    header = next(h for h in response.headers.getlist("Set-Cookie") if h.startswith("device_"))
    assert "Secure" in header and "HttpOnly" in header


def test_a_device_cookie_lets_its_owner_past_a_refused_address_and_a_slowed_account(app, waits) -> None:  # type: ignore[no-untyped-def]
    owner = browser(app, "198.51.100.7")
    assert login(owner, "admin").status_code == 302
    for _ in range(LIMIT):  # someone at the owner's address (or the owner, in another browser) guesses
        assert login(browser(app, "198.51.100.7"), "admin", "wrong-password").status_code == 401
    for i in range(2):  # and others elsewhere: the name is past its slow-down
        assert login(browser(app, f"203.0.113.{i}"), "admin", "wrong-password").status_code == 401
    assert login(browser(app, "198.51.100.7"), "admin").status_code == 429  # no cookie: that address is refused
    before = counts(app, "198.51.100.7", "admin")
    assert login(owner, "admin", "wrong-password").status_code == 401  # the owner mistypes: the cookie's failure
    assert counts(app, "198.51.100.7", "admin") == before
    assert login(owner, "admin").status_code == 302
    assert waits == []  # nothing made the owner wait


def test_a_device_cookies_own_failures_lock_it_and_then_it_counts_as_untrusted(app, waits) -> None:  # type: ignore[no-untyped-def]
    stolen = browser(app, "203.0.113.9")
    assert login(stolen, "admin").status_code == 302
    for _ in range(LIMIT):
        assert login(stolen, "admin", "wrong-password").status_code == 401
    assert counts(app, "203.0.113.9", "admin") == (0, 0, 0)  # counted against the cookie alone
    for _ in range(LIMIT):  # locked: counted as any browser's, until that address is refused for the name
        assert login(stolen, "admin", "wrong-password").status_code == 401
    assert counts(app, "203.0.113.9", "admin") == (LIMIT, LIMIT, LIMIT)
    assert login(stolen, "admin").status_code == 429
    assert login(browser(app, "198.51.100.7"), "admin").status_code == 302  # the owner elsewhere is not refused


def test_only_a_valid_cookie_for_the_name_tried_is_trusted(app) -> None:  # type: ignore[no-untyped-def]
    address = "203.0.113.9"
    giver = browser(app, address)
    assert login(giver, "curator").status_code == 302 and login(giver, "admin").status_code == 302
    curators, admins = device_cookie(giver, "curator").value, device_cookie(giver, "admin").value
    for _ in range(LIMIT):
        assert login(browser(app, address), "admin", "wrong-password").status_code == 401
    name = throttle.device_cookie_name("admin")
    signer = device_signer(app.secret_key)
    expired = device_signer(app.secret_key, signer=YearAndADayAgo).dumps(["admin", "n" * 22])
    forged = device_signer("not the app's key").dumps(["admin", "n" * 22])
    for value in (curators, admins[:-2] + "xx", expired, forged, signer.dumps("admin"), "junk"):
        client = browser(app, address)
        client.set_cookie(name, value, path="/login")
        assert login(client, "admin").status_code == 429, value
    client = browser(app, address)
    client.set_cookie(name, admins, path="/login")
    assert login(client, "admin").status_code == 302


def test_no_device_cookies_when_their_life_is_zero(settings: Settings, tokens) -> None:  # type: ignore[no-untyped-def]
    with app_with(settings, login_device_cookie_days=0) as app:
        response = login(app.test_client(), "admin")
    assert response.status_code == 302
    assert not any(h.startswith("device_") for h in response.headers.getlist("Set-Cookie"))


# Served floods: the attacker in another process (tests/flood.py), on real connections.


@pytest.fixture
def real_hashing() -> Iterator[None]:
    """Unknown names hashed with the real (scrypt) dummy hash too, as in production."""
    user_service._dummy_hash.cache_clear()
    yield
    user_service._dummy_hash.cache_clear()


class Flood:
    """``python -m tests.flood`` running against ``served`` until :meth:`stop`: 16 connections post
    wrong passwords (``share`` of them for admin, the rest for random names), or get ``page``."""

    def __init__(self, served: Served, addresses: list[str], share: float = 0.0, page: str = "") -> None:
        command = [sys.executable, "-m", "tests.flood", served.url, "--connections", "16", "--share", str(share),
                   "--seconds", "55", *(f"--address={a}" for a in addresses), *(["--get", page] if page else []),
                   *(["--proxied"] if served.proxied else [])]
        self.process = subprocess.Popen(command, cwd=ROOT, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        assert self.process.stdout and self.process.stdout.readline().strip() == READY
        self.since: float | None = time.monotonic()  # sending since then; None: paused
        self.active_s, self.stretches = 0.0, 1  # seconds spent sending, and in how many stretches

    def pause(self) -> None:
        """Stop sending, as if the attacker's machine froze (its connections stay open)."""
        if self.since is not None:
            self.process.send_signal(signal.SIGSTOP)
            self.active_s += time.monotonic() - self.since
            self.since = None

    def resume(self) -> None:
        if self.since is None:
            self.process.send_signal(signal.SIGCONT)
            self.since = time.monotonic()
            self.stretches += 1

    def stop(self) -> Counter[int]:
        """End the flood; the statuses it got."""
        self.resume()
        self.pause()  # counts the last stretch
        self.process.send_signal(signal.SIGCONT)
        try:
            out, _ = self.process.communicate(input="", timeout=45)
        except subprocess.TimeoutExpired:
            self.process.kill()
            raise
        return Counter({int(status): n for status, n in json.loads(out.strip().splitlines()[-1]).items()})


def timed_login(served: Served, address: str, cookies: httpx.Cookies | None = None) -> tuple[int, float, httpx.Cookies]:
    """A new browser at ``address`` (holding ``cookies``) logs in as admin: the status, the seconds the
    post took, and the device cookies it holds after."""
    with served.client(address) as browser:
        if cookies is not None:
            browser.cookies.update(cookies)
        token = login_token(browser)
        started = time.monotonic()
        status = post_login(browser, token, "admin", PASSWORD)
        took = time.monotonic() - started
        kept = httpx.Cookies()
        for cookie in browser.cookies.jar:
            if cookie.name.startswith(throttle.DEVICE_COOKIE_PREFIX):
                kept.jar.set_cookie(cookie)
        return status, took, kept


def owner_address(served: Served) -> str:
    return "198.51.100.7" if served.proxied else "127.0.0.7"


@pytest.mark.password_hashing
def test_parallel_guesses_with_a_device_cookie_cannot_pass_its_limit(served: Served) -> None:
    """16 connections carrying one device cookie post wrong passwords at once: the cookie's limit (3)
    are checked as trusted, and the rest, untrusted, are held to the address's limit for the name (3)."""
    address = owner_address(served)
    status, _, cookies = timed_login(served, address)
    assert status == 302
    answers = guess_at_once(served, address, FLOOD, cookies)
    assert answers == {401: 2 * LIMIT, 429: FLOOD - 2 * LIMIT}, answers


@pytest.mark.serial
@pytest.mark.password_hashing
@pytest.mark.usefixtures("real_hashing")
def test_an_owner_with_a_device_cookie_who_mistyped_gets_in_during_a_two_address_flood(served: Served) -> None:
    """16 connections from two addresses guess (a tenth for admin, the rest random names), filling
    every waiting slot; the admin's address failed once for admin, so a cookie-less login from there
    must wait and mostly finds no slot. With its device cookie (and one mistake of its own) the
    admin's browser gets in on ≥ 90% of tries within login_slowdown_max_s + 1 s."""
    address = owner_address(served)
    status, _, cookies = timed_login(served, address)
    assert status == 302
    with served.client(address) as elsewhere:  # a failure from the owner's address without the cookie
        assert post_login(elsewhere, login_token(elsewhere), "admin", "wrong-password") == 401
    with served.client(address) as mine:  # and the owner's own mistake, with it
        mine.cookies.update(cookies)
        assert post_login(mine, login_token(mine), "admin", "wrong-password") == 401
    attackers = ["203.0.113.9", "203.0.113.10"] if served.proxied else ["127.0.0.9", "127.0.0.10"]
    flood = Flood(served, attackers, share=0.1)
    try:
        time.sleep(2 * MAX_S)  # the attackers' waits have grown to their longest
        without = Counter(timed_login(served, address)[0] for _ in range(5))
        tries, deadline = 25, time.monotonic() + 40
        took: list[float] = []  # the seconds of each try that got in
        for _ in range(tries):
            if time.monotonic() > deadline:
                break
            status, seconds, cookies = timed_login(served, address, cookies)
            if status == 302:
                took.append(seconds)
    finally:
        answers = flood.stop()
    within = sum(t <= MAX_S + 1 for t in took)
    report = f"in {within}/{tries} within {MAX_S + 1} s; median {statistics.median(took or [0]):.2f} s, " \
             f"max {max(took or [0]):.2f} s; without the cookie: {dict(without)}; flood: {dict(answers)}"
    print(report)
    assert within >= 0.9 * tries, report
    assert answers[401] and answers[429], report  # the flood was counted and refused


@pytest.fixture
def served_as_deployed(tmp_path: Path) -> Iterator[Served]:
    """:func:`serve` with the deployment's longest wait (``login_slowdown_max_s``' default)."""
    with serve(tmp_path / "ws", proxied=False, login_slowdown_max_s=DEPLOYED_MAX_S) as app:
        yield app


@pytest.mark.serial
@pytest.mark.password_hashing
@pytest.mark.usefixtures("real_hashing")
def test_a_many_name_flood_from_one_address_leaves_clean_logins_at_most_twice_as_slow(served_as_deployed: Served) -> None:
    """A clean address's login (no device cookie, no failures of its own) while 16 connections from
    one address flood slowed logins for random names: neither refused nor slowed, and in the median
    at most twice as slow as while the flood pauses. The flood's refused logins check no password;
    its waiting ones hold two threads and check two passwords per wait. What remains is the server's
    cost of answering requests at all, which the report shows beside a flood of the cheapest page
    (/healthz) from the same connections. The phases alternate, a few logins each, so that whatever
    else the machine runs meanwhile weighs on all of them alike."""
    served, address, attacker = served_as_deployed, "127.0.0.7", "127.0.0.9"
    with served.client(attacker) as setup:  # that address at its longest wait from the start
        token = login_token(setup)
        for i in range(8):
            assert post_login(setup, token, f"x{i}", "wrong-password") == 401
    logins, pages = Flood(served, [attacker]), Flood(served, [attacker], page="/healthz")
    took: dict[str, list[float]] = {"logins": [], "quiet": [], "pages": []}
    statuses: Counter[int] = Counter()
    health = 0.0
    try:
        pages.pause()
        deadline = time.monotonic() + 36
        while len(took["pages"]) < 12 and time.monotonic() < deadline:
            for phase, flood in (("logins", logins), ("quiet", None), ("pages", pages)):
                if flood is not None:
                    flood.resume()
                    time.sleep(0.3)
                for status, seconds, _ in (timed_login(served, address) for _ in range(3)):
                    statuses[status] += 1
                    took[phase].append(seconds)
                if flood is logins:
                    with served.client(address) as other:
                        started = time.monotonic()
                        assert other.get("/healthz").status_code == 200
                        health = max(health, time.monotonic() - started)
                if flood is not None:
                    flood.pause()
                    time.sleep(DEPLOYED_MAX_S + 0.3 if flood is logins else 0.1)  # its waiting logins are answered
    finally:
        answers, served_pages = logins.stop(), pages.stop()
    median = {phase: statistics.median(seconds) for phase, seconds in took.items()}
    report = (f"clean logins' median: {median['quiet']:.3f} s quiet, {median['logins']:.3f} s in the login flood "
              f"(×{median['logins'] / median['quiet']:.1f}; max {max(took['logins']):.3f} s; /healthz at most "
              f"{health:.3f} s), {median['pages']:.3f} s in the /healthz flood (×{median['pages'] / median['quiet']:.1f}); "
              f"{len(took['logins'])} logins a phase; login flood {dict(answers)} in {logins.active_s:.1f} s, "
              f"page flood {dict(served_pages)} in {pages.active_s:.1f} s")
    print(report)
    assert statuses == {302: sum(map(len, took.values()))} and len(took["pages"]) >= 9, report
    assert median["logins"] <= 2 * median["quiet"], report
    # Its password checks: two waiting logins at a time, each after the longest wait, and one more
    # each that was waiting when a stretch of the flood ended.
    most = throttle.WAITING_PER_ADDRESS * (logins.active_s / DEPLOYED_MAX_S + logins.stretches + 1)
    assert 0 < answers[401] <= most and answers[429], report
