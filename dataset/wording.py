"""How counts read in messages people see: "1 frame", "2 frames" (job logs, pages, the CLI)."""

from __future__ import annotations


def plural(n: int, word: str, many: str | None = None) -> str:
    """``n`` and ``word``, in the plural (``many``, else ``word`` + "s") unless ``n`` is 1."""
    return f"{n} {word if n == 1 else many or word + 's'}"
