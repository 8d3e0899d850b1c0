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

Only the console's own pages may use it (:class:`_Guard`, in front of every route): a request
or WebSocket whose ``Host`` is not one of the console's own names (loopback names, the
``--host`` it was bound to; see :func:`own_names`) is answered 403 and counted
``foreign_host`` — a DNS-rebinding page names its own domain there. A WebSocket whose
``Origin`` is not the console's own (``http://`` + its ``Host``) is answered 403 and counted
``foreign_origin`` — a page of another site (or another port) cannot take the pilot's seat.
A WebSocket without ``Origin`` is served: browsers always send one, so it is a script or a
tool (no cross-site risk: it could open the socket anyway). At most
:data:`~testbed.live.messages.MAX_CONNECTIONS` WebSockets at once; more are answered 403,
counted ``too_many``.

Ending is quiet whatever the clients do: a WebSocket whose close is already under way, or whose
peer stopped reading, is dropped (uvicorn's own shutdown raised ``InvalidState`` for the first
and waited forever for the second), and uvicorn's error log is dropped once stopping.

Browser input is data: each text frame is size-checked, rate-limited
(:class:`~testbed.live.messages.RateLimit`), parsed (:func:`~testbed.live.messages.parse_message`)
and counted; sticks go to the :class:`~testbed.operator.live_pilot.LivePilot`'s queue, other
control messages to the :class:`~testbed.live.hub.Hub`; pings are answered at once.
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import json
import logging
import socket
import sys
import threading
import time
from collections.abc import Iterable
from importlib import resources
from typing import Any

import uvicorn
from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import HTMLResponse, JSONResponse, Response
from starlette.routing import Route, WebSocketRoute
from starlette.types import ASGIApp, Receive, Scope, Send
from starlette.websockets import WebSocket, WebSocketDisconnect
from uvicorn.protocols.websockets.websockets_sansio_impl import WebSocketsSansIOProtocol

from testbed.live.hub import Hub
from testbed.live.messages import (
    MAX_CONNECTIONS,
    MAX_MESSAGE_BYTES,
    InputCounters,
    LatencyReport,
    Ping,
    RateLimit,
    Rejected,
    StickInput,
    parse_message,
    too_long,
)
from testbed.operator.live_pilot import LivePilot

__all__ = ["ConsoleServer", "bind", "build_app", "own_names"]

_CENTRE = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
_UVICORN_LOG = "uvicorn.error"
"""uvicorn's logger for its protocols' warnings."""
_BAD_REQUEST_WARNINGS = frozenset(
    {"Invalid HTTP request received.", "Unsupported upgrade request."}
)
"""What uvicorn's HTTP protocol logs for a request it answers 400 (or cannot upgrade)."""


_GRACE_S = 2
"""How long the server waits for its connections to end when stopping [s]."""
_LOOPBACK_NAMES = frozenset({"localhost", "127.0.0.1", "[::1]"})
_ANY_ADDRESS = frozenset({"", "0.0.0.0", "::", "[::]"})
_TOO_BIG = 1009
"""WebSocket close code "message too big": the protocol closed a socket whose message passed
``ws_max_size`` before the console saw it (counted as malformed)."""


class _UvicornLog(logging.Filter):
    """Counts uvicorn's bad-request warnings into ``counters.bad_requests`` and drops them;
    drops its errors once the server is stopping (a connection cut mid-close is not news)."""

    def __init__(self, counters: InputCounters) -> None:
        super().__init__()
        self._counters = counters
        self.stopping = False

    def filter(self, record: logging.LogRecord) -> bool:
        if record.msg in _BAD_REQUEST_WARNINGS:
            self._counters.bad_requests += 1
            return False
        return not (self.stopping and record.levelno >= logging.ERROR)


class _WebSocketProtocol(WebSocketsSansIOProtocol):
    """uvicorn's WebSocket protocol, ending quietly: at shutdown a connection whose close is
    already under way (uvicorn raised ``InvalidState``) or whose peer stopped reading (uvicorn
    waited for the flush forever) is dropped."""

    def shutdown(self) -> None:
        try:
            super().shutdown()
        except Exception:  # the peer's close is under way: nothing more to say
            self.transport.abort()
            return
        if self.transport.get_write_buffer_size():
            self.transport.abort()


def _host_name(host: str) -> str:
    """The name in a ``Host`` header (lower case, IPv6 in brackets), without the port."""
    host = host.strip().lower()
    if host.startswith("["):
        return host[: host.find("]") + 1] if "]" in host else host
    return host.rpartition(":")[0] if host.count(":") == 1 else host


def _ip_literal(name: str) -> bool:
    try:
        ipaddress.ip_address(name.strip("[]"))
    except ValueError:
        return False
    return True


def own_names(host: str) -> frozenset[str]:
    """The names the console answers to when bound to ``host``: the loopback names and
    ``host`` itself; for an any-address bind (``0.0.0.0``, ``::``) also this machine's host
    name (any IP literal is accepted too: see :class:`_Guard`)."""
    names = set(_LOOPBACK_NAMES)
    name = host.strip().lower()
    if name in _ANY_ADDRESS:
        names.add("*ip")
        names.update(n.lower() for n in (socket.gethostname(), socket.getfqdn()) if n)
    elif ":" in name and not name.startswith("["):
        names.add(f"[{name}]")
    else:
        names.add(name)
    return frozenset(names)


class _Guard:
    """ASGI middleware: refuses (403, counted) a ``Host`` that is not one of ``names`` and a
    WebSocket whose ``Origin`` is not ``http://`` + its ``Host``.

    A ``Host`` naming an IP address is accepted when bound to any address (``"*ip"`` in
    ``names``): a browser that sent it reached this socket at that address, so its page's
    origin is the console's own — DNS rebinding needs a domain name. The port is not checked
    (an SSH tunnel changes it); the origin check compares it.
    """

    def __init__(self, app: ASGIApp, names: Iterable[str], counters: InputCounters) -> None:
        self.app = app
        self.names = frozenset(names)
        self.counters = counters

    def _own(self, host: str) -> bool:
        name = _host_name(host)
        return name in self.names or ("*ip" in self.names and _ip_literal(name))

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        hosts = [v for k, v in scope["headers"] if k == b"host"]
        origins = [v for k, v in scope["headers"] if k == b"origin"]
        host = hosts[0].decode("latin-1") if len(hosts) == 1 else ""  # two: whose is it?
        if not self._own(host):
            self.counters.foreign_host += 1
            await self._refuse(scope, send, "not this console's host name")
            return
        own_origin = f"http://{host.strip().lower()}"  # two Origins: the WebSocket layer's 400
        if (
            scope["type"] == "websocket"
            and origins
            and origins[0].decode("latin-1").strip().lower() != own_origin
        ):
            self.counters.foreign_origin += 1
            await self._refuse(scope, send, "not this console's origin")
            return
        await self.app(scope, receive, send)

    @staticmethod
    async def _refuse(scope: Scope, send: Send, why: str) -> None:
        if scope["type"] == "websocket":
            await send({"type": "websocket.close", "code": 1008})  # before accept: HTTP 403
            return
        body = f"403 Forbidden: {why}\n".encode()
        headers = [(b"content-type", b"text/plain; charset=utf-8")]
        headers.append((b"content-length", str(len(body)).encode()))
        await send({"type": "http.response.start", "status": 403, "headers": headers})
        await send({"type": "http.response.body", "body": body})


def _static(name: str) -> str:
    return resources.files("testbed.live").joinpath("static", name).read_text(encoding="utf-8")


class _Connection:
    """One browser: its socket, its role and a wake-up for its sender."""

    def __init__(self, websocket: WebSocket, number: int) -> None:
        self.websocket = websocket
        self.number = number  # 1, 2, … in the order the browsers connected: events.csv's name
        self.pilot = False
        self.wake = asyncio.Event()
        self.limit = RateLimit()


class _Console:
    """The app's state: the connections, the pilot's seat, the hub and the live pilot."""

    def __init__(self, hub: Hub, pilot: LivePilot) -> None:
        self.hub = hub
        self.pilot = pilot
        self.connections: list[_Connection] = []
        self.connected = 0

    def connect(self, websocket: WebSocket) -> _Connection:
        """A new browser, numbered in connection order, given the seat if it is free."""
        self.connected += 1
        conn = _Connection(websocket, self.connected)
        self.seat(conn)
        return conn

    def seat(self, conn: _Connection) -> None:
        """Give ``conn`` the pilot's seat if it is free (recorded: who flies from now on)."""
        role = "viewer"
        if not any(c.pilot for c in self.connections):
            conn.pilot, role = True, "pilot"
        self.hub.seat_event("connect", f"browser {conn.number} as {role}")

    def leave(self, conn: _Connection) -> None:
        self.connections.remove(conn)
        role = "pilot" if conn.pilot else "viewer"
        self.hub.seat_event("disconnect", f"browser {conn.number} ({role}) left")
        if conn.pilot:
            self.pilot.submit(_CENTRE)  # sticks to centre at once, not after the dead man
            if self.connections:
                heir = self.connections[0]
                heir.pilot = True
                heir.wake.set()
                self.hub.seat_event("seat", f"browser {heir.number} took the pilot's seat")
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
        if too_long(text):
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


def build_app(
    hub: Hub, pilot: LivePilot, names: Iterable[str] = _LOOPBACK_NAMES
) -> tuple[ASGIApp, _Console]:
    """The app serving the console for ``hub`` and ``pilot`` to the host ``names``
    (:func:`own_names`)."""
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
        if len(console.connections) >= MAX_CONNECTIONS:
            hub.counters.too_many += 1
            await websocket.close(code=1013)  # before accept: HTTP 403
            return
        conn = console.connect(websocket)
        console.connections.append(conn)  # before accepting: the cap holds meanwhile
        hub.viewers = len(console.connections)
        conn.wake.set()
        sender: asyncio.Task[None] | None = None
        try:
            await websocket.accept()
            sender = asyncio.create_task(_sender(console, conn))
            while True:
                message = await websocket.receive()
                if message["type"] == "websocket.disconnect":
                    if message.get("code") == _TOO_BIG:  # closed by the protocol: over ws_max_size
                        hub.counters.malformed += 1
                    break
                text = message.get("text")
                if text is None:  # binary frames are not part of the protocol
                    hub.counters.malformed += 1
                    continue
                answer = console.receive(conn, text)
                if answer is not None:
                    await websocket.send_text(json.dumps(answer))
        except (WebSocketDisconnect, RuntimeError, OSError):
            pass
        finally:
            if sender is not None:
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
    return _Guard(Starlette(routes=routes), names, hub.counters), console


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
        host: the address ``sock`` was bound to as the user gave it (``--host``), one of the
            names the console answers to (:func:`own_names`); None: the socket's address.
    """

    def __init__(
        self, hub: Hub, pilot: LivePilot, sock: socket.socket, host: str | None = None
    ) -> None:
        self.hub = hub
        self.sock = sock
        bound = str(sock.getsockname()[0])
        names = own_names(bound) | (own_names(host) if host is not None else frozenset())
        self.app, self.console = build_app(hub, pilot, names)
        config = uvicorn.Config(
            self.app,
            http="httptools",
            ws=_WebSocketProtocol,
            log_level="warning",
            lifespan="off",
            ws_max_size=16 * MAX_MESSAGE_BYTES,
            timeout_graceful_shutdown=_GRACE_S,
        )
        self.server = uvicorn.Server(config)
        self._bad_requests = _UvicornLog(hub.counters)
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

        try:
            asyncio.run(main())
        except Exception as err:  # never a thread traceback; one line unless we were stopping
            if not self.server.should_exit:
                print(f"testbed live: the console's server stopped: {err!r}", file=sys.stderr)

    def stop(self, timeout_s: float = 5.0) -> None:
        """Stop serving and wait up to ``timeout_s`` [s] for the thread."""
        self._bad_requests.stopping = True
        self.server.should_exit = True
        self._thread.join(timeout_s)
        self.sock.close()
        logging.getLogger(_UVICORN_LOG).removeFilter(self._bad_requests)
