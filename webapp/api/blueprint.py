"""The API blueprint and the small request helpers its modules share."""

from __future__ import annotations

from typing import Any, TypeVar

from flask import Blueprint, g, request

from dataset.services.errors import InvalidInput, NotFound

api = Blueprint("api", __name__)
T = TypeVar("T")


def json_body() -> dict[str, Any]:
    body = request.get_json(silent=True)
    if not isinstance(body, dict):
        raise InvalidInput("expected a JSON object body")
    return body


def int_arg(name: str, default: int | None = None) -> int | None:
    raw = request.args.get(name)
    if raw is None or raw == "":
        return default
    try:
        return int(raw)
    except ValueError:
        raise InvalidInput(f"query parameter {name!r} must be an integer") from None


def cursor_args() -> dict[str, str | None]:
    """The keyset cursors of a paged list (``after``/``before``, from a previous page's ``next``/``prev``)."""
    return {"after": request.args.get("after") or None, "before": request.args.get("before") or None}


def get_or_404(model: type[T], ident: int, what: str) -> T:
    """The row ``ident`` of ``model``, or a 404 naming the ``what``."""
    row = g.db.get(model, ident)
    if row is None:
        raise NotFound(f"no {what} {ident}")
    return row
