"""The audit log of human decisions."""

from __future__ import annotations

from typing import Any

from sqlalchemy.orm import Session

from dataset.tables import AuditEntry


def record(session: Session, user_id: int | None, action: str, target_kind: str,
           target_id: int | None, **detail: Any) -> AuditEntry:
    """Add one entry in the caller's transaction, so the decision and its record commit together."""
    entry = AuditEntry(user_id=user_id, action=action, target_kind=target_kind,
                       target_id=target_id, detail=detail)
    session.add(entry)
    return entry
