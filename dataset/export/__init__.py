"""Dataset export and import: the native layout (``NATIVE_FORMAT.md``) and the authors' released
layout, both ways, as jobs; and a torch ``Dataset`` over a native export (``torch_dataset``, imported
on its own so that nothing else here needs torch).

The names below load their submodule on first use: the trainer reads split specs through
``dataset.export.splits``, and importing the job handlers eagerly would load the database layer into it."""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from dataset.export.errors import LayoutError
    from dataset.export.handlers import FORMATS, HANDLERS, export_job, export_params, import_job, import_params
    from dataset.export.splits import parse_split_spec, split_of

_SUBMODULE = {
    "FORMATS": "handlers",
    "HANDLERS": "handlers",
    "LayoutError": "errors",
    "export_job": "handlers",
    "export_params": "handlers",
    "import_job": "handlers",
    "import_params": "handlers",
    "parse_split_spec": "splits",
    "split_of": "splits",
}

__all__ = [
    "FORMATS",
    "HANDLERS",
    "LayoutError",
    "export_job",
    "export_params",
    "import_job",
    "import_params",
    "parse_split_spec",
    "split_of",
]


def __getattr__(name: str) -> Any:
    """Import the public ``name`` from its submodule on first use (and keep it here for the next)."""
    if name not in _SUBMODULE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(f"{__name__}.{_SUBMODULE[name]}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
