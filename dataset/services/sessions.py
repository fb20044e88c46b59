"""Server-side sessions: a row per signed-in browser, so that a session can be ended for good.

The cookie carries only the row's random id (signed by Flask); a request whose row is gone, idle
too long or too old is anonymous. Logout ends one session; a password reset, a role change or a
deactivation ends every session of that user.
"""

from __future__ import annotations

import secrets
from datetime import timedelta

from sqlalchemy import delete
from sqlalchemy.orm import Session

from dataset.tables import User, UserSession, utcnow

TOUCH_EVERY = timedelta(minutes=1)  # at most one write a minute per session, not one per click


def start_session(session: Session, user: User) -> str:
    """A new session for ``user``; returns its id (for the cookie)."""
    row = UserSession(id=secrets.token_urlsafe(32), user_id=user.id)
    session.add(row)
    session.flush()
    return row.id


def user_for_session(session: Session, session_id: str, *, idle: timedelta, lifetime: timedelta) -> User | None:
    """The active user of session ``session_id``, or None once it ended, idled out or expired."""
    row = session.get(UserSession, session_id)
    if row is None:
        return None
    now = utcnow()
    if now - row.last_seen_at > idle or now - row.created_at > lifetime:
        session.delete(row)
        return None
    user = session.get(User, row.user_id)
    if user is None or not user.active:
        return None
    if now - row.last_seen_at > TOUCH_EVERY:
        row.last_seen_at = now
    return user


def end_session(session: Session, session_id: str) -> None:
    session.execute(delete(UserSession).where(UserSession.id == session_id))


def end_user_sessions(session: Session, user_id: int) -> int:
    """End every session of one user; returns how many there were."""
    return session.execute(delete(UserSession).where(UserSession.user_id == user_id)).rowcount
