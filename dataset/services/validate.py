"""Checks of client-sent values that the database would otherwise choke on (a clear 400 instead)."""

from __future__ import annotations

from typing import Any

from dataset.services.errors import InvalidInput

# Ids, revisions and counts are INTEGER columns: 32 bits on PostgreSQL (PostgreSQL casts a
# parameter to the column's type and fails beyond it), so that is the bound for every backend.
DB_INT_MAX = 2**31 - 1
TEXT_CHARS = 1000  # any text field a request carries, unless the field says less
REASON_CHARS = 256  # a reviewer's reason: stored, and shown to the annotator on their page


def db_int(value: Any, what: str, *, minimum: int = -DB_INT_MAX, maximum: int = DB_INT_MAX) -> int:
    """``value`` as an integer in ``minimum..maximum``; booleans and numbers with a fraction are refused."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise InvalidInput(f"{what} must be an integer")
    if not minimum <= value <= maximum:
        raise InvalidInput(f"{what} must be in {minimum}..{maximum}")
    return value


def optional_text(value: Any, what: str, *, max_chars: int = TEXT_CHARS) -> str:
    """A string field of at most ``max_chars`` characters that may be absent (``""``); any other type is
    refused, never stringified."""
    if value is None:
        return ""
    if not isinstance(value, str):
        raise InvalidInput(f"{what} must be a string")
    if len(value) > max_chars:
        raise InvalidInput(f"{what} must have at most {max_chars} characters")
    return value


def reason_text(value: str) -> str:
    """A reviewer's reason, stripped, of at most REASON_CHARS characters (kept as written: it is the
    reviewer's text for the person it goes to)."""
    return optional_text((value or "").strip(), "reason", max_chars=REASON_CHARS)
