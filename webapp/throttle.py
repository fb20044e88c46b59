"""Login and API-token throttling: refuse the guesser, slow the target down, never lock its owner out.

Logins (the spirit of OWASP ASVS V2.2). Failed logins are counted per (user name, address), per
user name and per address. Past ``login_limit_per_account_address`` that address gets 429 with
``Retry-After`` for that name, its password unchecked: the guesser is refused. The pair's count
goes up as an attempt's password is about to be checked, in the same atomic step that tests the
limit (a right password then clears it), so however many connections guess in parallel, no more
than the limit have their passwords checked. The wider counters never refuse, since anyone could
drive them up; past them a login waits before its password is checked, 0.25 s doubling with each
further failure up to ``login_slowdown_max_s``, right or wrong password alike (the wait tells
nothing), then succeeds or fails as usual:

- past ``login_slowdown_per_address`` (one address, all names), every login from that address;
- past ``login_slowdown_per_account`` (one name, all addresses), the logins for that name from
  addresses that have themselves tried it (in the pair counter's window). An address that has
  not is not made to wait for the others' failures. Making it wait would need a thread for the
  wait, and so a cap on waiting logins that strangers can fill (with many addresses if the cap
  is per address), so the owner's login would be refused after all. What the exemption gives a
  guesser is one unslowed guess per name per address and window; a second waits, and the pair's
  limit refuses it soon after.

Device cookies (OWASP's "Slow Down Online Guessing Attacks with Device Cookies"). A successful
login leaves the browser a cookie for that user: the user name and a random nonce, signed with
the app's secret key as Flask signs its session cookie (itsdangerous; the signature carries the
time of issue), HttpOnly, SameSite=Lax, Secure when the app is served over HTTPS (``https``),
sent back only to the login page and valid for ``login_device_cookie_days`` (365; 0 turns device
cookies off). A later login for that name carrying it is trusted: it is counted only against
that cookie, never against the pair, name or address counters, and no one's failures slow it
down or refuse it, so it needs no waiting slot. The cookie has its own limit, the pair's
(``login_limit_per_account_address`` failures in its window), counted as the pair's is; past
it the cookie is locked and its logins count as untrusted until the window ends. Each successful
login issues a new cookie (a new nonce), so a copy of an old one keeps its own failures.

So a stranger can slow an account down but not lock its owner out: the owner's right password is
neither refused nor slowed by anyone else's failures when it comes with the device cookie of an
earlier login in that browser, or from an address that has not itself tried the name lately.
A client without a device cookie should expect, while others flood the login page:

- from an address that has not tried the name (and is not the flood's): no wait and no refusal;
  its answer comes later than usual only because every request waits its turn for a server
  thread and for the CPU (measured with one address's 16 connections flooding, on two cores:
  0.2 s instead of 0.12 s in the median, against 0.18 s under a flood of the cheapest page);
- from an address that has tried it (a mistyped password within the window), or that the flood
  shares (one NAT or proxy): a wait of up to ``login_slowdown_max_s`` before its password is
  checked, or, while the flood holds the waiting slots, 429 with ``Retry-After`` at once, very
  likely again on each retry until the flood stops. A device cookie is the way past it.

A waiting login holds a server thread, so waits are capped (:class:`WaitingLogins`): at most
:data:`WAITING_PER_ADDRESS` per client address — one address cannot hold more, however many
connections it opens — and, of all addresses, half the server's threads, so other routes (and
logins that need not wait) keep answering. A slowed login past either cap is answered 429 at
once, its password unchecked. The caps count this process's threads, so they live in memory.
A flood's refused logins check no password, and so hash none; its waiting logins hash one each
after its wait: two per address per wait, at most half the server's threads' worth in all. Those
hashes compete for the CPU (and scrypt's memory) with the logins let through, so a shorter
``login_slowdown_max_s`` costs them: at 1 s instead of the default 4 s, the clean logins in the
flood above took about 3 times (up to 5 times) as long as quiet ones instead of 1.7 times. A
refusal is answered with a one-paragraph page rather than the login form: a third less work for
each of the hundreds of refusals a second that a flood gets.

Addresses are the clients' as :mod:`webapp.proxies` resolves them behind ``trusted_proxies``; an
IPv6 client counts by its /64 network, since a machine or household gets a whole /64 and would
otherwise have 2^64 fresh counters.

API tokens. A right token always passes. A bad one is counted per address and, when it names a
token (``ist_<id>_…``), per account; past either limit bad tokens get 429 instead of 401. Others'
bad tokens from the same proxy therefore never lock a script out. The secrets are 256-bit: the
limit makes guessing visible and cheap to refuse, it does not guard a guessable secret.

Storage: the deployment's Redis when the queue runs on Redis; otherwise a small SQLite file in the
data dir (:class:`SqliteLimitStorage`). The counters are `limits`' fixed windows, used directly: these
are counters a login consults, not limits on routes, so Flask-Limiter's decorators (built on the same
package) have nothing to add. The `limits` package ships memory, Redis, Memcached and
MongoDB storages; memory counts per process (a multi-process server would multiply every limit)
and the other two are services this app does not otherwise need, whereas a SQLite file is shared
by every process on the machine, like the default job queue. While the counters are unreachable
(Redis down) throttling is skipped: an outage of the counters must not lock everyone out, and the
requests that need the queue on that Redis answer 503 anyway.
"""
from __future__ import annotations

import hashlib
import ipaddress
import logging
import math
import secrets
import sqlite3
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, TypeVar

from flask import Flask, Response, current_app, request
from itsdangerous import BadData, URLSafeTimedSerializer
from limits import RateLimitItem, parse
from limits.storage import Storage, storage_from_string
from limits.strategies import FixedWindowRateLimiter

from dataset.settings import Settings
from webapp.proxies import TrustedProxies, parse_address

log = logging.getLogger(__name__)
T = TypeVar("T")
FIRST_WAIT_S = 0.25  # the first slowed-down login's wait; each further failure doubles it
WAITING_PER_ADDRESS = 2  # slowed logins one client address may have waiting at once (a double-clicked form: 2)
DEFAULT_SERVER_THREADS = 8  # `serve --threads`' default
DEVICE_COOKIE_PREFIX = "device_"  # then a digest of the user name: one cookie per user of a browser
DEVICE_COOKIE_SALT = "login-device"  # itsdangerous salt: no other cookie's signature passes for a device cookie's


def client_key() -> str:
    """The address this request's failures count under: the client's (``REMOTE_ADDR``, which
    :mod:`webapp.proxies` resolved), an IPv6 one as its /64 network."""
    text = request.remote_addr or ""
    address = parse_address(text)
    if address is None:
        return text  # not an IP address (a Unix socket's peer): counted as the server reports it
    if address.version == 6:
        return str(ipaddress.ip_network(f"{address}/64", strict=False))
    return str(address)


class WaitingLogins:
    """The slowed logins one app has waiting: at most ``per_address`` for one client address and
    ``at_once`` in all (a wait holds a server thread)."""

    def __init__(self, at_once: int, per_address: int = WAITING_PER_ADDRESS) -> None:
        self.at_once = at_once
        self.per_address = per_address
        self._lock = threading.Lock()
        self._waiting: dict[str, int] = {}

    @contextmanager
    def slot(self, address: str) -> Iterator[bool]:
        """True inside while ``address`` holds one of the slots; False (nothing held) when a cap is reached."""
        with self._lock:
            held = self._waiting.get(address, 0)
            granted = held < self.per_address and sum(self._waiting.values()) < self.at_once
            if granted:
                self._waiting[address] = held + 1
        try:
            yield granted
        finally:
            if granted:
                with self._lock:
                    if (left := self._waiting[address] - 1) > 0:
                        self._waiting[address] = left
                    else:
                        del self._waiting[address]


    @classmethod
    def for_server(cls, threads: int) -> WaitingLogins:
        """Slots for a server of ``threads`` worker threads: slowed logins wait on at most half (at least one)."""
        return cls(at_once=max(1, threads // 2))


def waiting_logins(app: Flask | None = None) -> WaitingLogins:
    """``app``'s (default: the current app's) slots for slowed logins, sized by :func:`init_throttle`."""
    return (app or current_app).extensions["waiting_logins"]  # type: ignore[no-any-return]


def _counters() -> FixedWindowRateLimiter:
    """The current app's fixed-window counters, in its storage (:func:`init_throttle`)."""
    return current_app.extensions["rate_limiter"]  # type: ignore[no-any-return]


@dataclass(frozen=True)
class Counter:
    """One fixed-window counter of failures (or attempts): its limit and what it counts for (``key``)."""

    limit: RateLimitItem
    key: tuple[str, ...]

    def count(self) -> int:
        return _counters().storage.get(self.limit.key_for(*self.key))

    def exceeded(self) -> bool:
        return self.count() >= self.limit.amount

    def hit(self) -> None:
        _counters().hit(self.limit, *self.key)

    def attempt(self) -> bool:
        """Count one more and say whether that kept within the limit: one atomic step in the storage,
        so of parallel requests that all found room before any counted, only the limit's number pass."""
        return _counters().hit(self.limit, *self.key)

    def clear(self) -> None:
        _counters().clear(self.limit, *self.key)

    def retry_after(self) -> int:
        """Whole seconds until this window ends (at least 1)."""
        reset = _counters().get_window_stats(self.limit, *self.key).reset_time
        return max(1, int(reset - time.time()) + 1)


def _unless_down(what: str, default: T, action: Callable[[], T]) -> T:
    """``action()``, or ``default`` while the counters' storage is unreachable (logged)."""
    try:
        return action()
    except Exception:  # redis.ConnectionError, sqlite3.Error …: the storage is down
        log.warning("%s skipped: the throttle's counters are unreachable", what, exc_info=True)
        return default


@dataclass(frozen=True)
class LoginCounters:
    """The three counters a login attempt for one name from one address (``client``) touches."""

    client: str
    pair: Counter
    account: Counter
    address: Counter

    @classmethod
    def of(cls, settings: Settings, name: str) -> LoginCounters:
        """Counters for user name ``name`` (case and surrounding spaces ignored) from this request's address."""
        name, client, scope = normal_name(name), client_key(), settings.queue_name
        return cls(client=client,
                   pair=Counter(parse(settings.login_limit_per_account_address), (scope, "login", name, client)),
                   account=Counter(parse(settings.login_slowdown_per_account), (scope, "login-account", name)),
                   address=Counter(parse(settings.login_slowdown_per_address), (scope, "login-address", client)))

    def refused(self) -> int | None:
        """Seconds until this address may try this name again, once it failed too often; else None.
        A quick look, so that a refused pair takes no waiting slot; :meth:`admit` is the binding test."""
        return _unless_down("login throttling", None,
                            lambda: self.pair.retry_after() if self.pair.exceeded() else None)

    def admit(self) -> int | None:
        """Count this attempt for (name, address) just before its password is checked, in the same
        atomic step as the test of the limit, so parallel connections cannot all pass a look taken
        before any of them failed. Seconds until this address may try this name again when this one
        was past the limit (its password unchecked), else None."""
        return _unless_down("login throttling", None,
                            lambda: None if self.pair.attempt() else self.pair.retry_after())

    def wait_s(self, settings: Settings) -> float:
        """How long this attempt waits: 0 until the address's failures, or the name's when this
        address has tried it too (its pair count, cleared by a success), reach their slow-down limit;
        then 0.25 s doubling with each further failure, at most ``login_slowdown_max_s``."""
        def wait() -> float:
            counters = (self.address, self.account) if self.pair.count() else (self.address,)
            beyond = max(c.count() - c.limit.amount for c in counters)
            return 0.0 if beyond < 0 else min(settings.login_slowdown_max_s, FIRST_WAIT_S * 2.0 ** min(beyond, 32))

        return _unless_down("login slow-down", 0.0, wait)

    def slow_down(self, settings: Settings) -> int | None:
        """Wait :meth:`wait_s` before the password is checked (a plain sleep: no lock is held), in
        one of :func:`waiting_logins`' slots; when this address's or the server's are all taken,
        return the seconds to come back after instead (no wait), so waits cannot hold every thread."""
        if (seconds := self.wait_s(settings)) <= 0:
            return None
        with waiting_logins().slot(self.client) as granted:
            if not granted:
                return max(1, math.ceil(seconds))
            time.sleep(seconds)
        return None

    def failed(self) -> None:
        """Count a wrong password for the name and for the address (:meth:`admit` counted the pair)."""
        def hit() -> None:
            for counter in (self.account, self.address):
                counter.hit()

        _unless_down("counting a failed login", None, hit)

    def succeeded(self) -> None:
        """The owner got in from here: this address's failures for the name are forgotten. The
        wider counters stay, or a guesser could clear them by logging into an account of their own."""
        _unless_down("clearing a login's failures", None, self.pair.clear)


def normal_name(name: str) -> str:
    """A user name as the counters and device cookies know it: case and surrounding spaces ignored."""
    return name.strip().lower()


def device_cookie_name(name: str) -> str:
    """The cookie that holds this browser's device cookie for user ``name``: one per user, so people
    who share a browser each keep theirs."""
    return DEVICE_COOKIE_PREFIX + hashlib.sha256(normal_name(name).encode()).hexdigest()[:16]


def _device_serializer() -> URLSafeTimedSerializer:
    """Signs with the app's secret key (old keys in SECRET_KEY_FALLBACKS still verify), as Flask's session cookie."""
    keys = [*(current_app.config.get("SECRET_KEY_FALLBACKS") or ()), current_app.secret_key]
    return URLSafeTimedSerializer(keys, salt=DEVICE_COOKIE_SALT, signer_kwargs={"digest_method": hashlib.sha256})


def device_counter(settings: Settings, name: str) -> Counter | None:
    """The failure counter of the device cookie for ``name`` that this request carries, when it is
    one this app signed for that name no longer than ``login_device_cookie_days`` ago; else None."""
    max_age = settings.login_device_cookie_days * 86400
    raw = request.cookies.get(device_cookie_name(name)) if max_age else None
    if not raw:
        return None
    try:
        owner, nonce = _device_serializer().loads(raw, max_age=max_age)
    except (BadData, ValueError, TypeError):  # forged, expired, or not a pair
        return None
    if owner != normal_name(name) or not isinstance(nonce, str):
        return None
    return Counter(parse(settings.login_limit_per_account_address), (settings.queue_name, "login-device", nonce))


def set_device_cookie(response: Response, settings: Settings, name: str, path: str) -> None:
    """Give this browser a new device cookie for user ``name``, sent back only to ``path`` (the login
    page's): the user name, a random nonce and, in the signature, the time of issue. A new nonce
    each login, so the failures counted against an old cookie stay with it."""
    if not (days := settings.login_device_cookie_days):
        return
    value = _device_serializer().dumps([normal_name(name), secrets.token_urlsafe(16)])
    response.set_cookie(device_cookie_name(name), value, max_age=days * 86400, path=path,
                        secure=current_app.config["SESSION_COOKIE_SECURE"], httponly=True, samesite="Lax")


@dataclass(frozen=True)
class Refusal:
    """A login answered 429 with its password unchecked: come back after ``retry_after`` seconds."""

    retry_after: int
    busy: bool  # the waiting slots were taken (else this address failed too often for this name)


@dataclass(frozen=True)
class LoginAttempt:
    """One login's throttling: from a browser with a trusted device cookie for the name (``device``,
    its counter: nothing else counts or slows it), or untrusted (``counters``)."""

    counters: LoginCounters
    device: Counter | None

    @classmethod
    def start(cls, settings: Settings, name: str) -> LoginAttempt:
        """This request's attempt at ``name``. A device cookie's attempt is counted here, before the
        password is checked (atomically, as :meth:`LoginCounters.admit`); past its limit the cookie
        is not trusted until its window ends, and the attempt goes the untrusted way."""
        device = device_counter(settings, name)
        if device is not None and not _unless_down("device cookie throttling", True, device.attempt):
            device = None
        return cls(LoginCounters.of(settings, name), device)

    @property
    def trusted(self) -> bool:
        """The request carries a valid device cookie for the name, not locked."""
        return self.device is not None

    def refusal(self, settings: Settings) -> Refusal | None:
        """Why this attempt is answered 429 with its password unchecked; None once it may be checked
        (an untrusted one after its slow-down, and then counted)."""
        if self.trusted:
            return None
        if (wait := self.counters.refused()) is not None:
            return Refusal(wait, busy=False)
        if (busy := self.counters.slow_down(settings)) is not None:
            return Refusal(busy, busy=True)
        if (wait := self.counters.admit()) is not None:
            return Refusal(wait, busy=False)
        return None

    def failed(self) -> None:
        """A wrong password: a trusted device's failure was counted against the cookie alone."""
        if not self.trusted:
            self.counters.failed()

    def succeeded(self) -> None:
        """The right password: this address's attempts at the name are forgotten (see :meth:`LoginCounters.succeeded`)."""
        self.counters.succeeded()


# One answer for both token limits: which one was hit would tell a guesser which token ids exist.
TOKEN_LIMIT_MESSAGE = "too many bad API tokens; try again later"


def _token_counters(settings: Settings, account: int | None) -> list[Counter]:
    """Bad tokens from this address and, when the token names one, for its account."""
    scope = settings.queue_name
    counters = [Counter(parse(settings.token_limit_per_address), (scope, "token", client_key()))]
    if account is not None:
        counters.append(Counter(parse(settings.token_limit_per_account), (scope, "token-account", str(account))))
    return counters


def bad_token(settings: Settings, account: int | None) -> int | None:
    """Count a refused bearer token; returns the seconds to wait when this address, or the account
    ``account`` it named, was already past its limit (answer 429), else None (answer 401)."""
    def count() -> int | None:
        counters = _token_counters(settings, account)
        for counter in counters:
            if counter.exceeded():
                return counter.retry_after()
        for counter in counters:
            counter.hit()
        return None

    return _unless_down("token throttling", None, count)


def storage_uri(settings: Settings) -> str:
    if settings.queue_url.startswith(("redis://", "rediss://")):
        return settings.queue_url
    return f"{SqliteLimitStorage.STORAGE_SCHEME[0]}:///{settings.home / 'ratelimit.db'}"


def init_throttle(app: Flask, settings: Settings, threads: int = DEFAULT_SERVER_THREADS) -> None:
    """Counters in :func:`storage_uri`'s storage, for clients resolved behind ``trusted_proxies``; slots
    for the slowed logins of a server of ``threads`` worker threads. Both are the app's own: several
    apps in one process (the tests) neither share them nor take over each other's storage."""
    app.extensions["rate_limiter"] = FixedWindowRateLimiter(storage_from_string(storage_uri(settings)))
    app.extensions["waiting_logins"] = WaitingLogins.for_server(threads)
    app.wsgi_app = TrustedProxies(app.wsgi_app, settings.trusted_proxies)  # type: ignore[method-assign]


class SqliteLimitStorage(Storage):
    """Fixed-window counters in one SQLite file (WAL), shared by the processes of one machine."""

    STORAGE_SCHEME = ["illusion+sqlite"]

    def __init__(self, uri: str, wrap_exceptions: bool = False, **options: Any) -> None:
        super().__init__(uri, wrap_exceptions=wrap_exceptions, **options)
        self.path = uri.split(":///", 1)[1]
        self._local = threading.local()
        db = self._db()
        db.execute("create table if not exists counters (key text primary key, count integer not null,"
                   " expires real not null)")
        db.execute("delete from counters where expires <= ?", (time.time(),))  # windows long over

    @property
    def base_exceptions(self) -> type[Exception]:
        return sqlite3.Error

    def _db(self) -> sqlite3.Connection:
        conn = getattr(self._local, "conn", None)
        if conn is None:
            conn = sqlite3.connect(self.path, timeout=10, isolation_level=None)
            conn.execute("pragma journal_mode=wal")
            self._local.conn = conn
        return conn

    def incr(self, key: str, expiry: int, amount: int = 1) -> int:
        now = time.time()
        db = self._db()
        # One statement: a window that ran out starts again at ``amount``, else it adds up.
        return db.execute(
            "insert into counters (key, count, expires) values (?, ?, ?) on conflict(key) do update set"
            " count = case when expires <= ? then excluded.count else count + excluded.count end,"
            " expires = case when expires <= ? then excluded.expires else expires end returning count",
            (key, amount, now + expiry, now, now)).fetchone()[0]

    def get(self, key: str) -> int:
        row = self._db().execute("select count from counters where key = ? and expires > ?",
                                 (key, time.time())).fetchone()
        return row[0] if row else 0

    def get_expiry(self, key: str) -> float:
        row = self._db().execute("select expires from counters where key = ?", (key,)).fetchone()
        return row[0] if row and row[0] > time.time() else time.time()

    def check(self) -> bool:
        self._db().execute("select 1")
        return True

    def reset(self) -> int | None:
        return self._db().execute("delete from counters").rowcount

    def clear(self, key: str) -> None:
        self._db().execute("delete from counters where key = ?", (key,))
