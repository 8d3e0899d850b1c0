"""Packet boundaries on the ground-station links: a stray or truncated UDP datagram, or a TCP
client that dropped mid-packet, costs that piece only (counted ``truncated``), never the valid
packets behind it. Real sockets, pymavlink-encoded messages, the endpoint's own counters."""

from __future__ import annotations

import socket
import time
from collections.abc import Callable

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.common.components import ActiveMode, Armed, ControlMode
from testbed.ecs import World
from testbed.mavlink import EndpointOptions, MavlinkWire, VehicleEndpoint
from testbed.mavlink.channel import Channel
from testbed.mavlink.links import Intake, Link, TcpServerLink, UdpLink

WAIT_S = 10.0
STRAYS = [b"\xfd", b"\xfe", b"\xfd\xff", b"hello\xfe"]
"""Datagrams a stray sender or a garbled link may leave: each holds the start of a packet whose
length byte (missing or 0xff) claims more than the datagram has."""


class _Sink:
    def __init__(self) -> None:
        self.data = b""

    def write(self, data: bytes) -> None:
        self.data += data


GCS = mav.MAVLink(_Sink(), srcSystem=255, srcComponent=190)


def heartbeat() -> bytes:
    return bytes(GCS.heartbeat_encode(6, 8, 0, 0, 4).pack(GCS))


def sticks(x: int) -> bytes:
    return bytes(GCS.manual_control_encode(1, x, 0, 500, 0, 0).pack(GCS))


def endpoint() -> VehicleEndpoint:
    """An endpoint on a bare world (decoding and counting only)."""
    world = World()
    vehicle = world.spawn(Armed(False), ActiveMode(ControlMode.MANUAL))
    return VehicleEndpoint(world, vehicle, world.spawn(), EndpointOptions())


def drain_until(
    link: Link, ep: VehicleEndpoint, channel: Channel, done: Callable[[], bool]
) -> None:
    """Feed the link's reads to the endpoint as the run does (with their ``end``) until
    ``done()`` or :data:`WAIT_S` (then fail)."""
    intake = Intake(link.inbox)
    deadline = time.monotonic() + WAIT_S
    while not done():
        for received in intake.take():
            ep.receive(channel, received.data, 0.0, end=received.end)
        if done():
            return
        assert time.monotonic() < deadline, f"gave up: {ep.received}, {ep.rejected}"
        time.sleep(0.002)


def test_a_piece_of_a_packet_at_a_datagrams_end_is_counted_and_not_continued() -> None:
    for stray in STRAYS:
        wire = MavlinkWire()
        assert wire.decode(stray, end=True).bad["truncated"] == 1
        got = [m.get_type() for m in wire.decode(sticks(300), end=True).messages]
        assert got == ["MANUAL_CONTROL"], stray
    wire = MavlinkWire()  # without an end, a piece still waits for the rest (a stream)
    packet = sticks(300)
    assert wire.decode(packet[:10]).bad == {}
    assert [m.get_type() for m in wire.decode(packet[10:], end=True).messages] == ["MANUAL_CONTROL"]
    assert wire.decode(heartbeat(), end=True).bad == {}  # a whole datagram: nothing dropped


@pytest.mark.parametrize("stray", STRAYS)
def test_a_stray_udp_datagram_costs_no_valid_message_behind_it(stray: bytes) -> None:
    link = UdpLink("udpin:127.0.0.1:0", "127.0.0.1", 0, listen=True)
    ep = endpoint()
    channel = ep.open_channel(link.url)
    try:
        assert link.local_address is not None
        before = [heartbeat() if i % 2 else sticks(10 * i) for i in range(10)]
        after = [heartbeat() if i % 2 else sticks(-10 * i) for i in range(15)]
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as gcs:
            for datagram in [*before, stray, *after]:
                gcs.sendto(datagram, link.local_address)
        # every datagram read (the stray one too), then every valid message decoded
        drain_until(
            link,
            ep,
            channel,
            lambda: sum(ep.received.values()) >= 25 and link.counters()["packets_in"] == 26,
        )
        assert ep.received == {"HEARTBEAT": 12, "MANUAL_CONTROL": 13}
        assert ep.rejected["truncated"] == 1  # the stray bytes, counted
        assert set(ep.rejected) - {"wrong_target", "wrong_sysid"} <= {"truncated", "garbage"}
        assert ep.rejected["garbage"] == (1 if stray.startswith(b"hello") else 0)
        assert link.counters()["bytes_in"] == sum(map(len, [*before, stray, *after]))
    finally:
        link.close()


def wait_for(condition: Callable[[], bool]) -> None:
    deadline = time.monotonic() + WAIT_S
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.002)


@pytest.mark.parametrize("hang_up", [True, False], ids=["hung-up", "replaced-while-open"])
def test_a_new_tcp_client_starts_with_no_piece_of_the_old_ones_packet(hang_up: bool) -> None:
    link = TcpServerLink("tcpin:127.0.0.1:0", "127.0.0.1", 0)
    ep = endpoint()
    channel = ep.open_channel(link.url)
    try:
        first = heartbeat() + sticks(100)[:5]  # dropped mid-packet: a length byte, no body
        old = socket.create_connection(link.local_address, timeout=WAIT_S)
        try:
            old.sendall(first)
            wait_for(lambda: link.bytes_in == len(first))
            if hang_up:
                old.close()
            valid = [sticks(20 * i) if i % 3 else heartbeat() for i in range(15)]
            with socket.create_connection(link.local_address, timeout=WAIT_S) as new:
                wait_for(lambda: link.clients == 2)
                new.sendall(b"".join(valid))
                drain_until(link, ep, channel, lambda: sum(ep.received.values()) >= 16)
            assert ep.received == {"HEARTBEAT": 1 + 5, "MANUAL_CONTROL": 10}
            assert ep.rejected["truncated"] == 1  # the old client's piece, counted
        finally:
            old.close()
    finally:
        link.close()


def test_tcpin_reads_every_client_on_one_thread() -> None:
    """A thread per client ever accepted was kept (joined only at close)."""
    link = TcpServerLink("tcpin:127.0.0.1:0", "127.0.0.1", 0)
    try:
        for i in range(5):
            with socket.create_connection(link.local_address, timeout=WAIT_S) as client:
                client.sendall(bytes([i]))
                wait_for(lambda i=i: link.bytes_in == i + 1)
        assert link.clients == 5 and len(link._threads) == 1
    finally:
        link.close()


def _ipv6_loopback() -> bool:
    try:
        with socket.socket(socket.AF_INET6, socket.SOCK_STREAM) as probe:
            probe.bind(("::1", 0))
    except OSError:
        return False
    return True


@pytest.mark.skipif(not _ipv6_loopback(), reason="no IPv6 loopback")
def test_tcpin_on_an_ipv6_address() -> None:
    link = TcpServerLink("tcpin:::1:0", "::1", 0)
    try:
        with socket.create_connection(link.local_address[:2], timeout=WAIT_S) as client:
            client.sendall(b"over ipv6")
            wait_for(lambda: link.bytes_in == 9)
            assert link.inbox.get(timeout=WAIT_S).data == b"over ipv6"
            assert link.send(b"back")
            assert client.recv(16) == b"back"
    finally:
        link.close()


def test_a_pause_on_a_serial_line_splits_no_packet() -> None:
    """A telemetry radio delivers a packet in bursts: half a MANUAL_CONTROL, a pause well past
    the serial transport's idle gap, then the rest (pyserial's loop:// port, a real serial
    object we did not write). The packet arrives whole, nothing is counted truncated."""
    from testbed.mavlink.links import open_link

    link = open_link("loop://")
    ep = endpoint()
    channel = ep.open_channel(link.url)
    try:
        packet = sticks(300)
        link.send(packet[:9])
        time.sleep(0.2)  # the stimulus: a gap of 10 idle periods, not a bound on anything
        link.send(packet[9:])
        drain_until(link, ep, channel, lambda: sum(ep.received.values()) >= 1)
        assert ep.received == {"MANUAL_CONTROL": 1}
        assert "truncated" not in ep.rejected
    finally:
        link.close()
