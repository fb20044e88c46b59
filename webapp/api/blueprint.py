"""The API blueprint and the small request helpers its modules share."""

from __future__ import annotations

import json
import math
import re
from typing import Any, TypeVar

from flask import Blueprint, g, request

from core.formats.rle import compact_list_counts
from core.wording import quoted
from dataset.services.errors import InvalidInput, NotFound
from dataset.services.validate import DB_INT_MAX

api = Blueprint("api", __name__)
_ID = re.compile(r"[0-9]{1,10}")
# A mask's compressed counts as JSON: characters '0'..'o' (its backslashes escaped, so doubled). A quote
# ends it. Character classes only: a pattern that repeats a group keeps a state per repetition, which
# for a string of escapes is hundreds of bytes a character.
_COUNTS_STRING = re.compile(rb'(?<!\\)"counts"[ \t\n\r]*:[ \t\n\r]*"([0-o]*)"')
T = TypeVar("T")


def _finite(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"number {quoted(text)} is out of range")
    return value


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not JSON")


def _structure(text: bytes | bytearray, start: int = 0, end: int | None = None) -> int:
    """The commas, colons and opening brackets in ``text[start:end]``."""
    return sum(text.count(c, start, end) for c in (b",", b":", b"[", b"{"))


def too_many_values(text: bytes | bytearray, limit: int) -> bool:
    """Whether the JSON ``text`` holds more than ``limit`` values and keys (masks' runs aside), told
    without parsing it: a value is the root or an element of a list or object (a container of n holds
    n - 1 commas), a key comes with a colon, and each string is one or the other."""
    if text.count(b'"') > 2 * limit:  # escaped quotes count too: a few more, never fewer
        return True
    values = 1 + _structure(text)
    # The colons and brackets of masks' compressed counts are characters, not structure: taken off
    # while the count is over the limit.
    for match in _COUNTS_STRING.finditer(text) if values > limit else ():
        values -= _structure(text, *match.span(1))
        if values <= limit:
            break
    return values > limit


def json_body(*, many_masks: bool = False, max_values: int | None = None) -> dict[str, Any]:
    """The request's JSON object; numbers must be finite (``1e400`` is refused), nesting bounded.

    ``many_masks``: a body of up to many MB of masks (a draft). Its RLE counts lists are read as the
    compressed strings of the same runs (:func:`compact_list_counts`) and the body is not kept, so
    that reading it takes memory in its size, not several times it (a parsed list of runs takes 8 to
    36 bytes a run where its text takes two or more).

    ``max_values``: the most values and keys (:func:`too_many_values`, masks' runs aside) the route reads.
    Parsed, one takes up to some 100 bytes where its text may take two (``{},``): more are refused
    unparsed.
    """
    raw: bytes | bytearray = request.get_data(cache=not many_masks) or b"null"
    try:
        if many_masks:
            raw = compact_list_counts(raw)
        if max_values is not None and too_many_values(raw, max_values):
            raise InvalidInput(f"the JSON body holds more than {max_values} values and keys (masks' runs "
                               "aside); this route reads no more")
        # Decoded here rather than by json.loads, so that the bytes go before the parsed objects come.
        text = raw.decode(json.detect_encoding(raw), "surrogatepass")
        del raw
        body = json.loads(text, parse_float=_finite, parse_constant=_no_constant)
    except RecursionError:
        raise InvalidInput("the JSON body is nested too deeply") from None
    except ValueError as exc:  # JSONDecodeError, UnicodeDecodeError and ours are ValueErrors
        raise InvalidInput(f"expected a JSON object body: {exc}") from None
    if not isinstance(body, dict):
        raise InvalidInput("expected a JSON object body")
    return body


def int_arg(name: str, default: int | None = None, *, minimum: int = -DB_INT_MAX,
            maximum: int = DB_INT_MAX) -> int | None:
    """Query parameter ``name`` as an integer in ``minimum..maximum`` (``default`` when absent)."""
    raw = request.args.get(name)
    if raw is None or raw == "":
        return default
    try:
        value = int(raw)
    except ValueError:
        raise InvalidInput(f"query parameter {name!r} must be an integer") from None
    if not minimum <= value <= maximum:
        raise InvalidInput(f"query parameter {name!r} must be in {minimum}..{maximum}")
    return value


def id_list_arg(name: str) -> list[int]:
    """Query parameter ``name`` as comma-separated ids (``?ids=1,2``): ASCII digits within the
    database's range only; anything else is left out, as an id no row has would be."""
    values = (v.strip() for v in request.args.get(name, "").split(","))
    return [int(v) for v in values if _ID.fullmatch(v) and int(v) <= DB_INT_MAX]


def cursor_args() -> dict[str, str | None]:
    """The keyset cursors of a paged list (``after``/``before``, from a previous page's ``next``/``prev``)."""
    return {"after": request.args.get("after") or None, "before": request.args.get("before") or None}


def get_or_404(model: type[T], ident: int, what: str) -> T:
    """The row ``ident`` of ``model``, or a 404 naming the ``what``."""
    row = g.db.get(model, ident) if 0 <= ident <= DB_INT_MAX else None
    if row is None:
        raise NotFound(f"no {what} {ident}")
    return row
