"""The one exception type of capture and reconstruction import."""

from __future__ import annotations

from dataset.services.errors import InvalidInput


class CaptureError(InvalidInput):
    """A capture or reconstruction folder that cannot be imported; the message names the file and why."""
