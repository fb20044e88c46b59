"""How counts and values read in messages people see: "1 frame", "2 frames" (job logs, pages, the
CLI), and a client's value as an error quotes it."""

from __future__ import annotations

from typing import Any

SHOWN_CHARS = 80  # of a value an error message quotes: enough to tell which, never a request echoed whole


def plural(n: int, word: str, many: str | None = None) -> str:
    """``n`` and ``word``, in the plural (``many``, else ``word`` + "s") unless ``n`` is 1."""
    return f"{n} {word if n == 1 else many or word + 's'}"


def quoted(value: Any) -> str:
    """``value`` as an error message quotes it: its repr, cut after SHOWN_CHARS characters with how
    long it was (``'sss…'…(200000 characters)``). Every message that names a client's value says it so."""
    text = repr(value)
    if len(text) <= SHOWN_CHARS:
        return text
    return f"{text[:SHOWN_CHARS]}…({len(value) if isinstance(value, str) else len(text)} characters)"
