"""Transports: loop:// round trips, a socket:// peer that vanishes and returns, a fake port.

No sleeps: every wait is a bounded wait on a queue, an event or a socket accept.
"""

from __future__ import annotations

import queue
import socket
import threading
import time
from pathlib import Path

import pytest
import serial

from testbed.cli.hil import write_port_log
from testbed.hil import (
    LinkEndpoint,
    M64Adapter,
    RawAdapter,
    S100Adapter,
    SerialTransport,
    TcpTransport,
    crc8,
)
from testbed.protocol import Frame, encode_frame

WAIT_S = 5.0
PAYLOADS = [bytes([k]) * (10 + 20 * k) for k in range(5)]


def collect(endpoint: LinkEndpoint, n: int) -> list[bytes]:
    got: list[bytes] = []
    while len(got) < n:
        events = endpoint.wait(WAIT_S)
        assert events, f"timed out with {len(got)}/{n} frames"
        got += [e.payload for e in events if isinstance(e, Frame)]
    return got


@pytest.mark.parametrize("adapter", [RawAdapter(), S100Adapter(pace_bps=1e7)], ids=["raw", "s100"])
def test_loop_round_trip(adapter: RawAdapter | S100Adapter) -> None:
    woken = threading.Event()
    transport = SerialTransport("loop://", adapter, baudrate=115200, on_bytes=woken.set)
    endpoint = LinkEndpoint(transport)
    try:
        for p in PAYLOADS:
            assert endpoint.send(encode_frame(p))
        assert collect(endpoint, len(PAYLOADS)) == PAYLOADS
        assert woken.is_set()
        assert len(endpoint.latencies_ns) == len(PAYLOADS)
        assert transport.frames_sent == len(PAYLOADS)
        assert transport.port_errors == 0
    finally:
        endpoint.close()
    assert not any(t.is_alive() for t in transport._threads)


def test_send_never_blocks_and_drops_when_full() -> None:
    transport = SerialTransport(
        "loop://", S100Adapter(pace_bps=8.0), baudrate=115200, max_pending_frames=2
    )
    try:
        results = [transport.send(encode_frame(b"x" * 40)) for _ in range(10)]
        assert results.count(False) >= 7  # the first write holds 42 s; 2 may queue
        assert transport.frames_dropped == results.count(False)
    finally:
        transport.close()


def test_every_accepted_frame_ends_sent_or_dropped_when_the_transport_closes() -> None:
    # A loaded HIL run ended with orders its transport had accepted neither written nor
    # counted dropped: close() discarded the queue (here: the first write holds 42 s, the
    # rest wait behind it).
    transport = SerialTransport(
        "loop://", S100Adapter(pace_bps=8.0), baudrate=115200, max_pending_frames=4
    )
    try:
        results = [transport.send(encode_frame(b"x" * 40)) for _ in range(6)]
        deadline = time.monotonic() + 10.0
        while transport.bytes_out == 0 and time.monotonic() < deadline:
            time.sleep(0.005)  # the first frame is on the wire, the others wait their turn
        assert transport.bytes_out > 0
    finally:
        transport.close()
    assert results.count(True) >= 4
    assert transport.frames_sent + transport.frames_dropped == len(results)


def test_callback_errors_are_counted() -> None:
    def boom() -> None:
        raise RuntimeError("boom")

    transport = SerialTransport("loop://", RawAdapter(), baudrate=115200, on_bytes=boom)
    endpoint = LinkEndpoint(transport)
    try:
        endpoint.send(encode_frame(b"hi"))
        assert collect(endpoint, 1) == [b"hi"]
        assert transport.callback_errors == 1
    finally:
        endpoint.close()


class Peer:
    """A TCP server on 127.0.0.1 that can be stopped and restarted on the same port."""

    def __init__(self) -> None:
        self.listener = self._listen(0)
        self.port = self.listener.getsockname()[1]
        self.conn: socket.socket | None = None

    @staticmethod
    def _listen(port: int) -> socket.socket:
        sock = socket.socket()
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(("127.0.0.1", port))
        sock.listen(1)
        sock.settimeout(WAIT_S)
        return sock

    def accept(self) -> socket.socket:
        self.conn, _ = self.listener.accept()
        self.conn.settimeout(WAIT_S)
        return self.conn

    def stop(self) -> None:
        if self.conn is not None:
            self.conn.close()
        self.listener.close()

    def restart(self) -> None:
        self.listener = self._listen(self.port)


def test_port_vanishes_and_returns() -> None:
    peer = Peer()
    transport = SerialTransport(
        f"socket://127.0.0.1:{peer.port}",
        RawAdapter(),
        baudrate=115200,
        backoff_initial_s=0.01,
        backoff_max_s=0.1,
    )
    endpoint = LinkEndpoint(transport)
    try:
        conn = peer.accept()
        conn.sendall(encode_frame(b"before"))
        assert collect(endpoint, 1) == [b"before"]

        peer.stop()  # the modem is unplugged
        assert _wait_for(lambda: transport.port_errors >= 1)
        assert not transport.connected.is_set()
        assert not transport.send(encode_frame(b"lost")) or _wait_for(
            lambda: transport.frames_dropped >= 1 or transport.reopen_failures >= 1
        )
        assert _wait_for(lambda: transport.reopen_failures >= 2)  # backing off, run goes on

        peer.restart()  # and plugged back in
        conn = peer.accept()
        assert transport.connected.wait(WAIT_S)
        conn.sendall(b"\x00garbage" + encode_frame(b"after"))
        assert collect(endpoint, 1) == [b"after"]
        assert transport.opens == 2
        assert endpoint.decoder.garbage_bytes == len(b"\x00garbage")

        endpoint.send(encode_frame(b"to peer"))
        data = b""
        while encode_frame(b"to peer") not in data:
            data += conn.recv(100)
    finally:
        endpoint.close()
        peer.stop()


def _wait_for(condition: object, timeout_s: float = WAIT_S) -> bool:
    """Poll ``condition`` with bounded event waits (no sleep)."""
    tick = threading.Event()
    for _ in range(int(timeout_s / 0.005)):
        if condition():  # type: ignore[operator]  # a callable returning bool
            return True
        tick.wait(0.005)
    return bool(condition())  # type: ignore[operator]  # a callable returning bool


class FakePort:
    """Delivers scripted chunks, then fails like an unplugged USB adapter."""

    def __init__(self, chunks: list[bytes]) -> None:
        self.chunks: queue.Queue[bytes] = queue.Queue()
        for c in chunks:
            self.chunks.put(c)
        self.written = bytearray()

    def read(self, size: int = 1) -> bytes:
        try:
            return self.chunks.get(timeout=0.01)
        except queue.Empty:
            raise serial.SerialException("device disconnected") from None

    def write(self, data: bytes) -> int:
        self.written += data
        return len(data)

    @property
    def in_waiting(self) -> int:
        return 0

    def close(self) -> None:
        pass


def test_fake_port_fails_reopen_fails_twice_then_recovers() -> None:
    frame = encode_frame(b"m64")
    sentences = [b"wrp,8," + frame[i : i + 8].ljust(8, b"\0") for i in range(0, len(frame), 8)]
    stream = b"".join(s + b"*%02x\r\n" % crc8(s) for s in sentences)
    script: list[object] = [
        FakePort([stream[:5], stream[5:17]]),  # split reads, then vanishes
        serial.SerialException("no such device"),
        serial.SerialException("no such device"),
        FakePort([stream[17:]]),
    ]

    def factory() -> FakePort:
        item = script.pop(0) if script else FakePort([])
        if isinstance(item, Exception):
            raise item
        assert isinstance(item, FakePort)
        return item

    transport = SerialTransport(
        "fake", M64Adapter(), baudrate=115200, port_factory=factory, backoff_initial_s=0.001
    )
    endpoint = LinkEndpoint(transport)
    try:
        assert collect(endpoint, 1) == [b"m64"]
        assert transport.reopen_failures >= 2
        assert transport.port_errors >= 1
        assert transport.opens >= 2
        assert transport.counters()["adapter_packets_in"] == len(sentences)
    finally:
        endpoint.close()


def test_tcp_transport_round_trip_through_an_echoing_peer() -> None:
    peer = Peer()
    transport = TcpTransport("127.0.0.1", peer.port, RawAdapter())
    endpoint = LinkEndpoint(transport)
    try:
        conn = peer.accept()
        frame = encode_frame(b"tcp")
        endpoint.send(frame)
        data = b""
        while len(data) < len(frame):
            data += conn.recv(100)
        conn.sendall(data)  # echo
        assert collect(endpoint, 1) == [b"tcp"]
    finally:
        endpoint.close()
        peer.stop()


def test_first_open_failure_raises() -> None:
    with pytest.raises(serial.SerialException):
        SerialTransport("/dev/does-not-exist-testbed", RawAdapter(), baudrate=9600)


class StalledWritePort:
    """A loop:// port whose writes go through but then raise pyserial's write timeout, as
    pyserial's own ``write`` does when the host held the thread past ``write_timeout`` before
    it checked the clock (it checks after a complete ``os.write``); ``stuck`` ones raise
    without writing (flow control that never lets a byte out)."""

    def __init__(self, stalls: list[str]) -> None:
        self.port = serial.serial_for_url("loop://", timeout=0.01)
        self.stalls = stalls  # per write: "ok", "stalled" (written, then raises) or "stuck"

    def read(self, size: int = 1) -> bytes:
        return bytes(self.port.read(size))

    def write(self, data: bytes) -> int | None:
        kind = self.stalls.pop(0) if self.stalls else "ok"
        if kind != "stuck":
            self.port.write(data)
        if kind != "ok":
            raise serial.SerialTimeoutException("Write timeout")
        return len(data)

    @property
    def in_waiting(self) -> int:
        return int(self.port.in_waiting)

    def close(self) -> None:
        self.port.close()


def test_one_write_timeout_after_the_bytes_went_out_is_counted_not_a_port_error() -> None:
    """The frame the stalled write carried comes back through loop:// (it went out), the
    port stays open, and the timeout is counted; two timeouts in a row fail the port."""
    port = StalledWritePort(["stalled", "ok"])
    transport = SerialTransport("fake", RawAdapter(), baudrate=115200, port_factory=lambda: port)
    endpoint = LinkEndpoint(transport)
    try:
        endpoint.send(encode_frame(b"first"))
        endpoint.send(encode_frame(b"second"))
        assert collect(endpoint, 2) == [b"first", b"second"]
        counts = transport.counters()
        assert counts["write_timeouts"] == 1 and counts["port_errors"] == 0
        assert counts["frames_sent"] == 2 and counts["frames_dropped"] == 0
    finally:
        endpoint.close()
    ports = [StalledWritePort(["stuck", "stuck"])]
    transport = SerialTransport(
        "fake",
        RawAdapter(),
        baudrate=115200,
        port_factory=lambda: ports.pop(0) if ports else StalledWritePort([]),
        backoff_initial_s=0.001,
    )
    try:
        transport.send(encode_frame(b"a"))
        transport.send(encode_frame(b"b"))
        assert transport.connected.wait(WAIT_S)
        deadline = threading.Event()
        for _ in range(500):  # bounded: the writer thread takes both frames within ms
            if transport.port_errors:
                break
            deadline.wait(0.01)
        assert transport.port_errors == 1 and transport.write_timeouts == 2
        assert transport.frames_dropped == 1  # the second, whose write failed the port
    finally:
        transport.close()


def test_the_byte_log_holds_every_byte_written_and_read_in_time_order(tmp_path: Path) -> None:
    """``testbed hil --log-bytes``: through loop:// each frame (S100: frame + CR LF) is written,
    then read back, byte for byte; ports.csv lists both, in time order, from the clock start."""
    transport = SerialTransport(
        "loop://", S100Adapter(pace_bps=1e7), baudrate=115200, log_bytes=True
    )
    endpoint = LinkEndpoint(transport)
    start_ns = time.perf_counter_ns()
    try:
        for p in PAYLOADS:
            assert endpoint.send(encode_frame(p))
        assert collect(endpoint, len(PAYLOADS)) == PAYLOADS
    finally:
        endpoint.close()
    log = list(transport.byte_log or ())
    written = b"".join(data for _, direction, data in log if direction == "out")
    read = b"".join(data for _, direction, data in log if direction == "in")
    wire = b"".join(encode_frame(p) + b"\r\n" for p in PAYLOADS)
    assert written == read == wire
    assert sum(len(d) for _, k, d in log if k == "out") == transport.bytes_out
    write_port_log({"operator": endpoint}, start_ns, tmp_path / "ports.csv")
    lines = (tmp_path / "ports.csv").read_text().splitlines()
    assert lines[0] == "t_s,port,dir,bytes,hex"
    rows = [line.split(",") for line in lines[1:]]
    assert len(rows) == len(log) and [float(r[0]) for r in rows] == sorted(
        float(r[0]) for r in rows
    )
    assert all(float(r[0]) >= 0.0 and r[1] == "operator" for r in rows)
    assert bytes.fromhex("".join(r[4] for r in rows if r[2] == "out")) == wire
