"""The code version recorded in every sample's provenance."""

from __future__ import annotations

import importlib.metadata


def code_version() -> str:
    try:
        return importlib.metadata.version("illusion-studio")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"
