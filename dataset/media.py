"""The content-addressed media store: every file lives once, under its SHA-256.

Keys look like ``ab/cd/abcd…(64 hex).png``. Writes are atomic (temporary file in the target
directory, fsync, rename), so a crash never leaves a half-written file under a valid key, and a
key can never name a path outside the root.
"""

from __future__ import annotations

import hashlib
import os
import re
import tempfile
from pathlib import Path
from typing import BinaryIO

from core.atomic import atomic_write_bytes

_KEY = re.compile(r"^[0-9a-f]{2}/[0-9a-f]{2}/[0-9a-f]{64}\.[a-z0-9]{1,8}$")
_EXT = re.compile(r"^[a-z0-9]{1,8}$")


def sha256_file(path: Path) -> str:
    """Hex SHA-256 of a file's bytes, read in chunks (files may be larger than memory)."""
    digest = hashlib.sha256()
    with Path(path).open("rb") as fh:
        while chunk := fh.read(1 << 20):
            digest.update(chunk)
    return digest.hexdigest()


class MediaKeyError(ValueError):
    """A key that is malformed or would leave the media root."""


class MediaStore:
    """Files under ``root`` addressed by content hash."""

    def __init__(self, root: Path) -> None:
        self.root = Path(root).resolve()

    @staticmethod
    def key_for(data: bytes, ext: str) -> str:
        ext = ext.lower().lstrip(".")
        if not _EXT.match(ext):
            raise MediaKeyError(f"bad file extension {ext!r}")
        digest = hashlib.sha256(data).hexdigest()
        return f"{digest[:2]}/{digest[2:4]}/{digest}.{ext}"

    def put_bytes(self, data: bytes, ext: str) -> str:
        """Store ``data`` (idempotent) and return its key."""
        key = self.key_for(data, ext)
        path = self.path(key)
        if not path.exists():
            atomic_write_bytes(path, data)
        return key

    def put_file(self, src: Path) -> str:
        with Path(src).open("rb") as fh:
            return self.put_stream(fh, Path(src).suffix)

    def put_stream(self, stream: BinaryIO, ext: str) -> str:
        """Store a (possibly large) stream without holding it in memory; hashes while copying."""
        ext = ext.lower().lstrip(".")
        if not _EXT.match(ext):
            raise MediaKeyError(f"bad file extension {ext!r}")
        incoming = self.root / ".incoming"
        incoming.mkdir(parents=True, exist_ok=True)
        digest = hashlib.sha256()
        fd, tmp = tempfile.mkstemp(dir=incoming, suffix=".part")
        try:
            with os.fdopen(fd, "wb") as out:
                while chunk := stream.read(1 << 20):
                    digest.update(chunk)
                    out.write(chunk)
                out.flush()
                os.fsync(out.fileno())
            hexdigest = digest.hexdigest()
            key = f"{hexdigest[:2]}/{hexdigest[2:4]}/{hexdigest}.{ext}"
            path = self.path(key)
            path.parent.mkdir(parents=True, exist_ok=True)
            os.chmod(tmp, 0o644)
            os.replace(tmp, path)  # same filesystem: atomic, and idempotent for equal content
            return key
        finally:
            Path(tmp).unlink(missing_ok=True)

    @staticmethod
    def is_key(text: str) -> bool:
        return bool(_KEY.match(text))

    def path(self, key: str) -> Path:
        """The file of ``key``; raises :class:`MediaKeyError` for anything not a store key."""
        if not isinstance(key, str) or not _KEY.match(key):
            raise MediaKeyError(f"not a media key: {key!r}")
        path = (self.root / key).resolve()
        if not path.is_relative_to(self.root):  # e.g. a symlinked subdir pointing elsewhere
            raise MediaKeyError(f"media key leaves the media root: {key!r}")
        return path

    def read_bytes(self, key: str) -> bytes:
        return self.path(key).read_bytes()

    def exists(self, key: str) -> bool:
        return self.path(key).is_file()
