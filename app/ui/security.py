"""Hardening of viser 1.1.1's defaults (see docs/security.md).

viser binds every interface, accepts WebSocket connections from any web page's Origin and offers a
share tunnel to an outside server. :func:`create_server` changes all three:

1. it binds ``127.0.0.1`` unless told otherwise (``ocslam run --host`` is the explicit flag);
2. every HTTP/WebSocket request must name an allowed ``Host`` (loopback names when bound to
   loopback, which also defeats DNS rebinding), and a WebSocket handshake whose ``Origin`` is not the
   server's own (``http(s)://<Host header>``) or in the explicit allow-list is refused with 403;
   clients that send no Origin (non-browser tools) are allowed, as browsers always send one;
3. the share tunnel is disabled: the Share button is hidden, the client's ``ShareUrlRequest`` handler
   is removed and ``request_share_url`` does nothing.

This relies on viser 1.1.1 internals (pinned exactly in pyproject.toml).
"""

from __future__ import annotations

import contextlib
import functools
import http
import ipaddress
import logging
import threading
from dataclasses import dataclass, field
from typing import Any, Iterator

import viser
import websockets.asyncio.server
from websockets.datastructures import Headers
from websockets.http11 import Request, Response

log = logging.getLogger(__name__)

LOOPBACK_NAMES = ("127.0.0.1", "localhost", "[::1]", "::1")
_patch_lock = threading.Lock()


def is_loopback(host: str) -> bool:
    h = host.strip("[]")
    if h == "localhost":
        return True
    try:
        return ipaddress.ip_address(h).is_loopback
    except ValueError:
        return False


def _split_host(host_header: str) -> tuple[str, str]:
    """'127.0.0.1:8080' → ('127.0.0.1', '8080'); '[::1]:80' → ('[::1]', '80')."""
    h = host_header.strip().lower()
    if h.startswith("["):
        end = h.find("]")
        return h[: end + 1], h[end + 2 :] if end + 1 < len(h) and h[end + 1] == ":" else ""
    name, _, port = h.partition(":")
    return name, port


@dataclass
class OriginPolicy:
    """Which Host headers and Origins a server accepts."""

    bind_host: str
    extra_origins: list[str] = field(default_factory=list)
    refused: int = 0  # handshakes refused (Origin or Host)

    def host_allowed(self, host_header: str | None) -> bool:
        if host_header is None:
            return False
        name, _ = _split_host(host_header)
        if is_loopback(self.bind_host):
            return name in LOOPBACK_NAMES or is_loopback(name)
        return True  # exposed on purpose (--host): any name the client used to reach us

    def origin_allowed(self, origin: str | None, host_header: str | None) -> bool:
        if origin is None:
            return True  # not a browser
        origin = origin.strip().lower().rstrip("/")
        if origin in (o.lower().rstrip("/") for o in self.extra_origins):
            return True
        if host_header is None:
            return False
        own = host_header.strip().lower()
        return origin in (f"http://{own}", f"https://{own}")

    def check(self, request: Request) -> tuple[bool, str]:
        host = request.headers.get("Host")
        if not self.host_allowed(host):
            return False, f"Host {host!r} not allowed"
        if request.headers.get("Upgrade", "").lower() == "websocket":
            origin = request.headers.get("Origin")
            if not self.origin_allowed(origin, host):
                return False, f"Origin {origin!r} is not this server's"
        return True, ""


def _guard(policy: OriginPolicy, inner: Any):
    def process_request(connection: Any, request: Request) -> Response | None:
        ok, why = policy.check(request)
        if not ok:
            policy.refused += 1
            log.warning("refused connection: %s", why)
            body = f"403 Forbidden: {why}\n".encode()
            return Response(
                http.HTTPStatus.FORBIDDEN,
                "Forbidden",
                Headers({"Content-Type": "text/plain; charset=utf-8", "Content-Length": str(len(body))}),
                body,
            )
        return inner(connection, request) if inner is not None else None

    return process_request


@contextlib.contextmanager
def _guarded_serve(policy: OriginPolicy) -> Iterator[None]:
    """Patch ``websockets.asyncio.server.serve`` while a ViserServer starts (it binds in its constructor)."""
    original = websockets.asyncio.server.serve

    @functools.wraps(original)
    def serve(*args: Any, **kwargs: Any):
        kwargs["process_request"] = _guard(policy, kwargs.get("process_request"))
        return original(*args, **kwargs)

    with _patch_lock:
        websockets.asyncio.server.serve = serve  # type: ignore[assignment]
        try:
            yield
        finally:
            websockets.asyncio.server.serve = original  # type: ignore[assignment]


def disable_share(server: viser.ViserServer) -> None:
    """No share tunnel: hide the button, drop the client's request handlers, neuter the method."""
    server.gui.configure_theme(show_share_button=False)
    ws = server._websock_server  # viser 1.1.1 internal
    for msg_type in (viser._messages.ShareUrlRequest, viser._messages.ShareUrlDisconnect):
        with contextlib.suppress(Exception):
            ws.unregister_handler(msg_type)
    server.request_share_url = lambda *a, **k: None  # type: ignore[method-assign]


def create_server(
    host: str = "127.0.0.1", port: int = 8080, *, allow_origins: list[str] | None = None, label: str | None = None
) -> tuple[viser.ViserServer, OriginPolicy]:
    """A hardened viser server. ``port=0`` picks a free port (read it with ``server.get_port()``)."""
    policy = OriginPolicy(bind_host=host, extra_origins=list(allow_origins or []))
    with _guarded_serve(policy):
        server = viser.ViserServer(host=host, port=port, label=label, verbose=False)
    disable_share(server)
    if port and server.get_port() != port:
        log.warning("port %d was busy; listening on %d instead", port, server.get_port())
    return server, policy
