"""Server hardening: loopback bind, Origin and Host checks, no share tunnel (real sockets)."""

from __future__ import annotations

import asyncio
import http.client

import pytest
import viser
import websockets
from websockets.datastructures import Headers
from websockets.http11 import Request

from app.ui.security import OriginPolicy, create_server


def _req(headers: dict[str, str]) -> Request:
    return Request("/", Headers(headers))


def test_policy_same_origin_only() -> None:
    pol = OriginPolicy("127.0.0.1")
    ws = {"Upgrade": "websocket"}
    assert pol.check(_req({**ws, "Host": "127.0.0.1:8080", "Origin": "http://127.0.0.1:8080"}))[0]
    assert pol.check(_req({**ws, "Host": "localhost:8080", "Origin": "http://localhost:8080"}))[0]
    assert pol.check(_req({**ws, "Host": "127.0.0.1:8080"}))[0]  # no Origin: not a browser
    assert not pol.check(_req({**ws, "Host": "127.0.0.1:8080", "Origin": "http://evil.example"}))[0]
    assert not pol.check(_req({**ws, "Host": "127.0.0.1:8080", "Origin": "http://127.0.0.1:9999"}))[0]
    # DNS rebinding: a foreign Host name is refused when bound to loopback, even for plain HTTP
    assert not pol.check(_req({"Host": "evil.example:8080"}))[0]
    assert not pol.check(_req({}))[0]
    allowed = OriginPolicy("127.0.0.1", extra_origins=["http://dashboard.local:3000"])
    assert allowed.check(_req({**ws, "Host": "127.0.0.1:8080", "Origin": "http://dashboard.local:3000"}))[0]
    exposed = OriginPolicy("0.0.0.0")
    assert exposed.check(_req({**ws, "Host": "robot.lan:8080", "Origin": "http://robot.lan:8080"}))[0]
    assert not exposed.check(_req({**ws, "Host": "robot.lan:8080", "Origin": "http://evil.example"}))[0]


@pytest.fixture()
def hardened():
    server, policy = create_server("127.0.0.1", 0)
    try:
        yield server, policy
    finally:
        server.stop()


def _ws_status(port: int, origin: str | None) -> int:
    async def go() -> int:
        try:
            async with websockets.connect(
                f"ws://127.0.0.1:{port}", origin=origin, subprotocols=[f"viser-v{viser.__version__}"], open_timeout=10
            ):
                return 101
        except websockets.exceptions.InvalidStatus as e:
            return e.response.status_code

    return asyncio.run(go())


def test_real_server_refuses_foreign_origin(hardened) -> None:
    server, policy = hardened
    port = server.get_port()
    assert server.get_host() == "127.0.0.1"
    assert _ws_status(port, f"http://127.0.0.1:{port}") == 101
    assert _ws_status(port, None) == 101
    assert _ws_status(port, "http://evil.example") == 403
    assert policy.refused == 1


def test_real_server_refuses_foreign_host(hardened) -> None:
    server, _ = hardened
    conn = http.client.HTTPConnection("127.0.0.1", server.get_port(), timeout=10)
    conn.putrequest("GET", "/", skip_host=True)
    conn.putheader("Host", f"rebind.example:{server.get_port()}")
    conn.endheaders()
    assert conn.getresponse().status == 403
    conn = http.client.HTTPConnection("127.0.0.1", server.get_port(), timeout=10)
    conn.request("GET", "/")
    assert conn.getresponse().status == 200


def test_share_tunnel_disabled(hardened) -> None:
    server, _ = hardened
    assert server.request_share_url() is None
    handlers = server._websock_server._incoming_handlers  # viser 1.1.1 internal
    assert not handlers.get(viser._messages.ShareUrlRequest)
    assert not handlers.get(viser._messages.ShareUrlDisconnect)
