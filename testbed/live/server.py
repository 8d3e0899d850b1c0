"""The console's web server: one static page, a state endpoint and a WebSocket, on its own thread.

Stack: Starlette (routing, WebSocket) on uvicorn (ASGI server, ``websockets`` protocol) — small,
maintained, typed, no build step; the page is plain HTML and JavaScript served from the package
(``testbed/live/static/``).

Routes: ``/`` the page, ``/console.js`` its script, ``/state`` the latest state as JSON (for
tests and scripts), ``/ws`` the WebSocket. The first browser connected is the **pilot**; later
ones are read-only viewers (their control messages are counted ``not_pilot`` and ignored);
when the pilot leaves, the oldest viewer becomes the pilot. Each connection gets every
published state (the newest only, if it falls behind: a slow viewer never holds up another or
the simulation).

Bytes that are not HTTP at all (a garbled request line, a malformed chunked body) are answered
400 by uvicorn's parser (httptools: its h11 alternative logged a traceback for a malformed body
that arrives while the app answers) and counted ``bad_requests``; the warning uvicorn would log
for each is not printed, so a flood of them cannot fill the pilot's terminal.

Browser input is data: each text frame is size-checked, rate-limited
(:class:`~testbed.live.messages.RateLimit`), parsed (:func:`~testbed.live.messages.parse_message`)
and counted; sticks go to the :class:`~testbed.operator.live_pilot.LivePilot`'s queue, other
control messages to the :class:`~testbed.live.hub.Hub`; pings are answered at once.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import socket
import threading
import time
from importlib import resources
from typing import Any

import uvicorn
from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import HTMLResponse, JSONResponse, Response
from starlette.routing import Route, WebSocketRoute
from starlette.websockets import WebSocket, WebSocketDisconnect

from testbed.live.hub import Hub
from testbed.live.messages import (
    MAX_MESSAGE_BYTES,
    InputCounters,
    LatencyReport,
    Ping,
    RateLimit,
    Rejected,
    StickInput,
    parse_message,
)
from testbed.operator.live_pilot import LivePilot

__all__ = ["ConsoleServer", "bind", "build_app"]

_CENTRE = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
_UVICORN_LOG = "uvicorn.error"
"""uvicorn's logger for its protocols' warnings."""
_BAD_REQUEST_WARNINGS = frozenset(
    {"Invalid HTTP request received.", "Unsupported upgrade request."}
)
"""What uvicorn's HTTP protocol logs for a request it answers 400 (or cannot upgrade)."""


class _BadRequestCounter(logging.Filter):
    """Counts uvicorn's bad-request warnings into ``counters.bad_requests`` and drops them."""

    def __init__(self, counters: InputCounters) -> None:
        super().__init__()
        self._counters = counters

    def filter(self, record: logging.LogRecord) -> bool:
        if record.msg in _BAD_REQUEST_WARNINGS:
            self._counters.bad_requests += 1
            return False
        return True


def _static(name: str) -> str:
    return resources.files("testbed.live").joinpath("static", name).read_text(encoding="utf-8")


class _Connection:
    """One browser: its socket, its role and a wake-up for its sender."""

    def __init__(self, websocket: WebSocket) -> None:
        self.websocket = websocket
        self.pilot = False
        self.wake = asyncio.Event()
        self.limit = RateLimit()


class _Console:
    """The app's state: the connections, the pilot's seat, the hub and the live pilot."""

    def __init__(self, hub: Hub, pilot: LivePilot) -> None:
        self.hub = hub
        self.pilot = pilot
        self.connections: list[_Connection] = []

    def seat(self, conn: _Connection) -> None:
        """Give ``conn`` the pilot's seat if it is free."""
        if not any(c.pilot for c in self.connections):
            conn.pilot = True

    def leave(self, conn: _Connection) -> None:
        self.connections.remove(conn)
        if conn.pilot:
            self.pilot.submit(_CENTRE)  # sticks to centre at once, not after the dead man
            if self.connections:
                self.connections[0].pilot = True
                self.connections[0].wake.set()
        self.hub.viewers = len(self.connections)

    def broadcast(self) -> None:
        for conn in self.connections:
            conn.wake.set()

    def receive(self, conn: _Connection, text: str) -> dict[str, Any] | None:
        """Handle one text frame; returns an immediate answer (pong), if any."""
        received_ns = time.monotonic_ns()
        counters = self.hub.counters
        if not conn.limit.allow():
            counters.flooded += 1
            return None
        if len(text) > MAX_MESSAGE_BYTES:
            counters.malformed += 1
            return None
        parsed = parse_message(text)
        counters.count(parsed)
        if isinstance(parsed, Rejected):
            return {"t": "rejected", "kind": parsed.kind, "reason": parsed.reason}
        if isinstance(parsed, Ping):
            return {"t": "pong", "c": parsed.client_ms, "s": time.monotonic_ns() / 1e6}
        if isinstance(parsed, LatencyReport):
            if conn.pilot and parsed.pixels_ms is not None:
                self.hub.pixel_latencies_ms.append(parsed.pixels_ms)
            if conn.pilot and parsed.rtt_ms is not None:
                self.hub.round_trips_ms.append(parsed.rtt_ms)
            return None
        if not conn.pilot:
            counters.not_pilot += 1
            return None
        if isinstance(parsed, StickInput):
            self.pilot.submit(parsed.sticks(), received_ns)
        else:
            self.hub.submit(parsed, received_ns)
        return None


async def _sender(console: _Console, conn: _Connection) -> None:
    """Send each new state (the newest only) to one browser."""
    while True:
        await conn.wake.wait()
        conn.wake.clear()
        state = console.hub.latest
        if state is None:
            continue
        document = dict(state)
        document["role"] = "pilot" if conn.pilot else "viewer"
        document["viewers"] = len(console.connections)
        await conn.websocket.send_text(json.dumps(document))


def build_app(hub: Hub, pilot: LivePilot) -> tuple[Starlette, _Console]:
    """The Starlette app serving the console for ``hub`` and ``pilot``."""
    console = _Console(hub, pilot)
    page, script = _static("index.html"), _static("console.js")

    async def index(request: Request) -> Response:
        del request
        return HTMLResponse(page)

    async def code(request: Request) -> Response:
        del request
        return Response(script, media_type="text/javascript")

    async def state(request: Request) -> Response:
        del request
        latest = hub.latest
        return JSONResponse({"state": latest, "viewers": len(console.connections)})

    async def ws(websocket: WebSocket) -> None:
        await websocket.accept()
        conn = _Connection(websocket)
        console.seat(conn)
        console.connections.append(conn)
        hub.viewers = len(console.connections)
        conn.wake.set()
        sender = asyncio.create_task(_sender(console, conn))
        try:
            while True:
                message = await websocket.receive()
                if message["type"] == "websocket.disconnect":
                    break
                text = message.get("text")
                if text is None:  # binary frames are not part of the protocol
                    hub.counters.malformed += 1
                    continue
                answer = console.receive(conn, text)
                if answer is not None:
                    await websocket.send_text(json.dumps(answer))
        except (WebSocketDisconnect, RuntimeError):
            pass
        finally:
            sender.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await sender
            console.leave(conn)

    routes = [
        Route("/", index),
        Route("/console.js", code),
        Route("/state", state),
        WebSocketRoute("/ws", ws),
    ]
    return Starlette(routes=routes), console


def bind(host: str, port: int) -> socket.socket:
    """A listening TCP socket on ``host:port`` (port 0: any free one).

    Raises:
        OSError: the address cannot be bound (in use, not local).
    """
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
        sock.listen(64)
    except OSError:
        sock.close()
        raise
    sock.setblocking(False)
    return sock


class ConsoleServer:
    """uvicorn serving the console on a bound socket, on a daemon thread.

    Args:
        hub: the bridge to the session.
        pilot: the live pilot.
        sock: the listening socket (:func:`bind`).
    """

    def __init__(self, hub: Hub, pilot: LivePilot, sock: socket.socket) -> None:
        self.hub = hub
        self.sock = sock
        self.app, self.console = build_app(hub, pilot)
        config = uvicorn.Config(
            self.app,
            http="httptools",
            log_level="warning",
            lifespan="off",
            ws_max_size=16 * MAX_MESSAGE_BYTES,
        )
        self.server = uvicorn.Server(config)
        self._bad_requests = _BadRequestCounter(hub.counters)
        self._thread = threading.Thread(target=self._serve, name="live-console", daemon=True)

    @property
    def url(self) -> str:
        """The console's address."""
        host, port = self.sock.getsockname()[:2]
        return f"http://{f'[{host}]' if ':' in host else host}:{port}/"

    def start(self) -> None:
        """Serve from now on (returns at once)."""
        logging.getLogger(_UVICORN_LOG).addFilter(self._bad_requests)
        self._thread.start()

    def _serve(self) -> None:
        async def main() -> None:
            loop = asyncio.get_running_loop()
            event = asyncio.Event()
            self.hub.set_waker(loop, event)

            async def fan_out() -> None:
                while True:
                    await event.wait()
                    event.clear()
                    self.console.broadcast()

            task = asyncio.create_task(fan_out())
            try:
                await self.server.serve(sockets=[self.sock])
            finally:
                task.cancel()

        asyncio.run(main())

    def stop(self, timeout_s: float = 5.0) -> None:
        """Stop serving and wait up to ``timeout_s`` [s] for the thread."""
        self.server.should_exit = True
        self._thread.join(timeout_s)
        self.sock.close()
        logging.getLogger(_UVICORN_LOG).removeFilter(self._bad_requests)
