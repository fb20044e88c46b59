"""The client's address behind trusted proxies: X-Forwarded-For is read only from a peer in
``trusted_proxies``, right to left past trusted addresses, so a client cannot name its own address,
and clients behind a trusted proxy are counted apart."""

from __future__ import annotations

import ipaddress
import logging
from pathlib import Path

import pytest

from dataset.db import migrate
from dataset.settings import Settings
from tests.conftest import login, make_settings
from webapp.proxies import client_address

PROXIES = [ipaddress.ip_network(n) for n in ("127.0.0.1/32", "10.0.0.0/8", "::1/128")]


@pytest.mark.parametrize(("peer", "forwarded_for", "client"), [
    ("203.0.113.9", "198.51.100.7", "203.0.113.9"),  # not a proxy: its header is the client's own words
    ("127.0.0.1", "198.51.100.7", "198.51.100.7"),
    ("127.0.0.1", "", "127.0.0.1"),  # a trusted peer without the header is the client
    ("127.0.0.1", "6.6.6.6, 198.51.100.7, 10.0.0.2", "198.51.100.7"),  # past the proxies; the made-up left part unread
    ("127.0.0.1", "10.0.0.3, 10.0.0.2", "10.0.0.3"),  # every hop trusted: the leftmost
    ("127.0.0.1", "198.51.100.7, not-an-address", "127.0.0.1"),  # garbage: the trusted hop that wrote it
    ("127.0.0.1", "not-an-address, 10.0.0.2", "10.0.0.2"),
    ("::ffff:127.0.0.1", "198.51.100.7", "198.51.100.7"),  # an IPv4-mapped peer on a dual-stack socket
    ("::1", "2001:db8::5", "2001:db8::5"),
    ("unix", "198.51.100.7", "unix"),  # not an IP address: never a proxy
])
def test_the_client_is_the_rightmost_address_outside_the_trusted_proxies(peer: str, forwarded_for: str,
                                                                          client: str) -> None:
    assert client_address(peer, forwarded_for, PROXIES) == client


@pytest.fixture
def settings(request: pytest.FixtureRequest, tmp_path: Path) -> Settings:
    """Small login limits; ``trusted_proxies`` as the test's parameter names it (none by default)."""
    s = make_settings(tmp_path / "ws", login_limit_per_account_address="3 per 15 minutes",
                      trusted_proxies=getattr(request, "param", []))
    migrate(s.database_url)
    return s


def behind(app, peer: str, forwarded_for: str | None = None):  # type: ignore[no-untyped-def]
    client = app.test_client()
    client.environ_base["REMOTE_ADDR"] = peer
    if forwarded_for is not None:
        client.environ_base["HTTP_X_FORWARDED_FOR"] = forwarded_for
    return client


def test_without_trusted_proxies_a_guesser_cannot_name_a_fresh_address(app, caplog) -> None:  # type: ignore[no-untyped-def]
    caplog.set_level(logging.WARNING, logger="webapp.proxies")
    for i in range(3):
        assert login(behind(app, "203.0.113.9", f"198.51.100.{i}"), "admin", "wrong-password").status_code == 401
    assert login(behind(app, "203.0.113.9", "198.51.100.99"), "admin").status_code == 429
    warnings = [r.getMessage() for r in caplog.records if r.name == "webapp.proxies"]
    assert len(warnings) == 1 and "trusted_proxies is empty" in warnings[0]  # said once, not per request


@pytest.mark.parametrize("settings", [["192.0.2.0/24"]], indirect=True)
def test_clients_behind_a_trusted_proxy_are_counted_apart(app) -> None:  # type: ignore[no-untyped-def]
    for _ in range(3):
        assert login(behind(app, "192.0.2.1", "203.0.113.9"), "admin", "wrong-password").status_code == 401
    assert login(behind(app, "192.0.2.1", "203.0.113.9"), "admin").status_code == 429  # the guesser
    assert login(behind(app, "192.0.2.1", "198.51.100.7"), "admin").status_code == 302  # the owner, same proxy
    # a guesser writing its own header ahead of the proxy's is counted by what the proxy saw
    assert login(behind(app, "192.0.2.1", "198.51.100.7, 203.0.113.9"), "admin").status_code == 429
