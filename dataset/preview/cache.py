"""A thin disk cache of rendered files, keyed by what they are made from.

Keys name the inputs by their media keys (content hashes) plus a renderer version, so a
regenerated sample or a changed renderer simply misses; nothing is ever invalidated by hand.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from core.filecache import BoundedFileCache


class RenderCache(BoundedFileCache):
    """Files under ``root``, one per key, within a byte budget; concurrent makers of one key both
    write the same bytes."""

    def path(self, key: Any, ext: str) -> Path:
        """Where the file for ``key`` (any JSON-able value) lives, whether or not it exists yet."""
        digest = hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()
        return self.root / digest[:2] / f"{digest}.{ext}"

    def get_or_make(self, key: Any, ext: str, make: Callable[[], bytes]) -> Path:
        """The cached file for ``key``, made by ``make()`` on a miss."""
        path = self.path(key, ext)
        if not self.touch(path):
            self.write(path, make())
        return path
