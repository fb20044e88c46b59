"""The client's address behind the reverse proxies the settings trust (``trusted_proxies``).

Without ``trusted_proxies`` a request comes from its socket's peer, and X-Forwarded-For is ignored:
anyone can write that header. With it, the header is read only when the peer is inside one of the
trusted address ranges, and walked right to left past trusted addresses; the first address outside
them is the client (nginx's ``real_ip_recursive on``). Every entry read that way was appended by a
proxy the settings trust; what lies to its left the client may have made up.

Address ranges rather than a hop count (werkzeug's ProxyFix ``x_for=N``): a hop count believes
the N-th address from the right whoever connected, so a client that reaches the server around the
proxy names any address it likes and starts every login and token counter afresh; and it breaks
when the path's length changes (a CDN in front of the load balancer). Ranges believe only what
the proxies themselves wrote, on paths of any length.

:class:`TrustedProxies` rewrites ``REMOTE_ADDR`` as WSGI middleware, so everything that asks for
the client's address (``request.remote_addr``) gets the resolved one, whichever server runs the app.
The server must hand the header over as it came (cheroot does; which peers to believe is decided here).
"""

from __future__ import annotations

import ipaddress
import logging
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from _typeshed.wsgi import StartResponse, WSGIApplication, WSGIEnvironment

log = logging.getLogger(__name__)
Network = ipaddress.IPv4Network | ipaddress.IPv6Network
Address = ipaddress.IPv4Address | ipaddress.IPv6Address


def parse_address(text: str) -> Address | None:
    """``text`` as an IP address (an IPv4-mapped IPv6 one as its IPv4 address), or None."""
    try:
        address = ipaddress.ip_address(text.strip())
    except ValueError:
        return None
    if isinstance(address, ipaddress.IPv6Address) and address.ipv4_mapped is not None:
        return address.ipv4_mapped
    return address


def client_address(peer: str, forwarded_for: str, trusted: Sequence[Network]) -> str:
    """The client's address: ``peer`` (the socket's), unless it is a trusted proxy; then the
    rightmost address of ``forwarded_for`` (X-Forwarded-For, every such header joined by commas)
    outside ``trusted``. An entry that is not an address ends the walk at the trusted hop to its
    right, which wrote it: clients it stands for share that hop's address rather than naming one."""
    client = parse_address(peer)
    if client is None or not _is_trusted(client, trusted):
        return peer
    for entry in reversed(forwarded_for.split(",")):
        hop = parse_address(entry)
        if hop is None:
            break
        client = hop
        if not _is_trusted(hop, trusted):
            break
    return str(client)


def _is_trusted(address: Address, trusted: Iterable[Network]) -> bool:
    return any(address in network for network in trusted)


class TrustedProxies:
    """WSGI middleware: ``REMOTE_ADDR`` becomes :func:`client_address`'s answer.

    With no trusted proxies, a request carrying X-Forwarded-For is logged once (the app is probably
    behind a proxy it was not told about, and every client behind it then shares one address)."""

    def __init__(self, app: WSGIApplication, trusted: Sequence[Network]) -> None:
        self.app = app
        self.trusted = tuple(trusted)
        self._warned = False

    def __call__(self, environ: WSGIEnvironment, start_response: StartResponse) -> Iterable[bytes]:
        peer, forwarded_for = environ.get("REMOTE_ADDR", ""), environ.get("HTTP_X_FORWARDED_FOR", "")
        if self.trusted:
            environ["REMOTE_ADDR"] = client_address(peer, forwarded_for, self.trusted)
        elif forwarded_for and not self._warned:
            self._warned = True
            log.warning("a request from %s carried X-Forwarded-For, which is ignored: trusted_proxies is empty, so "
                        "login and token limits count every client behind that proxy as one address", peer)
        return self.app(environ, start_response)
