"""The ground-station links: URLs, UDP in and out, TCP listening, serial (pyserial ``loop://``)."""

from __future__ import annotations

import queue
import socket

import pytest

from testbed.hil import Received
from testbed.mavlink.links import (
    DEFAULT_BAUD,
    SerialLink,
    TcpServerLink,
    UdpLink,
    open_link,
    parse_url,
)

WAIT_S = 5.0


def test_urls() -> None:
    assert parse_url("udpout:127.0.0.1:14550") == ("udpout", "127.0.0.1", 14550)
    assert parse_url("udpin::14551") == ("udpin", "127.0.0.1", 14551)  # loopback by default
    assert parse_url("tcpin:0.0.0.0:5760") == ("tcpin", "0.0.0.0", 5760)
    assert parse_url("serial:/dev/ttyACM0,57600") == ("serial", "/dev/ttyACM0", 57600)
    assert parse_url("/dev/ttyUSB0") == ("serial", "/dev/ttyUSB0", DEFAULT_BAUD)
    assert parse_url("socket://localhost:5760") == ("serial", "socket://localhost:5760", 115200)
    for bad in ("udpin:127.0.0.1", "tcpin:x:0", "udp:1.2.3.4:5", "serial:/dev/x,fast", ""):
        with pytest.raises(ValueError):
            parse_url(bad)


def take(inbox: queue.Queue[Received]) -> bytes:
    return inbox.get(timeout=WAIT_S).data


def test_udpin_answers_the_last_sender_and_udpout_its_peer() -> None:
    listening = UdpLink("udpin:127.0.0.1:0", "127.0.0.1", 0, listen=True)
    try:
        assert listening.local_address is not None
        port = listening.local_address[1]
        assert not listening.send(b"nobody yet")  # no peer: dropped, counted
        sender = UdpLink(f"udpout:127.0.0.1:{port}", "127.0.0.1", port, listen=False)
        try:
            assert sender.send(b"ping")
            assert take(listening.inbox) == b"ping"
            assert listening.send(b"pong")
            assert take(sender.inbox) == b"pong"
            assert listening.counters()["dropped"] == 1
        finally:
            sender.close()
    finally:
        listening.close()


def test_tcpin_serves_one_client_at_a_time() -> None:
    link = TcpServerLink("tcpin:127.0.0.1:0", "127.0.0.1", 0)
    try:
        address = link.local_address
        with socket.create_connection(address, timeout=WAIT_S) as client:
            client.sendall(b"hello")
            assert take(link.inbox) == b"hello"
            assert link.send(b"back")
            assert client.recv(16) == b"back"
        assert link.clients == 1
    finally:
        link.close()


def test_serial_through_the_hil_transport() -> None:
    link = SerialLink("serial:loop://", "loop://", DEFAULT_BAUD)
    try:
        assert link.send(b"\xfd looped")
        assert take(link.inbox) == b"\xfd looped"
    finally:
        link.close()


def test_open_link_refuses_a_port_in_use() -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        with pytest.raises(OSError):
            open_link(f"udpin:127.0.0.1:{taken.getsockname()[1]}")
