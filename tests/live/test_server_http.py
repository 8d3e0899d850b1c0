"""The console's server against garbled HTTP on its socket: answered, counted, never a traceback.

Raw bytes go to a real :class:`~testbed.live.server.ConsoleServer` (uvicorn on a bound socket,
its own thread) through plain sockets; the server must answer each with an HTTP error, keep
serving ``/state``, count each request it could not parse and log no error (uvicorn's h11 path
logged "Exception in ASGI application" with a traceback for a malformed chunked body).
"""

from __future__ import annotations

import json
import logging
import socket
import urllib.request
from collections.abc import Iterator

import pytest

from testbed.live.hub import Hub
from testbed.live.server import ConsoleServer, bind
from testbed.operator.live_pilot import LivePilot

_TIMEOUT_S = 30.0
"""Failure bound of each socket read [s]: a loaded machine answers late, never wrong."""

GARBLED = [
    # a chunked body whose chunk size is not hex: the request the h11 path raised on
    b"POST / HTTP/1.1\r\nHost: localhost\r\nTransfer-Encoding: chunked\r\n\r\nZZZ\r\nabc\r\n",
    # not HTTP at all
    b"GARBAGE\x00\xff\r\n\r\n",
    # a request line with a space in the target and a bad version
    b"GET / x HTTP/9.9\r\n\r\n",
]


@pytest.fixture
def server() -> Iterator[ConsoleServer]:
    console = ConsoleServer(Hub(), LivePilot(), bind("127.0.0.1", 0))
    console.start()
    try:
        yield console
    finally:
        console.stop()


def _exchange(address: tuple[str, int], data: bytes) -> bytes:
    """Send ``data``, close our side, read the whole answer."""
    with socket.create_connection(address, timeout=_TIMEOUT_S) as conn:
        conn.sendall(data)
        conn.shutdown(socket.SHUT_WR)
        answer = b""
        while chunk := conn.recv(4096):
            answer += chunk
    return answer


def test_garbled_requests_are_answered_400_and_counted(
    server: ConsoleServer, caplog: pytest.LogCaptureFixture
) -> None:
    address = server.sock.getsockname()[:2]
    caplog.set_level(logging.WARNING)
    for data in GARBLED:
        answer = _exchange(address, data)
        assert answer.startswith(b"HTTP/1.1 400 "), (data, answer[:60])
    assert server.hub.counters.bad_requests == len(GARBLED)
    # still serving, and the counts are part of what the session reports
    with urllib.request.urlopen(f"{server.url}state", timeout=_TIMEOUT_S) as response:
        assert response.status == 200
        assert json.load(response) == {"state": None, "viewers": 0}
    assert server.hub.counters.as_dict()["bad_requests"] == len(GARBLED)
    uvicorn_records = [r for r in caplog.records if r.name.startswith("uvicorn")]
    assert not any(r.levelno >= logging.ERROR or r.exc_info for r in uvicorn_records)
    assert not any("Invalid HTTP request" in r.getMessage() for r in uvicorn_records)


def test_a_well_formed_request_is_not_counted(server: ConsoleServer) -> None:
    answer = _exchange(
        server.sock.getsockname()[:2], b"GET /state HTTP/1.1\r\nHost: localhost\r\n\r\n"
    )
    assert answer.startswith(b"HTTP/1.1 200 ")
    assert server.hub.counters.bad_requests == 0
