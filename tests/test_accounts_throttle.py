"""Throttling that refuses the guesser and never locks the owner out: failed logins per (account,
address) get 429; across addresses they only slow the account down; bad API tokens get 429 while
right ones always pass; a bad or throttled token on a page answers 401 or 429 with a page."""

from __future__ import annotations

import uuid
from contextlib import ExitStack
from pathlib import Path

import pytest

from dataset.db import migrate
from dataset.settings import Settings
from tests.conftest import PASSWORD, TEST_REDIS_URL, csrf_from, login, make_settings


@pytest.fixture(params=["sqlite", "redis"])
def settings(request: pytest.FixtureRequest, tmp_path: Path) -> Settings:
    """Small limits, so each test needs only a few attempts; counters in ratelimit.db, or in Redis
    (under a queue name of its own) where TEST_REDIS_URL names one."""
    queue: dict[str, str] = {}
    if request.param == "redis":
        if not TEST_REDIS_URL:
            pytest.skip("Redis counters need TEST_REDIS_URL (e.g. redis://127.0.0.1:6379/0)")
        queue = {"queue_url": TEST_REDIS_URL, "queue_name": f"throttle-{uuid.uuid4().hex[:12]}"}
    s = make_settings(tmp_path / "ws", **queue, login_limit_per_account_address="3 per 15 minutes",
                      login_slowdown_per_account="4 per 15 minutes", login_slowdown_per_address="6 per 15 minutes",
                      login_slowdown_max_s=1.0, token_limit_per_address="5 per 15 minutes",
                      token_limit_per_account="3 per 15 minutes")
    migrate(s.database_url)
    return s


@pytest.fixture
def waits(monkeypatch: pytest.MonkeyPatch) -> list[float]:
    """The slow-down's waits, recorded instead of slept."""
    seen: list[float] = []
    monkeypatch.setattr("webapp.throttle.time.sleep", seen.append)
    return seen


def from_address(app, address: str):  # type: ignore[no-untyped-def]
    client = app.test_client()
    client.environ_base["REMOTE_ADDR"] = address
    return client


def bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def test_a_guessing_address_is_refused_for_that_account_but_its_owner_logs_in(app, waits) -> None:  # type: ignore[no-untyped-def]
    stranger = from_address(app, "203.0.113.9")
    for _ in range(3):
        assert login(stranger, "admin", "wrong-password").status_code == 401
    refused = login(stranger, "admin")  # the right password, from the address that guessed
    assert refused.status_code == 429 and int(refused.headers["Retry-After"]) > 0
    assert "Too many failed logins for this name from your address" in refused.get_data(as_text=True)
    assert '<a href="/login">Back to the login page</a>' in refused.get_data(as_text=True)  # a short page, no form
    assert login(stranger, "curator").status_code == 302  # the pair is refused, not the address
    assert login(from_address(app, "198.51.100.7"), "admin").status_code == 302  # nor the account
    assert waits == []


def test_guesses_from_many_addresses_slow_the_guessers_down_but_never_the_owner(app, waits) -> None:  # type: ignore[no-untyped-def]
    for i in range(4):  # one wrong password from each of 4 addresses: no pair reaches its limit
        assert login(from_address(app, f"203.0.113.{i}"), "admin", "wrong-password").status_code == 401
    assert waits == []  # each address's first failure for the name
    for i in range(3):  # the name is past 4 failures: an address that has failed for it waits, doubling
        assert login(from_address(app, f"203.0.113.{i}"), "admin", "wrong-password").status_code == 401
    assert waits == [0.25, 0.5, 1.0]
    assert login(from_address(app, "198.51.100.7"), "admin").status_code == 302  # the owner: no wait, in
    assert from_address(app, "198.51.100.8").get("/login").status_code == 200  # a page view waits for nothing
    assert waits == [0.25, 0.5, 1.0]


def test_an_ipv6_client_counts_by_its_64_network(app, waits) -> None:  # type: ignore[no-untyped-def]
    for i in range(3):  # a new address of one /64 for each guess
        assert login(from_address(app, f"2001:db8:1:2::{i + 1}"), "admin", "wrong-password").status_code == 401
    assert login(from_address(app, "2001:db8:1:2:ffff::9"), "admin").status_code == 429  # the /64's pair is refused
    assert login(from_address(app, "2001:db8:1:3::1"), "admin").status_code == 302  # the next /64 is someone else


def test_one_address_guessing_many_names_is_slowed_not_refused(app, waits) -> None:  # type: ignore[no-untyped-def]
    proxy = from_address(app, "192.0.2.1")
    for name in ("ana", "bo", "cy", "admin", "curator", "annotator"):
        assert login(proxy, name, "wrong-password").status_code == 401
    assert waits == []
    assert login(proxy, "annotator").status_code == 302  # someone else behind the proxy gets in
    assert waits == [0.25]


def test_a_right_token_is_never_refused_for_others_bad_tokens(app, tokens) -> None:  # type: ignore[no-untyped-def]
    proxy = from_address(app, "192.0.2.1")
    for _ in range(5):
        assert proxy.get("/api/v1/me", headers=bearer("ist_guess")).status_code == 401
    refused = proxy.get("/api/v1/me", headers=bearer("ist_guess"))
    assert refused.status_code == 429 and int(refused.headers["Retry-After"]) > 0
    assert refused.json["error"] == "too many bad API tokens; try again later"
    for role in ("admin", "curator", "annotator"):  # every script behind the same proxy still works
        assert proxy.get("/api/v1/me", headers=bearer(tokens[role])).json["name"] == role


def test_wrong_secrets_for_one_account_get_429_from_any_address_but_its_token_passes(app, tokens) -> None:  # type: ignore[no-untyped-def]
    wrong = tokens["admin"][:-43] + "x" * 43
    for i in range(3):
        assert from_address(app, f"203.0.113.{i}").get("/api/v1/me", headers=bearer(wrong)).status_code == 401
    assert from_address(app, "203.0.113.9").get("/api/v1/me", headers=bearer(wrong)).status_code == 429
    assert from_address(app, "203.0.113.9").get("/api/v1/me", headers=bearer(tokens["admin"])).status_code == 200


@pytest.mark.parametrize("path", ["/login", "/", "/admin/users", "/jobs"])
def test_a_bad_or_throttled_token_on_a_page_answers_401_or_429_with_a_page(app, tokens, path: str) -> None:  # type: ignore[no-untyped-def]
    client = from_address(app, "192.0.2.1")
    for _ in range(5):
        response = client.get(path, headers=bearer("bad"))
        assert response.status_code == 401 and response.mimetype == "text/html"
        assert response.headers["WWW-Authenticate"].lower().startswith("bearer")
        assert "this API token is not valid" in response.get_data(as_text=True)
        assert 'href="/login">Log in</a>' in response.get_data(as_text=True)
    response = client.get(path, headers=bearer("bad"))
    assert response.status_code == 429 and response.mimetype == "text/html"
    assert int(response.headers["Retry-After"]) > 0
    assert "too many bad API tokens" in response.get_data(as_text=True)
    right = client.get(path, headers=bearer(tokens["admin"]))  # the page (/login: on to the dashboard)
    assert right.status_code == (302 if path == "/login" else 200)


def test_a_client_throttled_on_the_api_gets_a_429_page_not_a_500(app) -> None:  # type: ignore[no-untyped-def]
    client = from_address(app, "192.0.2.1")
    for _ in range(5):
        client.get("/api/v1/me", headers=bearer("ist_guess"))
    for path in ("/login", "/"):  # the error page asks who is logged in: it must not throttle again
        response = client.get(path, headers=bearer("ist_guess"))
        assert response.status_code == 429 and "<h1>429</h1>" in response.get_data(as_text=True)


def test_apps_count_in_their_own_storage(app, settings, runtime, tmp_path, waits) -> None:  # type: ignore[no-untyped-def]
    """Two apps in one process (the suite runs many) count in their own storage: a workspace of its own
    (its ratelimit.db) does not see the other's failures; one deployment's Redis under one queue name does."""
    from webapp.app import create_app

    other = create_app(settings.model_copy(update={"home": tmp_path / "other"}), runtime)
    for _ in range(3):
        assert login(from_address(app, "203.0.113.9"), "admin", "wrong-password").status_code == 401
    assert login(from_address(app, "203.0.113.9"), "admin").status_code == 429
    shared = settings.queue_url.startswith("redis://")
    assert login(from_address(other, "203.0.113.9"), "admin").status_code == (429 if shared else 302)


def test_slowed_logins_wait_two_per_address_and_on_half_the_threads(app, waits, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """A slowed login past its address's two waiting slots, or past the server's (half of `serve`'s 8
    threads), is told to come back, with no wait and no password check; other addresses' still wait."""
    from webapp import throttle

    monkeypatch.setattr(throttle.LoginCounters, "wait_s", lambda self, settings: 3.0)
    slots = throttle.waiting_logins(app)
    assert slots.at_once == 4
    with ExitStack() as held:
        assert all(held.enter_context(slots.slot("203.0.113.9")) for _ in range(2))
        answer = login(from_address(app, "203.0.113.9"), "admin")
        assert answer.status_code == 429 and answer.headers["Retry-After"] == "3"
        assert "try again in 3 seconds" in answer.get_data(as_text=True)
        assert waits == []
        assert login(from_address(app, "198.51.100.7"), "admin").status_code == 302 and waits == [3.0]
        assert all(held.enter_context(slots.slot(f"192.0.2.{i}")) for i in range(2))
        assert login(from_address(app, "198.51.100.7"), "admin").status_code == 429 and waits == [3.0]
    assert login(from_address(app, "203.0.113.9"), "admin").status_code == 302 and waits == [3.0, 3.0]


def test_the_waiting_slots_follow_the_servers_threads(app, settings, runtime) -> None:  # type: ignore[no-untyped-def]
    """Each app has its own slots, sized for its server: a second app in the process (the suite runs
    many) leaves the first's alone."""
    from webapp import throttle
    from webapp.app import create_app

    assert throttle.WaitingLogins.for_server(16).at_once == 8
    small = throttle.waiting_logins(create_app(settings, runtime, threads=1))
    with small.slot("203.0.113.9") as first, small.slot("198.51.100.7") as second:
        assert first and not second
    assert throttle.waiting_logins(app).at_once == 4


def test_a_new_login_ends_the_browsers_old_session_on_the_server(app) -> None:  # type: ignore[no-untyped-def]
    first = app.test_client()
    assert login(first, "curator").status_code == 302
    copied = app.test_client()  # someone copied the first session's cookie
    copied.set_cookie("session", first.get_cookie("session").value)
    assert copied.get("/api/v1/me").status_code == 200
    token = csrf_from(first.get("/").get_data(as_text=True))  # logged in, /login redirects: post to it
    again = first.post("/login", data={"name": "annotator", "password": PASSWORD, "csrf_token": token})
    assert again.status_code == 302 and first.get("/api/v1/me").json["name"] == "annotator"
    assert copied.get("/api/v1/me").status_code == 401
