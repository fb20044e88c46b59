"""The API blueprint and the small request helpers its modules share."""

from __future__ import annotations

import json
import math
import re
from typing import Any, TypeVar

from flask import Blueprint, g, request

from dataset.services.errors import InvalidInput, NotFound
from dataset.services.validate import DB_INT_MAX

api = Blueprint("api", __name__)
_ID = re.compile(r"[0-9]{1,10}")
T = TypeVar("T")


def _finite(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"number {text} is out of range")
    return value


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not JSON")


def json_body() -> dict[str, Any]:
    """The request's JSON object; numbers must be finite (``1e400`` is refused), nesting bounded."""
    try:
        body = json.loads(request.get_data(cache=True) or b"null", parse_float=_finite, parse_constant=_no_constant)
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
