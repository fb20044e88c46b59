"""Flask's JSON provider, strict: a non-finite float is answered as ``null``.

Python's json writes NaN and Infinity as the bare words ``NaN`` / ``Infinity``, which are not JSON
(browsers' and most clients' parsers refuse the whole answer). A value a run or a job stored as NaN
(a diverged loss, a metric of an empty region) is "no value", which JSON says with null.
"""

from __future__ import annotations

from typing import Any

from flask.json.provider import DefaultJSONProvider

from dataset.finite import finite_json


class FiniteJSONProvider(DefaultJSONProvider):
    """Every JSON answer and ``tojson`` of the app: standard JSON, NaN and ±Infinity as null."""

    def dumps(self, obj: Any, **kwargs: Any) -> str:
        default = kwargs.pop("default", self.default)
        try:  # the common case, no NaN anywhere: one pass
            return super().dumps(obj, default=default, allow_nan=False, **kwargs)
        except ValueError:  # "Out of range float values are not JSON compliant"
            return super().dumps(finite_json(obj), default=lambda o: finite_json(default(o)), allow_nan=False, **kwargs)
