"""Flask's JSON provider, strict: a non-finite float is answered as ``null``.

Python's json writes NaN and Infinity as the bare words ``NaN`` / ``Infinity``, which are not JSON
(browsers' and most clients' parsers refuse the whole answer). A value a run or a job stored as NaN
(a diverged loss, a metric of an empty region) is "no value", which JSON says with null.
"""

from __future__ import annotations

import math
from typing import Any

from flask.json.provider import DefaultJSONProvider


def finite(value: Any) -> Any:
    """``value`` with every non-finite float inside dicts, lists and tuples replaced by None."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {key: finite(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite(item) for item in value]
    return value


class FiniteJSONProvider(DefaultJSONProvider):
    """Every JSON answer and ``tojson`` of the app: standard JSON, NaN and ±Infinity as null."""

    def dumps(self, obj: Any, **kwargs: Any) -> str:
        default = kwargs.pop("default", self.default)
        try:  # the common case, no NaN anywhere: one pass
            return super().dumps(obj, default=default, allow_nan=False, **kwargs)
        except ValueError:  # "Out of range float values are not JSON compliant"
            return super().dumps(finite(obj), default=lambda o: finite(default(o)), allow_nan=False, **kwargs)
