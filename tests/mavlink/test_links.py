"""The ground-station links: URLs, UDP in and out, TCP listening, serial (pyserial ``loop://``)."""

from __future__ import annotations

import queue
import socket
import time

import pytest

from testbed.hil import Received
from testbed.mavlink.links import (
    DEFAULT_BAUD,
    INBOX_PACKETS,
    MAX_UDP_DATAGRAM,
    Intake,
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


def test_udpout_takes_datagrams_from_its_peer_only() -> None:
    """A stranger who learns udpout's port cannot inject ground-station packets, and the link
    does not listen on every interface (it used to bind 0.0.0.0 for a non-loopback peer)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as peer:
        peer.bind(("127.0.0.1", 0))
        peer.settimeout(WAIT_S)
        port = peer.getsockname()[1]
        link = UdpLink(f"udpout:127.0.0.1:{port}", "127.0.0.1", port, listen=False)
        try:
            assert link.send(b"heartbeat")
            data, address = peer.recvfrom(64)
            assert data == b"heartbeat" and address[0] == "127.0.0.1"
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as stranger:
                stranger.bind(("127.0.0.1", 0))
                stranger.sendto(b"injected", address)
                peer.sendto(b"from the peer", address)
                assert take(link.inbox) == b"from the peer"
                stranger.sendto(b"injected again", address)
                peer.sendto(b"still the peer", address)
                assert take(link.inbox) == b"still the peer"
            assert link.inbox.empty() and link.counters()["packets_in"] == 2
        finally:
            link.close()


def test_a_flood_fills_the_inbox_to_its_bound_and_the_rest_is_counted() -> None:
    """Nobody drains the inbox (a frame stalled, or a flood faster than frames): it holds
    INBOX_PACKETS reads and counts every read it had to refuse."""
    link = UdpLink("udpin:127.0.0.1:0", "127.0.0.1", 0, listen=True)
    try:
        assert link.local_address is not None
        sent = INBOX_PACKETS + 300
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as flood:
            flood.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 1 << 20)
            for i in range(sent):
                flood.sendto(i.to_bytes(4, "big"), link.local_address)
                if i % 64 == 63:  # leave the reader time: the socket's own buffer is finite
                    deadline = time.monotonic() + WAIT_S
                    while link.packets_in + link.inbox_full <= i - 64:
                        assert time.monotonic() < deadline, "the reader stopped reading"
                        time.sleep(0.001)
        deadline = time.monotonic() + WAIT_S
        while link.packets_in + link.inbox_full < sent and time.monotonic() < deadline:
            time.sleep(0.01)
        counters = link.counters()
        assert counters["packets_in"] == INBOX_PACKETS == link.inbox.qsize()
        assert counters["inbox_full"] == sent - INBOX_PACKETS
        assert take(link.inbox) == (0).to_bytes(4, "big")  # the oldest kept, in order
    finally:
        link.close()


def test_a_datagram_longer_than_any_ground_station_sends_is_dropped_and_counted() -> None:
    link = UdpLink("udpin:127.0.0.1:0", "127.0.0.1", 0, listen=True)
    try:
        assert link.local_address is not None
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
            sender.sendto(b"\x00" * (MAX_UDP_DATAGRAM + 1), link.local_address)
            sender.sendto(b"\xfd" * MAX_UDP_DATAGRAM, link.local_address)
        assert take(link.inbox) == b"\xfd" * MAX_UDP_DATAGRAM
        assert link.counters()["oversize"] == 1 and link.inbox.empty()
    finally:
        link.close()


def test_an_intake_hands_a_frame_its_byte_share_in_order_and_splits_a_long_read() -> None:
    inbox: queue.Queue[Received] = queue.Queue()
    reads = [bytes([i]) * size for i, size in enumerate((10, 20, 30, 5000, 1))]
    for i, data in enumerate(reads):
        inbox.put(Received(data, i, end=True))
    intake = Intake(inbox, max_bytes=35)
    frames = []
    while batch := intake.take():
        assert sum(len(r.data) for r in batch) <= 35
        frames.append(batch)
    assert b"".join(r.data for batch in frames for r in batch) == b"".join(reads)  # in order
    assert [len(r.data) for r in frames[0]] == [10, 20, 5]  # the 30-B read split at the share
    assert [r.read_ns for r in frames[1]] == [2, 3]  # a split read keeps its read time
    pieces = [r for batch in frames for r in batch if r.read_ns == 3]
    assert [r.end for r in pieces] == [False] * (len(pieces) - 1) + [True]  # ends once, last
    with pytest.raises(ValueError, match="max_bytes"):
        Intake(inbox, max_bytes=0)


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
