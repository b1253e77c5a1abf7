"""A minimal viser 1.1.1 protocol client (no browser): counts bytes and can press GUI buttons.

Used by ``ocslam bench ui`` (bytes per tick per client) and by the multi-client tests. It speaks the
same wire format as viser's browser client: subprotocol ``viser-v<version>``; server frames are
``[8 B inner len][8 B compressed len][zstd msgpack {"messages": [...]}][aligned binary buffers]``;
client messages are msgpack dicts with a ``type``. viser registers a client only after its first
``ViewerCameraMessage``, so :meth:`connect` sends one.
"""

from __future__ import annotations

import asyncio
import threading
import time
from dataclasses import dataclass, field
from typing import Any

import msgspec
import viser
import websockets
import zstandard


@dataclass
class ClientStats:
    frames: int = 0
    bytes: int = 0
    first_t: float = 0.0
    last_t: float = 0.0
    labels: dict[str, str] = field(default_factory=dict)  # GUI label → uuid
    message_types: dict[str, int] = field(default_factory=dict)


class FakeViserClient:
    """Connects in a background thread; ``stats`` grows as frames arrive."""

    def __init__(self, port: int, host: str = "127.0.0.1", origin: str | None = None, decode: bool = True) -> None:
        self.url = f"ws://{host}:{port}"
        self.origin = origin
        self.decode = decode
        self.stats = ClientStats()
        self._loop = asyncio.new_event_loop()
        self._ws: Any = None
        self._ready = threading.Event()
        self._closed = threading.Event()
        self.error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, daemon=True, name="fake-viser-client")
        self._dctx = zstandard.ZstdDecompressor()

    # -- lifecycle --------------------------------------------------------------------------------
    def connect(self, timeout: float = 20.0) -> FakeViserClient:
        self._thread.start()
        if not self._ready.wait(timeout):
            raise TimeoutError(f"could not connect to {self.url}: {self.error}")
        if self.error:
            raise self.error
        return self

    def close(self) -> None:
        if self._ws is not None and not self._closed.is_set():
            fut = asyncio.run_coroutine_threadsafe(self._ws.close(), self._loop)
            try:
                fut.result(timeout=5)
            except Exception:
                pass
        self._closed.wait(5)

    def abort(self) -> None:
        """Drop the TCP connection without a close handshake (a client vanishing mid-stream)."""
        if self._ws is not None:
            self._loop.call_soon_threadsafe(self._ws.transport.abort)
        self._closed.wait(5)

    # -- messages -------------------------------------------------------------------------------
    def send(self, message: dict[str, Any]) -> None:
        data = msgspec.msgpack.encode(message)
        asyncio.run_coroutine_threadsafe(self._ws.send(data), self._loop).result(timeout=5)

    def click(self, label: str) -> None:
        self.send({"type": "GuiUpdateMessage", "uuid": self.uuid(label), "updates": {"value": True}})

    def set_value(self, label: str, value: Any) -> None:
        self.send({"type": "GuiUpdateMessage", "uuid": self.uuid(label), "updates": {"value": value}})

    def uuid(self, label: str, timeout: float = 10.0) -> str:
        t0 = time.monotonic()
        while label not in self.stats.labels:
            if time.monotonic() - t0 > timeout:
                raise KeyError(f"no GUI element labelled {label!r}")
            time.sleep(0.05)
        return self.stats.labels[label]

    # -- internals ------------------------------------------------------------------------------
    def _camera_message(self) -> dict[str, Any]:
        return {
            "type": "ViewerCameraMessage",
            "wxyz": (1.0, 0.0, 0.0, 0.0),
            "position": (3.0, 3.0, 3.0),
            "fov": 1.0,
            "near": 0.01,
            "far": 1000.0,
            "image_height": 600,
            "image_width": 800,
            "look_at": (0.0, 0.0, 0.0),
            "up_direction": (0.0, 0.0, 1.0),
        }

    def _run(self) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._loop.run_until_complete(self._main())
        except BaseException as e:  # noqa: BLE001
            self.error = e
            self._ready.set()
        finally:
            self._closed.set()

    async def _main(self) -> None:
        async with websockets.connect(
            self.url, origin=self.origin, subprotocols=[f"viser-v{viser.__version__}"], max_size=None,
            open_timeout=20,
        ) as ws:
            self._ws = ws
            await ws.send(msgspec.msgpack.encode(self._camera_message()))
            self._ready.set()
            async for raw in ws:
                now = time.perf_counter()
                st = self.stats
                if not st.frames:
                    st.first_t = now
                st.frames += 1
                st.bytes += len(raw)
                st.last_t = now
                if self.decode and isinstance(raw, (bytes, bytearray)):
                    self._decode(bytes(raw))

    def _decode(self, raw: bytes) -> None:
        inner_len = int.from_bytes(raw[0:8], "little")
        comp_len = int.from_bytes(raw[8:16], "little")
        try:
            inner = self._dctx.decompress(raw[16 : 16 + comp_len], max_output_size=inner_len)
            payload = msgspec.msgpack.decode(inner)
        except Exception:
            return
        for m in payload.get("messages", ()):
            t = m.get("type", "?")
            self.stats.message_types[t] = self.stats.message_types.get(t, 0) + 1
            props = m.get("props") if isinstance(m.get("props"), dict) else None
            label = props.get("label") if props else None
            if label and "uuid" in m:
                self.stats.labels[str(label)] = m["uuid"]
