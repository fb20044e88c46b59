"""How much of a request's body the server reads before a worker takes it, judged from its head alone.

The server (:mod:`webapp.server`) reads every body up to ``READ_AHEAD_BYTES`` in its selector thread
before a worker sees the request. A larger body is read ahead whole only when the request names a route
that takes it and carries the credentials of a role that route serves — a bearer token or a session
cookie that is still live on the server — and then up to the route's own limit (:mod:`webapp.bodies`).
Anyone else's large body is answered (401, 403, 413) from its first bytes, as before. The worker then
repeats every check on the request itself: this decides only what the server buffers.

Credentials are looked up in the database at most once per :data:`CACHE_S` each (a small LRU of
digests, so a token's secret is not kept in memory), and only for bodies over the read-ahead: an
upload, a draft, a large segment call.
"""

from __future__ import annotations

import hashlib
import logging
import threading
import time
from collections import OrderedDict
from datetime import timedelta
from urllib.parse import unquote, urlsplit

from flask import Flask
from itsdangerous import BadSignature
from werkzeug.exceptions import HTTPException
from werkzeug.http import parse_cookie
from werkzeug.routing import RequestRedirect

from dataset.services import sessions as session_service
from dataset.services import users as user_service
from dataset.settings import Settings
from dataset.tables import Role
from webapp.auth import PUBLIC, ROLE_ATTR, SESSION_ID
from webapp.bodies import body_limit
from webapp.runtime import Runtime
from webapp.server import READ_AHEAD_BYTES, Admit

log = logging.getLogger(__name__)
CACHE_S = 30.0  # a credential's role is looked up again after this long
CACHE_ENTRIES = 4096


class _RoleCache:
    """Credential digest → (role or None, when looked up); thread-safe, least recently used out first."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._roles: OrderedDict[bytes, tuple[Role | None, float]] = OrderedDict()

    def get(self, key: bytes) -> tuple[bool, Role | None]:
        with self._lock:
            found = self._roles.get(key)
            if found is None or time.monotonic() - found[1] > CACHE_S:
                return False, None
            self._roles.move_to_end(key)
            return True, found[0]

    def put(self, key: bytes, role: Role | None) -> None:
        with self._lock:
            self._roles[key] = (role, time.monotonic())
            self._roles.move_to_end(key)
            while len(self._roles) > CACHE_ENTRIES:
                self._roles.popitem(last=False)


def parse_head(head: bytes) -> tuple[str, str, dict[str, str]]:
    """A request's line and headers → (method, decoded path, headers by lower-case name)."""
    lines = head.decode("latin-1").split("\r\n")
    method, target = (lines[0].split(" ") + ["", ""])[:2]
    headers: dict[str, str] = {}
    for line in lines[1:]:
        name, _, value = line.partition(":")
        headers[name.strip().lower()] = value.strip()
    return method, unquote(urlsplit(target).path), headers


def make_admission(app: Flask, settings: Settings, rt: Runtime) -> Admit:
    """The server's :data:`~webapp.server.Admit` for ``app``: the route's body limit for a request whose
    credentials allow the route, else what the server reads of any body."""
    cache = _RoleCache()
    idle = timedelta(minutes=settings.session_idle_minutes)
    lifetime = timedelta(hours=settings.session_lifetime_hours)
    cookie_name = app.config["SESSION_COOKIE_NAME"]
    signer = app.session_interface.get_signing_serializer(app)  # type: ignore[attr-defined]

    def role_of(headers: dict[str, str]) -> Role | None:
        scheme, _, token = headers.get("authorization", "").partition(" ")
        if scheme.lower() == "bearer" and token.strip():
            key = b"t" + hashlib.sha256(token.strip().encode()).digest()
            lookup = lambda db: user_service.user_for_token(db, token.strip())
        else:
            value = parse_cookie(headers.get("cookie", "")).get(cookie_name)
            if not value or signer is None:
                return None
            try:
                sid = signer.loads(value).get(SESSION_ID)
            except (BadSignature, ValueError, AttributeError):
                return None
            if not isinstance(sid, str):
                return None
            key = b"s" + hashlib.sha256(sid.encode()).digest()
            lookup = lambda db: session_service.user_for_session(db, sid, idle=idle, lifetime=lifetime)
        known, role = cache.get(key)
        if not known:
            with rt.sessions() as db:
                user = lookup(db)
                role = user.role if user is not None else None
                db.rollback()  # the worker keeps the session's and token's last-used times
            cache.put(key, role)
        return role

    def admit(head: bytes) -> int:
        try:
            method, path, headers = parse_head(head)
            endpoint, _ = app.url_map.bind("localhost").match(path, method=method)
            required = getattr(app.view_functions.get(endpoint), ROLE_ATTR, None)
            if required is None or required == PUBLIC:
                return READ_AHEAD_BYTES
            role = role_of(headers)
            if role is None or not role.allows(Role(required)):
                return READ_AHEAD_BYTES
            return body_limit(app, endpoint, settings)
        except (HTTPException, RequestRedirect):  # no such route or method: answered from the head
            return READ_AHEAD_BYTES
        except Exception:  # the worker judges the request anyway; never let the selector thread die
            log.exception("judging a request's body from its head failed")
            return READ_AHEAD_BYTES

    return admit
