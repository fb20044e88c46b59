"""Login and API-token throttling with Flask-Limiter: failures per account and per address answer 429.

Storage: the deployment's Redis when the queue runs on Redis; otherwise a small SQLite file in the
data dir (:class:`SqliteLimitStorage`). The `limits` package ships memory, Redis, Memcached and
MongoDB storages; memory counts per process (a multi-process server would multiply every limit)
and the other two are services this app does not otherwise need, whereas a SQLite file is shared
by every process on the machine, like the default job queue.
"""

from __future__ import annotations

import logging
import sqlite3
import threading
import time
from typing import Any

from flask import Flask, current_app, request
from flask_limiter import Limiter
from flask_limiter.util import get_remote_address
from limits import RateLimitItem, parse
from limits.storage import Storage

from dataset.settings import Settings

log = logging.getLogger(__name__)
limiter = Limiter(key_func=get_remote_address)


def _failed(response: Any) -> bool:
    return response.status_code == 401


def _login_account() -> str:
    return "account:" + request.form.get("name", "").strip().lower()


def _setting(name: str) -> str:
    return getattr(current_app.extensions["runtime"].settings, name)


def limit_login(view: Any) -> Any:
    """Throttle a login view: only answers 401 (wrong name or password) count."""
    view = limiter.limit(lambda: _setting("login_limit_per_account"), key_func=_login_account, methods=["POST"],
                         deduct_when=_failed, error_message="too many failed logins for this account")(view)
    return limiter.limit(lambda: _setting("login_limit_per_address"), methods=["POST"], deduct_when=_failed,
                         error_message="too many failed logins from this address")(view)


# One answer for both limits: which one was hit would tell a guesser which token ids exist.
TOKEN_LIMIT_MESSAGE = "too many bad API tokens; try again later"


def _token_limits(settings: Settings, account: int | None) -> list[tuple[RateLimitItem, tuple[str, str]]]:
    """(limit, counter key) for this address and, when the token names one, its account."""
    checks = [(parse(settings.token_limit_per_address), ("token", get_remote_address()))]
    if account is not None:
        checks.append((parse(settings.token_limit_per_account), ("token-account", str(account))))
    return checks


def token_blocked(settings: Settings, account: int | None) -> int | None:
    """Seconds to wait when this address, or the account ``account`` a token named, may not try a
    bearer token again yet; else None.

    Fails open while the counters' storage is unreachable (Redis down), as the login limits do
    (``RATELIMIT_SWALLOW_ERRORS``): an outage of the counters must not lock every script out, and
    the requests that need the queue on that Redis answer 503 anyway."""
    try:
        for item, key in _token_limits(settings, account):
            if not limiter.limiter.test(item, *key):
                reset = limiter.limiter.get_window_stats(item, *key).reset_time
                return max(1, int(reset - time.time()) + 1)
    except Exception:  # redis.ConnectionError, sqlite3.Error …: the storage is down
        log.warning("token throttling skipped: its counters are unreachable", exc_info=True)
    return None


def count_bad_token(settings: Settings, account: int | None) -> None:
    """Count a refused bearer token against this address and, when it named one, its account."""
    try:
        for item, key in _token_limits(settings, account):
            limiter.limiter.hit(item, *key)
    except Exception:  # see token_blocked
        log.warning("a bad token went uncounted: the throttle's counters are unreachable", exc_info=True)


def storage_uri(settings: Settings) -> str:
    if settings.queue_url.startswith(("redis://", "rediss://")):
        return settings.queue_url
    return f"{SqliteLimitStorage.STORAGE_SCHEME[0]}:///{settings.home / 'ratelimit.db'}"


def init_throttle(app: Flask, settings: Settings) -> None:
    app.config.update(RATELIMIT_STORAGE_URI=storage_uri(settings), RATELIMIT_STRATEGY="fixed-window",
                      RATELIMIT_HEADERS_ENABLED=True, RATELIMIT_SWALLOW_ERRORS=True,
                      RATELIMIT_KEY_PREFIX=f"{settings.queue_name}:limits")
    limiter.init_app(app)


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
