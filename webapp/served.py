"""Answers that send a file the route has already opened (``dataset.contained.open_contained``),
never a path: what is sent is the file that was checked, whatever a swap puts under its name later.

Given a path, ``send_file`` takes the validators and the length from the path; given an open file it
has neither, so they come from the descriptor here, and Range and the validators (If-None-Match,
If-Modified-Since) keep working as for a path.
"""

from __future__ import annotations

import hashlib
import os
from typing import BinaryIO

from flask import Response, request, send_file


def send_opened(file: BinaryIO, download_name: str, *, mimetype: str | None = None, max_age: int = 0,
                as_attachment: bool = False) -> Response:
    """``file`` (open for reading) as the answer, named ``download_name`` (its type guessed from it
    unless ``mimetype`` is given), with an ETag, Last-Modified, its length, and Range honoured."""
    stat = os.fstat(file.fileno())
    try:
        response = send_file(file, mimetype=mimetype, as_attachment=as_attachment, download_name=download_name,
                             conditional=False, etag=_etag(stat), last_modified=stat.st_mtime, max_age=max_age)
        response.content_length = stat.st_size
        # send_file's own conditional=True would see no length for a file object, and so no Range.
        return response.make_conditional(request.environ, accept_ranges=True, complete_length=stat.st_size)
    except Exception:  # a 416, or anything else: the answer that would have closed it is not sent
        file.close()
        raise


def _etag(stat: os.stat_result) -> str:
    """Changes with the file's contents (time, length) and with the file itself (another inode), and
    says nothing of where it lies on the server."""
    key = f"{stat.st_dev}:{stat.st_ino}:{stat.st_mtime_ns}:{stat.st_size}".encode()
    return hashlib.blake2s(key, digest_size=12).hexdigest()
