"""Users, passwords and API tokens."""

from __future__ import annotations

import hashlib
import re
import secrets
from datetime import timedelta
from functools import cache

from sqlalchemy import select
from sqlalchemy.orm import Session
from werkzeug.security import check_password_hash, generate_password_hash

from dataset.models import ApiToken, Role, User, utcnow
from dataset.services.errors import Conflict, InvalidInput, NotFound

_NAME = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")
MIN_PASSWORD = 8


def parse_role(value: str) -> Role:
    try:
        return Role(value)
    except ValueError:
        raise InvalidInput(f"unknown role {value!r}; choose one of {', '.join(Role)}") from None


def create_user(session: Session, name: str, role: Role | str, password: str) -> User:
    """Add a user; rejects bad names, short passwords, unknown roles and duplicates."""
    role = parse_role(role) if isinstance(role, str) else role
    if not _NAME.match(name):
        raise InvalidInput("user name must be 1-64 letters, digits, '.', '_' or '-'")
    if len(password) < MIN_PASSWORD:
        raise InvalidInput(f"password must have at least {MIN_PASSWORD} characters")
    if session.scalar(select(User.id).where(User.name == name)) is not None:
        raise Conflict(f"user {name!r} already exists")
    user = User(name=name, role=role, password_hash=generate_password_hash(password))
    session.add(user)
    session.flush()
    return user


def get_user(session: Session, name: str) -> User:
    user = session.scalar(select(User).where(User.name == name))
    if user is None:
        raise NotFound(f"no user named {name!r}")
    return user


def authenticate(session: Session, name: str, password: str) -> User | None:
    """The active user with this name and password, else None (no hint which part was wrong)."""
    user = session.scalar(select(User).where(User.name == name))
    # Hash even for unknown names, so the answer's timing does not tell which names exist.
    ok = check_password_hash(user.password_hash if user else _dummy_hash(), password)
    return user if user is not None and user.active and ok else None


@cache
def _dummy_hash() -> str:
    return generate_password_hash("not anyone's password")


def _token_digest(token: str) -> str:
    return hashlib.sha256(token.encode()).hexdigest()


def issue_token(session: Session, user: User, label: str = "") -> str:
    """A new bearer token for ``user``; only its hash is stored, so print it now or lose it."""
    token = "ist_" + secrets.token_urlsafe(32)
    session.add(ApiToken(user_id=user.id, token_sha256=_token_digest(token), label=label))
    session.flush()
    return token


def user_for_token(session: Session, token: str) -> User | None:
    row = session.scalar(select(ApiToken).where(ApiToken.token_sha256 == _token_digest(token)))
    if row is None or not row.user.active:
        return None
    now = utcnow()
    # At most one write a minute per token: every API call (every click) would otherwise write.
    if row.last_used_at is None or now - row.last_used_at > timedelta(minutes=1):
        row.last_used_at = now
    return row.user


def user_json(user: User) -> dict[str, object]:
    return {"id": user.id, "name": user.name, "role": user.role.value, "active": user.active,
            "created_at": user.created_at.isoformat() + "Z"}
