"""Giving memory back to the operating system after a request that took a lot of it.

What Python frees, glibc's malloc keeps in its arenas for the next allocation (one arena per thread
that allocated, and large blocks too once its threshold has risen past them): after a few large
drafts at once the process stays at their peak. ``malloc_trim`` hands the free pages back.
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable
from functools import cache

from flask import Response, after_this_request


@cache
def _malloc_trim() -> Callable[[int], int] | None:
    """glibc's ``malloc_trim``; None where the C library has none (musl, macOS, Windows)."""
    try:
        return ctypes.CDLL(None).malloc_trim  # type: ignore[no-any-return]
    except (AttributeError, OSError, TypeError):
        return None


def give_back_freed_memory() -> None:
    """Return the C heap's free pages to the operating system (nothing where the C library cannot)."""
    trim = _malloc_trim()
    if trim is not None:
        trim(0)


def give_back_after_request() -> None:
    """Call in a view: once its request is over, whatever the answer (the response sent, the request's
    objects gone), the freed memory goes back to the operating system."""

    @after_this_request
    def _when_closed(response: Response) -> Response:
        response.call_on_close(give_back_freed_memory)
        return response
