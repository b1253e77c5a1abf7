"""Hardening of viser 1.1.1's defaults (see docs/security.md).

viser binds every interface, accepts WebSocket connections from any web page's Origin and offers a
share tunnel to an outside server. :func:`create_server` changes all three:

1. it binds ``127.0.0.1`` unless told otherwise (``ocslam run --host`` is the explicit flag);
2. every HTTP/WebSocket request must name an allowed ``Host`` (loopback names when bound to
   loopback, which also defeats DNS rebinding), and a WebSocket handshake whose ``Origin`` is not the
   server's own (``http(s)://<Host header>``) or in the explicit allow-list is refused with 403;
   clients that send no Origin (non-browser tools) are allowed, as browsers always send one;
3. the share tunnel is disabled: the Share button is hidden, the client's ``ShareUrlRequest`` handler
   is removed and ``request_share_url`` does nothing;
4. on a non-loopback host every HTTP and WebSocket request must carry the server's random access
   token (``?token=…`` once, then a cookie), as Jupyter does (:class:`OriginPolicy`);
5. an address or port that cannot be bound is one :class:`ServerStartError` (no port hopping, no hang);
6. every GUI value a client sends is checked against what the server offered before viser applies
   it (:class:`GuiGuard`): a dropdown value must be one of its options, numbers finite and inside
   the slider's range, the right type, only the ``value`` property, nothing for a disabled element,
   no file uploads;
7. every path the GUI can name is confined to a root and notifications are one line that never
   quotes a file (:mod:`app.ui.confine`: :func:`~app.ui.confine.confine_path`, :func:`~app.ui.confine.safe_message`).

This relies on viser 1.1.1 internals (pinned exactly in pyproject.toml).
"""

from __future__ import annotations

import contextlib
import errno
import functools
import hmac
import http
import ipaddress
import logging
import math
import secrets
import socket
import threading
import time
import urllib.parse
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import viser
import websockets.asyncio.server
from websockets.datastructures import Headers
from websockets.http11 import Request, Response

from app.config import ConfigError

log = logging.getLogger(__name__)


class ServerStartError(ConfigError):
    """The server cannot listen where it was told to (``ocslam: error: …``, exit code 2)."""


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


TOKEN_PARAM = "token"


def new_token() -> str:
    """A random access token (URL-safe, 192 bits)."""
    return secrets.token_urlsafe(24)


def _cookie_name(host_header: str | None) -> str:
    """One cookie per port: cookies are shared by every port of a host, tokens are not."""
    _, port = _split_host(host_header or "")
    return f"ocslam_token_{port or 'default'}"


def _cookies(header: str | None) -> dict[str, str]:
    out: dict[str, str] = {}
    for part in (header or "").split(";"):
        name, sep, value = part.strip().partition("=")
        if sep:
            out[name.strip()] = value.strip()
    return out


@dataclass
class OriginPolicy:
    """Which Host headers, Origins and tokens a server accepts.

    ``token`` (None: no token needed) must come with every request, either as ``?token=…`` in the
    URL or as the cookie the server sets on the first request that had it (the viser page opens its
    WebSocket at the bare URL, so the cookie is what lets the browser in).
    """

    bind_host: str
    extra_origins: list[str] = field(default_factory=list)
    token: str | None = None
    refused: int = 0  # handshakes refused (Origin, Host or token)
    refused_token: int = 0  # of which for a missing or wrong token

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

    def _token_ok(self, given: str | None) -> bool:
        return given is not None and self.token is not None and hmac.compare_digest(
            given.encode("utf-8", "replace"), self.token.encode("utf-8")
        )

    def token_source(self, request: Request) -> str | None:
        """'query' or 'cookie' when the request carries the right token, else None."""
        query = urllib.parse.parse_qs(urllib.parse.urlsplit(request.path).query)
        if any(self._token_ok(t) for t in query.get(TOKEN_PARAM, [])):
            return "query"
        cookie = _cookies(request.headers.get("Cookie")).get(_cookie_name(request.headers.get("Host")))
        if self._token_ok(cookie):
            return "cookie"
        return None

    def check(self, request: Request) -> tuple[bool, str]:
        host = request.headers.get("Host")
        if not self.host_allowed(host):
            return False, f"Host {host!r} not allowed"
        if request.headers.get("Upgrade", "").lower() == "websocket":
            origin = request.headers.get("Origin")
            if not self.origin_allowed(origin, host):
                return False, f"Origin {origin!r} is not this server's"
        if self.token is not None and self.token_source(request) is None:
            return False, "an access token is required: open the URL that `ocslam run` printed (it ends in ?token=…)"
        return True, ""


def _text_response(status: http.HTTPStatus, text: str, extra: dict[str, str] | None = None) -> Response:
    body = text.encode()
    headers = Headers({"Content-Type": "text/plain; charset=utf-8", "Content-Length": str(len(body))})
    for k, v in (extra or {}).items():
        headers[k] = v
    return Response(status, status.phrase, headers, body)


def _without_token(path: str) -> str:
    parts = urllib.parse.urlsplit(path)
    query = [(k, v) for k, v in urllib.parse.parse_qsl(parts.query, keep_blank_values=True) if k != TOKEN_PARAM]
    return urllib.parse.urlunsplit(("", "", parts.path or "/", urllib.parse.urlencode(query), ""))


def _guard(policy: OriginPolicy, inner: Any):
    def process_request(connection: Any, request: Request) -> Response | None:
        ok, why = policy.check(request)
        if not ok:
            policy.refused += 1
            if why.startswith("an access token"):
                policy.refused_token += 1
            log.warning("refused connection: %s", why)
            return _text_response(http.HTTPStatus.FORBIDDEN, f"403 Forbidden: {why}\n")
        is_ws = request.headers.get("Upgrade", "").lower() == "websocket"
        if policy.token is not None and not is_ws and policy.token_source(request) == "query":
            # Jupyter-style: remember the token in a cookie (the page's WebSocket carries it) and drop it
            # from the address bar.
            cookie = (f"{_cookie_name(request.headers.get('Host'))}={policy.token}; Path=/; HttpOnly; "
                      "SameSite=Strict")
            return _text_response(http.HTTPStatus.SEE_OTHER, "signed in\n",
                                  {"Location": _without_token(request.path), "Set-Cookie": cookie})
        return inner(connection, request) if inner is not None else None

    return process_request


@dataclass
class _BindWatch:
    """What the patched ``serve`` saw while viser tried to bind."""

    port: int
    error: OSError | None = None
    failed: threading.Event = field(default_factory=threading.Event)


class _WatchedServe:
    """``websockets.asyncio.server.serve(...)`` whose bind failure is recorded (viser swallows it)."""

    def __init__(self, inner: Any, watch: _BindWatch) -> None:
        self._inner = inner
        self._watch = watch

    async def __aenter__(self) -> Any:
        try:
            return await self._inner.__aenter__()
        except OSError as e:
            self._watch.error = e
            self._watch.failed.set()
            raise

    async def __aexit__(self, *exc: Any) -> Any:
        return await self._inner.__aexit__(*exc)


@contextlib.contextmanager
def _guarded_serve(policy: OriginPolicy, watch: _BindWatch) -> Iterator[None]:
    """Patch ``websockets.asyncio.server.serve`` while a ViserServer starts (it binds in its constructor)."""
    original = websockets.asyncio.server.serve

    @functools.wraps(original)
    def serve(*args: Any, **kwargs: Any):
        port = args[2] if len(args) > 2 else kwargs.get("port")
        if watch.failed.is_set() or (watch.port and port != watch.port):
            # viser would silently move on to the next port (up to +1000): stay where we were told
            raise OSError(errno.EADDRINUSE, f"port {watch.port} is not available")
        kwargs["process_request"] = _guard(policy, kwargs.get("process_request"))
        return _WatchedServe(original(*args, **kwargs), watch)

    with _patch_lock:
        websockets.asyncio.server.serve = serve  # type: ignore[assignment]
        try:
            yield
        finally:
            websockets.asyncio.server.serve = original  # type: ignore[assignment]


def check_bindable(host: str, port: int) -> None:
    """Raise :class:`ServerStartError` (one line) if ``host:port`` cannot be listened on right now."""
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except (socket.gaierror, UnicodeError) as e:
        raise ServerStartError(f"cannot listen on {host!r}: not a known address ({getattr(e, 'strerror', e)})") from None
    if not infos:
        raise ServerStartError(f"cannot listen on {host!r}: not a known address")
    for family, kind, proto, _, addr in infos:
        with socket.socket(family, kind, proto) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as asyncio's server does
            try:
                s.bind(addr)
            except OSError as e:
                why = {errno.EADDRINUSE: "the port is in use", errno.EADDRNOTAVAIL: "not an address of this machine",
                       errno.EACCES: "permission denied (ports below 1024 need root)"}.get(e.errno, e.strerror)
                raise ServerStartError(f"cannot listen on {host}:{port}: {why}") from None


def disable_share(server: viser.ViserServer) -> None:
    """No share tunnel: hide the button, drop the client's request handlers, neuter the method."""
    server.gui.configure_theme(show_share_button=False)
    ws = server._websock_server  # viser 1.1.1 internal
    for msg_type in (viser._messages.ShareUrlRequest, viser._messages.ShareUrlDisconnect):
        with contextlib.suppress(Exception):
            ws.unregister_handler(msg_type)
    server.request_share_url = lambda *a, **k: None  # type: ignore[method-assign]


def disable_uploads(server: viser.ViserServer) -> None:
    """No file uploads: OCSLAM has no upload button, and viser 1.1.1 accepts an upload aimed at *any*
    input's uuid (a text field's value would become the uploaded bytes)."""
    ws = server._websock_server
    for msg_type in (viser._messages.FileTransferStartUpload, viser._messages.FileTransferPart):
        with contextlib.suppress(Exception):
            ws.unregister_handler(msg_type)


def create_server(
    host: str = "127.0.0.1",
    port: int = 8080,
    *,
    allow_origins: list[str] | None = None,
    label: str | None = None,
    token: str | None = None,
    start_timeout_s: float = 30.0,
) -> tuple[viser.ViserServer, OriginPolicy]:
    """A hardened viser server. ``port=0`` picks a free port (read it with ``server.get_port()``).

    ``token``: required on every request (see :class:`OriginPolicy`); None for none. Raises
    :class:`ServerStartError` when ``host:port`` cannot be bound (busy port, foreign address): viser
    itself would hop to the next port or, for an address that is not local, wait forever.
    """
    check_bindable(host, port)
    policy = OriginPolicy(bind_host=host, extra_origins=list(allow_origins or []), token=token)
    watch = _BindWatch(port=int(port))
    box: dict[str, Any] = {}
    done = threading.Event()

    def build() -> None:
        try:
            box["server"] = viser.ViserServer(host=host, port=port, label=label, verbose=False)
        except BaseException as e:  # noqa: BLE001 - handed to the caller
            box["error"] = e
        finally:
            done.set()

    with _guarded_serve(policy, watch):
        # viser binds in its constructor and blocks until bound; when binding fails it never returns,
        # so build it in a helper thread and watch the bind attempt.
        threading.Thread(target=build, name="viser-start", daemon=True).start()
        t0 = time.monotonic()
        while not done.wait(0.02):
            if watch.failed.is_set():
                e = watch.error
                raise ServerStartError(f"cannot listen on {host}:{port}: {e.strerror if e else 'bind failed'}")
            if time.monotonic() - t0 > start_timeout_s:
                raise ServerStartError(f"cannot listen on {host}:{port}: the server did not start in {start_timeout_s:.0f} s")
    if "error" in box:
        raise box["error"]
    server = box["server"]
    disable_share(server)
    disable_uploads(server)
    return server, policy


# ----------------------------------------------------------------------------------------------
# GUI values from clients
# ----------------------------------------------------------------------------------------------
MAX_TEXT_CHARS = 1024


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def check_gui_value(handle: Any, updates: Any) -> str | None:
    """Why a client's ``GuiUpdateMessage.updates`` for ``handle`` is refused, or None if it is fine.

    Checked against the server's own state of the element (its options, range, type), before viser
    casts or applies anything. Deny by default: element kinds the app does not let clients set are
    refused.
    """
    if not isinstance(updates, dict) or set(updates) != {"value"}:
        # viser's client only ever sends "value"; anything else would overwrite server-side state
        # (props, callbacks) through viser's setattr
        return "only the value of a GUI element can be set"
    v = updates["value"]
    props = handle._impl.props
    if getattr(props, "disabled", False):
        return "the element is disabled"
    current = handle._impl.value
    if isinstance(handle, viser.GuiButtonHandle):
        return None if v is True else "a button can only be pressed"
    if isinstance(handle, viser.GuiCheckboxHandle):
        return None if isinstance(v, bool) else "a checkbox is true or false"
    if isinstance(handle, (viser.GuiDropdownHandle, viser.GuiButtonGroupHandle)):
        if not isinstance(v, str):
            return "not one of the offered options (not a string)"
        return None if v in tuple(props.options) else "not one of the offered options"
    if isinstance(handle, (viser.GuiSliderHandle, viser.GuiNumberHandle)):
        if not _is_number(v):
            return "not a number"
        if not math.isfinite(v):
            return "not a finite number"
        lo, hi = getattr(props, "min", None), getattr(props, "max", None)
        tol = 1e-9 * max(1.0, abs(lo or 0.0), abs(hi or 0.0))
        if lo is not None and v < lo - tol or hi is not None and v > hi + tol:
            return f"outside the range {lo:g} … {hi:g}" if lo is not None and hi is not None else "outside the allowed range"
        if isinstance(current, int) and not isinstance(current, bool) and float(v) != int(v):
            return "not a whole number"
        return None
    if isinstance(handle, viser.GuiTextHandle):
        if not isinstance(v, str):
            return "not text"
        if len(v) > MAX_TEXT_CHARS:
            return f"longer than {MAX_TEXT_CHARS} characters"
        allowed = "\n\t" if getattr(props, "multiline", False) else ""
        if any(ord(c) < 32 and c not in allowed or ord(c) == 127 for c in v):
            return "contains control characters"
        return None
    if isinstance(handle, (viser.GuiVector2Handle, viser.GuiVector3Handle, viser.GuiRgbHandle, viser.GuiRgbaHandle)):
        if not isinstance(v, (list, tuple)) or len(v) != len(current) or not all(_is_number(x) for x in v):
            return f"not {len(current)} numbers"
        if not all(math.isfinite(x) for x in v):
            return "not finite numbers"
        if isinstance(handle, (viser.GuiRgbHandle, viser.GuiRgbaHandle)) and not all(
            float(x).is_integer() and 0 <= x <= 255 for x in v
        ):
            return "colour channels are whole numbers 0 … 255"
        return None
    return f"a {type(handle).__name__} cannot be set by a client"


@dataclass
class Refusal:
    client_id: int
    label: str
    reason: str


class GuiGuard:
    """Checks every ``GuiUpdateMessage`` a client sends before viser applies it (:func:`check_gui_value`).

    A refused value is not applied and no callback runs; the sending client gets the server's value
    back (its widget reverts) and ``on_refused(client_id, one_line_message)`` is called (the app shows
    a notification). ``refusals`` keeps the last 100 (for tests and logs).
    """

    def __init__(self, server: viser.ViserServer, on_refused: Callable[[int, str], None] | None = None) -> None:
        self.server = server
        self.on_refused = on_refused
        self.refused = 0
        self.refusals: list[Refusal] = []
        gui = server.gui
        ws = server._websock_server  # viser 1.1.1 internals
        self._original = gui._handle_gui_updates
        handlers = ws._incoming_handlers.get(viser._messages.GuiUpdateMessage, [])
        if self._original not in handlers:
            raise RuntimeError("viser's GUI update handler was not found (viser version changed?)")
        ws.unregister_handler(viser._messages.GuiUpdateMessage, self._original)
        ws.register_handler(viser._messages.GuiUpdateMessage, self._handle)

    async def _handle(self, client_id: Any, message: Any) -> None:
        handle = self.server.gui._gui_input_handle_from_uuid.get(message.uuid)
        if handle is None or handle._impl.removed:
            return  # viser ignores these too
        reason = check_gui_value(handle, message.updates)
        if reason is None:
            await self._original(client_id, message)
            return
        label = str(getattr(handle._impl.props, "label", "") or "?")[:60]
        self.refused += 1
        self.refusals = (self.refusals + [Refusal(int(client_id), label, reason)])[-100:]
        log.warning("refused a GUI value from client %s for %r: %s", client_id, label, reason)
        client = self.server.get_clients().get(client_id)
        if client is not None and not handle._impl.is_button:
            with contextlib.suppress(Exception):  # show the server's value again in that client's widget
                client._websock_connection.queue_message(
                    viser._messages.GuiUpdateMessage(handle._impl.uuid, {"value": handle._impl.value})
                )
        if self.on_refused is not None:
            with contextlib.suppress(Exception):
                self.on_refused(int(client_id), f"{label}: {reason}")
