"""The HTTP server that ``illusion-studio serve`` runs: cheroot, changed so that no worker thread ever
waits on a client's bytes.

Stock cheroot gives each new connection a worker at once, which then waits up to ``timeout`` for every
byte of the request and its body: as many slow clients as there are threads stop the server. Here the
selector thread reads every request ahead, without waiting, as its bytes arrive, and a worker takes the
request only once it is whole — the way nginx buffers a body before it passes the request on
(``proxy_request_buffering on``):

* the request line and headers (at most :data:`HEAD_BYTES`) within :data:`TIMEOUT_S` of the first byte;
* then its body, as much as the app admits from the head alone (:data:`Admit`, see
  :mod:`webapp.admission`): every body up to :data:`READ_AHEAD_BYTES`, and a larger one up to the
  route's limit only when the head carries the credentials of a role the route serves. A body larger
  than the admission is read only up to :data:`READ_AHEAD_BYTES`; the app answers it (401, 403, 413)
  without reading further, and the connection closes.
* A body must arrive at a minimum rate, as Apache's ``mod_reqtimeout`` ``body=…,MinRate=…``: within
  :data:`BODY_GRACE_S` of the headers, plus one second for every :data:`BODY_MIN_RATE` bytes that came.
  A connection past its deadline is closed by the selector, which holds no thread for it meanwhile.

A body over :data:`SPOOL_BYTES` waits in a temporary file rather than in memory. The worker reads only
what the selector read: past it the body ends (a short body is the app's 400), so no read in a worker
touches the socket.
"""

from __future__ import annotations

import re
import socket
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import IO, Any

from cheroot import wsgi
from cheroot.makefile import MakeFile, StreamReader
from cheroot.server import HTTPConnection, HTTPRequest

READ_AHEAD_BYTES = 32 * 1024  # of any request's body, read before a worker takes it
HEAD_BYTES = 64 * 1024  # request line and headers, at most (cheroot answers 413/414 beyond)
TIMEOUT_S = 30  # for the line and headers to arrive from the first byte; an idle connection's life
BODY_GRACE_S = 10.0  # for a body to start arriving once its headers are in
BODY_MIN_RATE = 16 * 1024  # bytes a second a body must keep up on average past the grace (128 kbit/s)
SPOOL_BYTES = 1 << 20  # a body past this waits on disk
RECV_BYTES = 256 * 1024  # one read from a socket
PASS_BYTES = 4 << 20  # read from one connection in one pass of the selector, so that none starves the others
BACKLOG = 1024  # connections waiting to be accepted (waitress's default)
_HEAD_END = b"\r\n\r\n"
_LENGTH = re.compile(rb"\r\ncontent-length:[ \t]*([0-9]{1,18})[ \t]*(?:\r\n|$)", re.IGNORECASE)
_CHUNKED = re.compile(rb"\r\ntransfer-encoding:[^\r\n]*chunked", re.IGNORECASE)
_EXPECT = re.compile(rb"\r\nexpect:[ \t]*100-continue", re.IGNORECASE)
_CONTINUE = b"HTTP/1.1 100 Continue\r\n\r\n"
_CHUNK_LINE_BYTES = 4096  # a chunk's size line or a trailer line, at most

class BodyCut(Exception):
    """The app read past the part of a body that the server read ahead of a body over its admission:
    the body is larger than the route takes (the app answers 413)."""


Admit = Callable[[bytes], int]
"""A request's line and headers (bytes, up to the blank line) → how many bytes of body it may send
before a worker takes it. Called only for bodies over :data:`READ_AHEAD_BYTES`; must not raise."""


def admit_nothing_more(head: bytes) -> int:
    """The admission of a server with no app-specific rule: :data:`READ_AHEAD_BYTES` for every request."""
    return READ_AHEAD_BYTES


class ChunkCounter:
    """Follows a chunked body (RFC 9112 §7.1) as its raw bytes arrive: how many bytes of data it has
    carried, and where it ends. Bytes past the end belong to the connection's next request."""

    def __init__(self) -> None:
        self.data = 0  # bytes of chunk data so far
        self.ended = False  # the last chunk and the trailer section are in
        self.bad = False  # not chunked framing: the worker refuses it from what is there
        self._line = bytearray()  # a size or trailer line being read
        self._left = 0  # bytes of the current chunk's data and its CRLF still to come
        self._trailer = False  # past the last chunk, reading trailer lines

    def feed(self, raw: bytes | bytearray | memoryview) -> int:
        """Take ``raw``; return how many of its bytes belong to this body (all, until it ends)."""
        view, at = memoryview(raw), 0
        while at < len(view) and not (self.ended or self.bad):
            if self._left:
                step = min(self._left, len(view) - at)
                self.data += max(0, min(step, self._left - 2))  # the last two are the chunk's CRLF
                self._left -= step
                at += step
                continue
            end = bytes(view[at:at + _CHUNK_LINE_BYTES + 1]).find(b"\n")
            if end < 0:  # the line goes on in the next bytes
                self._line += view[at:]
                self.bad = len(self._line) > _CHUNK_LINE_BYTES
                return len(view)
            if len(self._line) + end > _CHUNK_LINE_BYTES:
                self.bad = True
                return at
            line, self._line = bytes(self._line + view[at:at + end]).rstrip(b"\r"), bytearray()
            at += end + 1
            self._next_line(line)
        return at

    def _next_line(self, line: bytes) -> None:
        if self._trailer:
            self.ended = not line
            return
        try:
            size = int(line.split(b";", 1)[0].strip(), 16)
        except ValueError:
            self.bad = True
            return
        if size < 0:
            self.bad = True
        elif size == 0:
            self._trailer = True
        else:
            self._left = size + 2


class _ReadAhead(socket.SocketIO):
    """A connection's raw reads as a worker sees them: what the selector read ahead (in memory, a large
    body on disk), then nothing — a worker never waits on the socket."""

    def __init__(self, sock: socket.socket) -> None:
        super().__init__(sock, "rb")
        self.ahead = bytearray()  # the request's line and headers, the start of its body, what came next
        self.spool: IO[bytes] | None = None  # a large body, read after ``ahead``
        self.after = bytearray()  # what came after a spooled body: the start of the next request
        self.cut = False  # the request's body is over its admission: reading past what is here raises BodyCut

    def spill(self, head: int, body: int) -> None:
        """Move the ``body`` bytes of body that follow the ``head`` bytes of line and headers to disk."""
        self.spool = tempfile.TemporaryFile()  # noqa: SIM115 (closed once read, or with the connection)
        self.spool.write(self.ahead[head:head + body])
        self.after += self.ahead[head + body:]
        del self.ahead[head:]

    def rewind(self) -> None:
        """The request is whole: its spooled body is read from its start."""
        if self.spool is not None:
            self.spool.seek(0)

    def readinto(self, b: Any) -> int:
        if not self.ahead and self.spool is not None:
            if n := self.spool.readinto(b):
                return n
            self.spool.close()
            self.spool, self.ahead, self.after = None, self.after, bytearray()
        n = min(len(b), len(self.ahead))
        if not n and self.cut and len(b):
            raise BodyCut("the request body is larger than this route takes")
        b[:n] = self.ahead[:n]
        del self.ahead[:n]
        return n

    def close(self) -> None:
        if self.spool is not None:
            self.spool.close()
            self.spool = None
        super().close()


class _Reader(StreamReader):
    """cheroot's buffered socket reader over :class:`_ReadAhead`."""

    def __init__(self, sock: socket.socket, bufsize: int) -> None:
        self.raw_ahead = _ReadAhead(sock)
        # StreamReader.__init__ would wrap a plain SocketIO: skip to its base, the buffered reader.
        super(StreamReader, self).__init__(self.raw_ahead, bufsize)
        self.bytes_read = 0


@dataclass
class Arrival:
    """What the selector knows of the request it is reading ahead on one connection."""

    began: float  # time.time() of its first byte
    head: int = 0  # once the headers are in: their length (the body's offset in the read-ahead), else 0
    headers_at: float = 0.0  # time.time() when they were
    length: int = 0  # Content-Length (0: none)
    admitted: int = READ_AHEAD_BYTES  # bytes of body it may send before a worker takes it
    expects: bool = False  # waits for "100 Continue"
    continued: bool = False  # the read-ahead sent it
    body: int = 0  # raw bytes of body read (chunk framing included)
    chunks: ChunkCounter | None = None  # the body is chunked
    whole: bool = False  # a worker may take it
    _head_bytes: bytes = field(default=b"", repr=False)
    _asked: bool = field(default=False, repr=False)  # the admission was asked
    _searched: int = field(default=0, repr=False)

    def deadline(self) -> float:
        """When (time.time() seconds) the connection is closed if the request is still not whole."""
        if not self.head:
            return self.began + TIMEOUT_S
        return self.headers_at + BODY_GRACE_S + self.body / BODY_MIN_RATE

    def wants(self) -> int:
        """Bytes to read next (0: none, the request is whole)."""
        if self.whole:
            return 0
        if not self.head:
            return HEAD_BYTES + 1
        if self.chunks is not None:
            return RECV_BYTES
        return self._body_target() - self.body

    def find_head(self, ahead: bytearray, admit: Admit) -> None:
        """Look for the end of the headers in ``ahead``, the connection's bytes from this request on."""
        end = ahead.find(_HEAD_END, max(0, self._searched - 3))
        self._searched = len(ahead)
        if end < 0:
            self.whole = len(ahead) > HEAD_BYTES  # past the limit: the worker refuses it from what is there
            return
        self.head, self.headers_at, self._head_bytes = end + len(_HEAD_END), time.time(), bytes(ahead[:end])
        self.expects = bool(_EXPECT.search(self._head_bytes))
        if _CHUNKED.search(self._head_bytes):
            self.chunks = ChunkCounter()
        elif length := _LENGTH.search(self._head_bytes):
            self.length = int(length[1])
            if self.length > READ_AHEAD_BYTES:
                self._ask(admit)
        self.body_in(bytes(ahead[self.head:]), admit)

    def body_in(self, fresh: bytes | bytearray, admit: Admit) -> int:
        """Account for ``fresh`` bytes read after the headers; return how many belong to this request."""
        if self.chunks is not None:
            used = self.chunks.feed(fresh)
            self.body += used
            if self.chunks.data > READ_AHEAD_BYTES:
                self._ask(admit)
            self.whole = self.chunks.ended or self.chunks.bad or self.chunks.data > self.admitted
            return used
        used = min(len(fresh), max(0, self.length - self.body))
        self.body += used
        self.whole = self.body >= self._body_target()
        return used

    @property
    def cut(self) -> bool:
        """Whole, but with a body over its admission, read only in part."""
        if self.chunks is not None:
            return self.whole and not (self.chunks.ended or self.chunks.bad)
        return self.whole and self.length > self.admitted

    def _body_target(self) -> int:
        if self.length <= self.admitted:
            return self.length
        return 0 if self.expects else min(self.length, READ_AHEAD_BYTES)  # answered from what is there

    def _ask(self, admit: Admit) -> None:
        if not self._asked:
            self._asked, self.admitted = True, max(READ_AHEAD_BYTES, admit(self._head_bytes))


class _Request(HTTPRequest):
    def header_reader(self, rfile: Any, hdict: dict[bytes, bytes]) -> dict[bytes, bytes]:
        """cheroot's header reading, leaving out an Expect the read-ahead has answered (cheroot would
        send a second "100 Continue")."""
        hdict = HTTPRequest.header_reader(rfile, hdict)
        if self.conn.continued:
            hdict.pop(b"Expect", None)
            self.conn.continued = False
        return hdict

    def send_headers(self) -> None:
        """Before answering, drain what the app left unread of a body the server read ahead whole (from
        memory: the connection then serves its next request); close the connection if the body was cut."""
        unread = (self.chunked_read and not self.rfile.closed) or getattr(self.rfile, "remaining", 0) > 0
        if unread and self.conn.rfile.raw_ahead.cut:
            self.close_connection = True
        elif unread and self.chunked_read:  # cheroot drains only a body of known length
            try:
                while self.rfile.read(RECV_BYTES):
                    pass
            except ValueError:  # not chunked framing after all
                self.close_connection = True
        super().send_headers()


class _Connection(HTTPConnection):
    RequestHandlerClass = _Request

    def __init__(self, server: Server, sock: socket.socket, makefile: Any = MakeFile) -> None:
        super().__init__(server, sock, lambda s, mode, size: _Reader(s, size) if "r" in mode else makefile(s, mode, size))
        self.arrival: Arrival | None = None  # the request being read ahead; None between requests
        self.continued = False  # the read-ahead sent this request's "100 Continue"

    def read_ahead(self, admit: Admit) -> bool | None:
        """Read, without waiting, what has arrived of the next request. True: it is whole, a worker
        may take it; False: wait for more; None: the client has gone."""
        raw = self.rfile.raw_ahead
        if self.rfile.has_data():  # the buffered reader holds the start of a pipelined request
            raw.ahead[:0] = self.rfile.read(len(self.rfile.peek(0)))
        if self.arrival is None and raw.ahead:
            self.arrival = Arrival(began=time.time())
            self.arrival.find_head(raw.ahead, admit)
        self.socket.settimeout(0)
        try:
            passed = 0
            while (self.arrival is None or self.arrival.wants() > 0) and passed < PASS_BYTES:
                try:
                    data = self.socket.recv(RECV_BYTES if self.arrival is None else min(self.arrival.wants(), RECV_BYTES))
                except BlockingIOError:
                    break
                if not data:
                    return None
                passed += len(data)
                self.arrival = self.arrival or Arrival(began=time.time())
                self._keep(self.arrival, raw, data, admit)
            arrival = self.arrival
            if arrival is not None and arrival.expects and arrival.head and not arrival.continued and arrival.wants() > 0:
                self.socket.send(_CONTINUE)  # a few bytes into an empty send buffer
                arrival.continued = self.continued = True
        except OSError:
            return None
        finally:
            self.socket.settimeout(self.server.timeout)
        if self.arrival is None or not self.arrival.whole:
            return False
        raw.cut, self.arrival = self.arrival.cut, None
        raw.rewind()
        return True

    @staticmethod
    def _keep(arrival: Arrival, raw: _ReadAhead, data: bytes, admit: Admit) -> None:
        """Keep ``data``, just read, in memory or (a large body's) on disk, in the order it came."""
        if not arrival.head:
            raw.ahead += data
            arrival.find_head(raw.ahead, admit)
        elif raw.spool is None:
            arrival.body_in(data, admit)
            raw.ahead += data
        else:
            used = arrival.body_in(data, admit)
            raw.spool.write(data[:used])
            raw.after += data[used:]
            return
        if arrival.head and raw.spool is None and arrival.body > SPOOL_BYTES:
            raw.spill(arrival.head, arrival.body)


class Server(wsgi.Server):
    """cheroot serving ``app`` on ``host:port`` (port 0: any free one) with ``threads`` workers. It
    listens from construction on; connections wait in the backlog until :meth:`run`. ``admit`` says
    from a request's head how much of its body to read before a worker takes it."""

    ConnectionClass = _Connection

    def __init__(self, app: Any, host: str, port: int, threads: int, admit: Admit = admit_nothing_more) -> None:
        super().__init__((host, port), app, numthreads=threads, max=threads, server_name="illusion-studio",
                         request_queue_size=BACKLOG, timeout=TIMEOUT_S)
        self.max_request_header_size = HEAD_BYTES
        self.admit = admit
        self.prepare()

    @property
    def effective_host(self) -> str:
        return str(self.bind_addr[0])

    @property
    def effective_port(self) -> int:
        return int(self.bind_addr[1])

    def process_conn(self, conn: _Connection) -> None:
        """Give ``conn`` to a worker once its request is whole; until then it waits in the selector,
        which closes it at the request's deadline."""
        ready = conn.read_ahead(self.admit)
        if ready:
            super().process_conn(conn)
        elif ready is None:
            conn.close()
        else:
            self.put_conn(conn)
            if conn.arrival is not None:
                # The selector closes connections unused for `timeout`: make that the request's deadline.
                conn.last_used = conn.arrival.deadline() - self.timeout

    def run(self) -> None:
        """Serve until :meth:`close` (or Ctrl-C), then stop the worker threads."""
        try:
            self.serve()
        finally:
            self.stop()

    def close(self) -> None:
        """Stop serving: the listening socket closes and the workers finish what they are answering."""
        self.stop()
