"""The HTTP server that ``illusion-studio serve`` runs: cheroot, changed so that a client's bytes cost
no worker thread until its request has arrived, and no body is read that the app did not ask for.

waitress, used before, reads every request body in full (to memory or disk) before the app runs,
under one limit for every route; cheroot hands the body to the app as it streams in (``wsgi.input``),
so the app decides from the route and the credentials whether to read it at all
(:mod:`webapp.bodies`). Two changes to cheroot keep strangers' bytes cheap:

* A connection goes to a worker only once its request line and headers, and the first
  :data:`READ_AHEAD_BYTES` of its body (a small body whole), are in: the selector thread reads them,
  without waiting, as they arrive. Stock cheroot gives each new connection a worker at once, which
  then waits up to ``timeout`` for every byte, so as many idle or dripping connections as there are
  threads stop the server. A request that has not arrived ``timeout`` seconds after its first
  byte is dropped.
* An answer sent while more than :data:`READ_AHEAD_BYTES` of the body are unread closes the
  connection. Stock cheroot reads the whole rest, into memory, to keep the connection open.
"""

from __future__ import annotations

import re
import socket
import time
from typing import Any

from cheroot import wsgi
from cheroot.makefile import MakeFile, StreamReader
from cheroot.server import HTTPConnection, HTTPRequest

READ_AHEAD_BYTES = 32 * 1024  # of a body, read before a worker takes its request
HEAD_BYTES = 64 * 1024  # request line and headers, at most (cheroot answers 413/414 beyond)
TIMEOUT_S = 30  # for a request to arrive; a worker's wait for one read; an idle connection's life
BACKLOG = 1024  # connections waiting to be accepted (waitress's default)
_HEAD_END = b"\r\n\r\n"
_LENGTH = re.compile(rb"\r\ncontent-length:[ \t]*([0-9]{1,18})[ \t]*(?:\r\n|$)", re.IGNORECASE)
_CHUNKED = re.compile(rb"\r\ntransfer-encoding:[^\r\n]*chunked", re.IGNORECASE)
_EXPECT = re.compile(rb"\r\nexpect:[ \t]*100-continue", re.IGNORECASE)
_LAST_CHUNK = b"0\r\n\r\n"
_CONTINUE = b"HTTP/1.1 100 Continue\r\n\r\n"


def wanted(pending: bytes | bytearray) -> tuple[int, bool]:
    """How many bytes of ``pending`` (what a connection has sent from its next request on) a worker
    finds there before it takes the request, and whether the request waits for "100 Continue"."""
    end = pending.find(_HEAD_END)
    if end < 0 or end >= HEAD_BYTES:
        return HEAD_BYTES + 1, False  # past the limit: the worker refuses it from what is there
    head, body = pending[:end], end + len(_HEAD_END)
    expects = bool(_EXPECT.search(head))
    if _CHUNKED.search(head):
        ended = len(pending) > body and pending.endswith(_LAST_CHUNK)
        return (len(pending) if ended else body + READ_AHEAD_BYTES), expects
    length = _LENGTH.search(head)
    return body + min(int(length[1]) if length else 0, READ_AHEAD_BYTES), expects


class _ReadAhead(socket.SocketIO):
    """A connection's raw reads: first what the selector thread read ahead, then the socket."""

    def __init__(self, sock: socket.socket) -> None:
        super().__init__(sock, "rb")
        self.ahead = bytearray()

    def readinto(self, b: Any) -> int | None:
        if self.ahead:
            n = min(len(b), len(self.ahead))
            b[:n] = self.ahead[:n]
            del self.ahead[:n]
            return n
        return super().readinto(b)


class _Reader(StreamReader):
    """cheroot's buffered socket reader over :class:`_ReadAhead`."""

    def __init__(self, sock: socket.socket, bufsize: int) -> None:
        self.raw_ahead = _ReadAhead(sock)
        # StreamReader.__init__ would wrap a plain SocketIO: skip to its base, the buffered reader.
        super(StreamReader, self).__init__(self.raw_ahead, bufsize)
        self.bytes_read = 0


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
        """Close the connection, rather than read the rest, when the app left a body unread."""
        unread_chunks = self.chunked_read and not self.rfile.closed
        if unread_chunks or getattr(self.rfile, "remaining", 0) > READ_AHEAD_BYTES:
            self.close_connection = True
        super().send_headers()


class _Connection(HTTPConnection):
    RequestHandlerClass = _Request

    def __init__(self, server: Server, sock: socket.socket, makefile: Any = MakeFile) -> None:
        super().__init__(server, sock, lambda s, mode, size: _Reader(s, size) if "r" in mode else makefile(s, mode, size))
        self.began: float | None = None  # time.time() of the first byte of the request being read ahead
        self.continued = False  # the read-ahead sent this request's "100 Continue"

    def read_ahead(self) -> bool | None:
        """Read, without waiting, what has arrived of the next request. True: a worker may take it;
        False: wait for more; None: the client has gone."""
        ahead = self.rfile.raw_ahead.ahead
        if self.rfile.has_data():  # the buffered reader holds the start of a pipelined request
            ahead[:0] = self.rfile.read(len(self.rfile.peek(0)))
        if not ahead:
            self.began = None
        want, expects = wanted(ahead)
        self.socket.settimeout(0)
        try:
            if len(ahead) < want:
                data = self.socket.recv(want - len(ahead))
                if not data:
                    return None
                ahead += data
                self.began = self.began or time.time()
                want, expects = wanted(ahead)
            if expects and not self.continued and len(ahead) < want:
                self.socket.send(_CONTINUE)  # a few bytes into an empty send buffer
                self.continued = True
        except BlockingIOError:
            pass
        except OSError:
            return None
        finally:
            self.socket.settimeout(self.server.timeout)
        if len(ahead) < want:
            return False
        self.began = None
        return True


class Server(wsgi.Server):
    """cheroot serving ``app`` on ``host:port`` (port 0: any free one) with ``threads`` workers. It
    listens from construction on; connections wait in the backlog until :meth:`run`."""

    ConnectionClass = _Connection

    def __init__(self, app: Any, host: str, port: int, threads: int) -> None:
        super().__init__((host, port), app, numthreads=threads, max=threads, server_name="illusion-studio",
                         request_queue_size=BACKLOG, timeout=TIMEOUT_S)
        self.max_request_header_size = HEAD_BYTES
        self.prepare()

    @property
    def effective_host(self) -> str:
        return str(self.bind_addr[0])

    @property
    def effective_port(self) -> int:
        return int(self.bind_addr[1])

    def process_conn(self, conn: _Connection) -> None:
        """Give ``conn`` to a worker once its request is in; until then it waits in the selector."""
        ready = conn.read_ahead()
        if ready:
            super().process_conn(conn)
        elif ready is None:
            conn.close()
        else:
            began = conn.began
            self.put_conn(conn)
            if began is not None:  # the selector drops connections unused for `timeout`: count from the first byte
                conn.last_used = began

    def run(self) -> None:
        """Serve until :meth:`close` (or Ctrl-C), then stop the worker threads."""
        try:
            self.serve()
        finally:
            self.stop()

    def close(self) -> None:
        """Stop serving: the listening socket closes and the workers finish what they are answering."""
        self.stop()
