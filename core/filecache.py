"""A directory of cache files kept within a byte budget, least recently used evicted first.

Several processes may read and write at once: writes are atomic (temporary file, then rename),
recency is the file's mtime (refreshed on every hit), and after each write the oldest files are
deleted until the cache fits. Two processes evicting at once may both try to delete a file: a
missing file is simply skipped.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

from core.atomic import atomic_write_bytes

STALE_TMP_S = 3600.0  # a temporary file this old belongs to a writer that died


class BoundedFileCache:
    def __init__(self, root: Path, budget_bytes: int) -> None:
        if budget_bytes < 0:
            raise ValueError(f"budget_bytes must be >= 0, got {budget_bytes}")
        self.root = Path(root)
        self.budget_bytes = int(budget_bytes)

    def read(self, path: Path) -> bytes | None:
        """The file's bytes, or None when absent (or evicted meanwhile); a hit refreshes its recency."""
        try:
            data = path.read_bytes()
            os.utime(path)
        except FileNotFoundError:
            return None
        return data

    def touch(self, path: Path) -> bool:
        """Whether the file is there; if so its recency is refreshed."""
        try:
            os.utime(path)
        except FileNotFoundError:
            return False
        return True

    def write(self, path: Path, data: bytes) -> None:
        """Store ``data`` at ``path`` atomically, then evict beyond the budget (a file larger than
        the whole budget is evicted at once)."""
        atomic_write_bytes(path, data)
        self._evict()

    def usage(self) -> int:
        """Bytes used by the entries now."""
        return sum(size for _, size, _ in self._entries())

    def _entries(self) -> list[tuple[float, int, Path]]:
        """(mtime, size, path) of every entry; deletes temporary files of dead writers."""
        entries = []
        now = time.time()
        for path in self.root.rglob("*"):
            try:
                st = path.stat()
            except FileNotFoundError:
                continue
            if not path.is_file():
                continue
            if not path.name.startswith("."):
                entries.append((st.st_mtime, st.st_size, path))
            elif now - st.st_mtime > STALE_TMP_S:
                path.unlink(missing_ok=True)
        return entries

    def _evict(self) -> None:
        entries = sorted(self._entries())
        total = sum(size for _, size, _ in entries)
        for _, size, path in entries:
            if total <= self.budget_bytes:
                break
            path.unlink(missing_ok=True)
            total -= size
