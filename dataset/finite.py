"""JSON has no NaN or Infinity (and PostgreSQL's JSON refuses them): a non-finite number stored or
answered is "no value", which JSON says with null."""

from __future__ import annotations

import math
from typing import Any

import numpy as np


def finite_json(value: Any) -> Any:
    """``value`` with every non-finite float (Python's or numpy's) inside dicts, lists and tuples
    replaced by None; tuples become lists, as JSON has them."""
    if isinstance(value, float | np.floating):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {key: finite_json(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [finite_json(item) for item in value]
    return value
