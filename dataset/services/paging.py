"""Keyset pagination: a page costs the same on page 1 and page 20,000, whatever the table's size.

A query is paged by its sort key (unique columns, e.g. ``(video_id, index)`` or ``(id,)``): the
page after a cursor is a range scan of an index from that key, never an OFFSET over everything
before it. Cursors are the key's integers joined by ``-`` (``"12-345"``); the page after a cursor
starts behind it even when the rows at the cursor have left the filter meanwhile (a curator's
decisions), so nothing is skipped or shown twice. ``offset`` is still accepted (old deep links):
the start key is found by an index-only walk of the key columns, and the page is keyed from there.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from sqlalchemy import ColumnElement, Select, func, select, tuple_
from sqlalchemy.orm import Session

from dataset.services.errors import InvalidInput


@dataclass(frozen=True)
class Page:
    rows: list[Any]
    prev: str | None  # the cursor for ``before=`` (None: this is the first page)
    next: str | None  # the cursor for ``after=`` (None: this is the last page)


def cursor(values: tuple[int, ...] | list[int]) -> str:
    return "-".join(str(int(v)) for v in values)


def parse_cursor(name: str, value: str | None, width: int) -> tuple[int, ...] | None:
    """``value`` as a key of ``width`` integers; a clear error naming ``name`` if it is not one."""
    if value is None or value == "":
        return None
    try:
        key = tuple(int(part) for part in value.split("-"))
    except ValueError:
        key = ()
    if len(key) != width:
        raise InvalidInput(f"{name} must be a cursor from a previous page (like {'-'.join(['12'] * width)!r})")
    return key


def keyset_page(session: Session, query: Select[Any], keys: tuple[ColumnElement[Any], ...], *, limit: int,
                after: str | None = None, before: str | None = None, offset: int = 0,
                descending: bool = False, keys_query: Select[Any] | None = None) -> Page:
    """One page of ``query`` ordered by ``keys`` (ascending, or all descending).

    ``after``/``before`` are cursors from a previous page; without them the page starts ``offset``
    rows in. ``query`` selects the key columns last: the cursors are read from them. ``keys_query``
    selects only the keys of the same rows, without the joins the page's columns need: the offset
    walk and the first/last-page checks run on it (an index-only scan where the index covers it).
    """
    if after and before:
        raise InvalidInput("give after or before, not both")
    if not 1 <= limit <= 10_000 or offset < 0:
        raise InvalidInput("limit must be 1..10000 and offset ≥ 0")
    start, end = parse_cursor("after", after, len(keys)), parse_cursor("before", before, len(keys))
    key = tuple_(*keys) if len(keys) > 1 else keys[0]

    def bound(values: tuple[int, ...]) -> Any:
        return tuple_(*values) if len(keys) > 1 else values[0]

    def beyond(values: tuple[int, ...], forward: bool, inclusive: bool = False) -> ColumnElement[bool]:
        ahead = forward != descending  # "ahead" in the key's own (ascending) terms
        if inclusive:
            return key >= bound(values) if ahead else key <= bound(values)
        return key > bound(values) if ahead else key < bound(values)

    def ordered(q: Select[Any], forward: bool) -> Select[Any]:
        asc = forward != descending
        return q.order_by(None).order_by(*(k.asc() if asc else k.desc() for k in keys))

    walk = query.with_only_columns(*keys) if keys_query is None else keys_query

    def exists(condition: ColumnElement[bool]) -> bool:
        return session.execute(walk.order_by(None).where(condition).limit(1)).first() is not None

    def step(values: tuple[int, ...], toward_end: bool) -> str:
        # The cursor just past ``values``, so that before=/after= it still includes ``values``.
        delta = 1 if toward_end != descending else -1
        return cursor((*values[:-1], values[-1] + delta))

    width = len(keys)
    if end is not None:
        rows = list(session.execute(ordered(query.where(beyond(end, False)), False).limit(limit + 1)).all())
        more_before = len(rows) > limit
        rows = rows[:limit][::-1]
        if not rows:
            return Page([], None, step(end, False) if exists(beyond(end, True, True)) else None)
        last = _key(rows[-1], width)
        return Page(rows, cursor(_key(rows[0], width)) if more_before else None,
                    cursor(last) if exists(beyond(last, True)) else None)
    inclusive = False
    if start is None and offset:
        # The start key, by walking only the key columns (an index-only scan), then a keyed page.
        first = session.execute(ordered(walk, True).offset(offset).limit(1)).first()
        if first is None:
            final = session.execute(ordered(walk, False).limit(1)).first()
            return Page([], None if final is None else step(tuple(final), True), None)
        start, inclusive = tuple(first), True
    page_query = query if start is None else query.where(beyond(start, True, inclusive))
    rows = list(session.execute(ordered(page_query, True).limit(limit + 1)).all())
    more_after = len(rows) > limit
    rows = rows[:limit]
    if not rows:
        return Page([], step(start, True) if start is not None and exists(beyond(start, False, True)) else None, None)
    first_key = _key(rows[0], width)
    prev = cursor(first_key) if start is not None and exists(beyond(first_key, False)) else None
    return Page(rows, prev, cursor(_key(rows[-1], width)) if more_after else None)


COUNT_CAP = 500


def bounded_count(session: Session, query: Select[Any], column: ColumnElement[Any],
                  cap: int = COUNT_CAP) -> tuple[int, bool]:
    """How many rows ``query`` has, counting no further than ``cap``: (count, whether it is exact)."""
    capped = query.with_only_columns(column).order_by(None).limit(cap + 1).subquery()
    n = int(session.scalar(select(func.count()).select_from(capped)) or 0)
    return min(n, cap), n <= cap


def _key(row: Any, width: int) -> tuple[int, ...]:
    return tuple(row[-width:])
