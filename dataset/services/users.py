"""Users, passwords and API tokens.

A password reset or a deactivation ends the user's sessions and revokes their API tokens for good:
whoever might have taken over the account keeps no way in. Reactivation lets the user log in
again with their password but brings no token back; an admin issues a new one.
"""

from __future__ import annotations

import hashlib
import hmac
import re
import secrets
from datetime import timedelta
from functools import cache

from sqlalchemy import delete, func, select
from sqlalchemy.orm import Session
from werkzeug.security import check_password_hash, generate_password_hash

from core.wording import plural, quoted
from dataset.services import audit
from dataset.services.errors import Conflict, InvalidInput, NotFound
from dataset.services.sessions import end_user_sessions
from dataset.services.validate import DB_INT_MAX
from dataset.tables import ApiToken, Role, User, utcnow

_NAME = re.compile(r"[A-Za-z0-9_.-]{1,64}")  # always fullmatch: "$" would let "admin\n" through
MIN_PASSWORD = 8
MAX_PASSWORD = 1024  # hashing a password costs in its length; no one types more


def parse_role(value: str) -> Role:
    try:
        return Role(value)
    except ValueError:
        raise InvalidInput(f"unknown role {quoted(value)}; choose one of {', '.join(Role)}") from None


def create_user(session: Session, name: str, role: Role | str, password: str) -> User:
    """Add a user; rejects bad names, short passwords, unknown roles and duplicates."""
    role = parse_role(role) if isinstance(role, str) else role
    if not _NAME.fullmatch(name):
        raise InvalidInput("user name must be 1-64 letters, digits, '.', '_' or '-'")
    _check_password(password)
    # Names are unique regardless of case: "Admin" next to "admin" would only mislead.
    taken = session.scalar(select(User.name).where(func.lower(User.name) == name.lower()))
    if taken is not None:
        raise Conflict(f"user {taken!r} already exists" + (f" (names ignore case: {name!r})" if taken != name else ""))
    user = User(name=name, role=role, password_hash=generate_password_hash(password))
    session.add(user)
    session.flush()
    return user


def _check_password(password: str) -> None:
    if len(password) < MIN_PASSWORD:
        raise InvalidInput(f"password must have at least {MIN_PASSWORD} characters")
    if len(password) > MAX_PASSWORD:
        raise InvalidInput(f"password must have at most {MAX_PASSWORD} characters")


def get_user(session: Session, name: str) -> User:
    user = session.scalar(select(User).where(User.name == name))
    if user is None:
        raise NotFound(f"no user named {quoted(name)}")
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


# ``ist_<row id>_<secret>``: the id names the token (and so its account, for the per-account
# throttle) and reveals nothing secret. The old ``ist_<secret>`` form is exactly 47 characters,
# too short to match the new one; a new token's bare secret (no ``ist_``) matches neither.
_NAMED_TOKEN = re.compile(r"ist_([1-9][0-9]{0,9})_([A-Za-z0-9_-]{43})")
_OLD_TOKEN = re.compile(r"ist_[A-Za-z0-9_-]{43}")


def issue_token(session: Session, user: User, label: str = "") -> str:
    """A new bearer token ``ist_<id>_<secret>`` for ``user``; only its secret's hash is stored, so
    print it now or lose it. Refused for a deactivated user: reactivation must not bring tokens."""
    if not user.active:
        raise Conflict(f"{user.name} is deactivated; reactivate them first")
    secret = secrets.token_urlsafe(32)
    row = ApiToken(user_id=user.id, token_sha256=_token_digest(secret), label=label)
    session.add(row)
    session.flush()
    return f"ist_{row.id}_{secret}"


def _named(token: str) -> tuple[int, str] | None:
    """(token id, secret) of a new-format token; None for the old form or anything else."""
    match = _NAMED_TOKEN.fullmatch(token)
    if match is None or int(match[1]) > DB_INT_MAX:
        return None
    return int(match[1]), match[2]


def token_account(session: Session, token: str) -> int | None:
    """The id of the user whose token ``token`` names, whether or not its secret is right; None for
    an old-format token or one naming no token (those are throttled per address only)."""
    named = _named(token)
    row = session.get(ApiToken, named[0]) if named else None
    return None if row is None else row.user_id


def user_for_token(session: Session, token: str) -> User | None:
    """The active user this bearer token (new or old format) belongs to, else None."""
    named = _named(token)
    if named is None:  # the old form: found by the hash of the whole token
        if _OLD_TOKEN.fullmatch(token) is None:
            return None
        row = session.scalar(select(ApiToken).where(ApiToken.token_sha256 == _token_digest(token)))
    else:
        row = session.get(ApiToken, named[0])
        if row is not None and not hmac.compare_digest(row.token_sha256, _token_digest(named[1])):
            row = None
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


def _keep_an_admin(session: Session, user: User) -> None:
    """Refuse a change that would leave no active admin."""
    others = session.scalar(select(func.count()).select_from(User).where(
        User.role == Role.admin, User.active.is_(True), User.id != user.id))
    if user.role == Role.admin and user.active and not others:
        raise Conflict(f"{user.name} is the last active admin; make another admin first")


def set_active(session: Session, actor_id: int | None, user: User, active: bool) -> int:
    """Deactivate ``user`` (ending every session, revoking every API token for good) or reactivate
    them (their password works again; no token comes back); audited. Returns the tokens revoked."""
    if active:
        user.active = True
        audit.record(session, actor_id, "user.activate", "user", user.id, name=user.name)
        return 0
    _keep_an_admin(session, user)
    end_user_sessions(session, user.id)
    tokens = _delete_tokens(session, user)
    user.active = False
    audit.record(session, actor_id, "user.deactivate", "user", user.id, name=user.name, tokens=tokens)
    return tokens


def set_role(session: Session, actor_id: int | None, user: User, role: Role | str) -> None:
    """Change ``user``'s role; ends their sessions so the new role applies from a fresh login; audited."""
    role = parse_role(role) if isinstance(role, str) else role
    if role == user.role:
        return
    if role != Role.admin:
        _keep_an_admin(session, user)
    audit.record(session, actor_id, "user.role", "user", user.id, name=user.name, old=user.role.value,
                 new=role.value)
    user.role = role
    end_user_sessions(session, user.id)


def reset_password(session: Session, actor_id: int | None, user: User, password: str) -> int:
    """Set a new password, end every session of ``user`` and revoke their API tokens for good;
    audited (without the password). Returns the tokens revoked."""
    _check_password(password)
    user.password_hash = generate_password_hash(password)
    end_user_sessions(session, user.id)
    tokens = _delete_tokens(session, user)
    audit.record(session, actor_id, "user.password", "user", user.id, name=user.name, tokens=tokens)
    return tokens


def revoke_tokens(session: Session, actor_id: int | None, user: User) -> int:
    """Delete every API token of ``user``; returns how many; audited."""
    count = _delete_tokens(session, user)
    audit.record(session, actor_id, "user.revoke_tokens", "user", user.id, name=user.name, tokens=count)
    return count


def revoked_words(count: int) -> str:
    """What a reset or deactivation did to the tokens, as the Users page and the CLI both say it."""
    return f"{plural(count, 'API token')} revoked for good"


def _delete_tokens(session: Session, user: User) -> int:
    count = session.execute(delete(ApiToken).where(ApiToken.user_id == user.id)).rowcount
    session.expire(user, ["tokens"])  # the page lists the count: no stale collection in this session
    return count
