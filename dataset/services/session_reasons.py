"""Why a browser's session ended, in words for the person whose tab it was.

An ended session leaves no row (``dataset/services/sessions.py`` deletes it), so the reason comes from
what ended it: an account change an admin made after the login (audited), or the session's age.
"""

from __future__ import annotations

from datetime import datetime, timedelta

from sqlalchemy import select
from sqlalchemy.orm import Session

from core.wording import plural
from dataset.tables import AuditEntry, User, utcnow

# The account changes that end every session of their user (dataset/services/users.py), and what
# each one means for its user.
ENDING_CHANGES = {
    "user.password": "your password was changed",
    "user.role": "your role was changed",
    "user.deactivate": "your account was deactivated",
}
NEXT_STEP = {
    "user.password": "log in with the new password",
    "user.role": "log in again to work with the new role",
    "user.deactivate": "log in once an admin has reactivated it",
}


def why_session_ended(session: Session, user_id: int, signed_in_at: datetime, *,
                      lifetime: timedelta) -> tuple[str, str] | None:
    """Why the session ``user_id`` began at ``signed_in_at`` has ended, and what to do: the newest
    account change since the login (who made it and when), else its age past ``lifetime``; None when
    neither says (idle, or ended elsewhere)."""
    entry = session.scalars(select(AuditEntry).where(
        AuditEntry.target_kind == "user", AuditEntry.target_id == user_id,
        AuditEntry.action.in_(list(ENDING_CHANGES)), AuditEntry.created_at >= signed_in_at,
    ).order_by(AuditEntry.id.desc()).limit(1)).first()
    if entry is not None:
        change = ENDING_CHANGES[entry.action]
        if entry.action == "user.role" and entry.detail.get("new"):
            change += f" to {entry.detail['new']}"
        actor = session.get(User, entry.user_id) if entry.user_id is not None else None
        by = ("by you" if entry.user_id == user_id else f"by {actor.name}") if actor else "on the command line"
        return f"Your session ended because {change} ({by}, {entry.created_at:%Y-%m-%d %H:%M} UTC)", NEXT_STEP[entry.action]
    if utcnow() - signed_in_at > lifetime:
        hours = round(lifetime.total_seconds() / 3600)
        return f"Your session ended {plural(hours, 'hour')} after you logged in, the longest a session lasts", "log in again"
    return None
