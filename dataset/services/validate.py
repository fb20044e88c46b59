"""Checks of client-sent values that the database would otherwise choke on (a clear 400 instead)."""

from __future__ import annotations

from typing import Any

from dataset.services.errors import InvalidInput

# Ids, revisions and counts are INTEGER columns: 32 bits on PostgreSQL (PostgreSQL casts a
# parameter to the column's type and fails beyond it), so that is the bound for every backend.
DB_INT_MAX = 2**31 - 1


def db_int(value: Any, what: str, *, minimum: int = -DB_INT_MAX, maximum: int = DB_INT_MAX) -> int:
    """``value`` as an integer in ``minimum..maximum``; booleans and numbers with a fraction are refused."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise InvalidInput(f"{what} must be an integer")
    if not minimum <= value <= maximum:
        raise InvalidInput(f"{what} must be in {minimum}..{maximum}")
    return value


def optional_text(value: Any, what: str) -> str:
    """A string field that may be absent (``""``); any other type is refused, never stringified."""
    if value is None:
        return ""
    if not isinstance(value, str):
        raise InvalidInput(f"{what} must be a string")
    return value
