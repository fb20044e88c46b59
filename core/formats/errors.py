"""The one exception type of the file formats."""

from __future__ import annotations


class FormatError(ValueError):
    """A file is malformed, of the wrong kind, or an array cannot be stored losslessly in it."""
