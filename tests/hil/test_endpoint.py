"""Endpoints from settings: the adapter each role needs, setup on every open, the report.

Truth: the role conventions of REFERENCE §1.3 (ROV address 1, operator 2) and §1.12 (peers in
different roles), bytes counted by hand, and percentiles of a hand-made latency list. Ports are
``loop://`` or scripted fakes; waits are bounded waits on queues (no sleep).
"""

from __future__ import annotations

import math
import queue

import pytest
import serial

from testbed.cli.hil import _MODEMS
from testbed.hil import (
    BAUD_RANGE,
    DEFAULT_BAUD,
    MODEM_KINDS,
    EvoLogicsAdapter,
    M64Adapter,
    PortSettings,
    RawAdapter,
    S100Adapter,
    endpoint_report,
    latency_summary_ms,
    make_adapter,
    open_endpoint,
)
from testbed.protocol import Frame, FrameDecoder, encode_frame

WAIT_S = 5.0


def test_settings_check_their_values_and_give_the_modems_default_speed() -> None:
    assert PortSettings("loop://", "s100", "operator").baud == 9600 == DEFAULT_BAUD["s100"]
    assert PortSettings("loop://", "m64", "vehicle").baud == 115200
    assert PortSettings("loop://", "m64", "vehicle", baudrate=9600).baud == 9600
    assert PortSettings("loop://", "raw", "vehicle").peer_role == "operator"
    with pytest.raises(ValueError):
        PortSettings("loop://", "s300", "operator")
    with pytest.raises(ValueError):
        PortSettings("loop://", "s100", "rov")
    with pytest.raises(ValueError):
        PortSettings("loop://", "s100", "operator", baudrate=0)
    assert PortSettings("loop://", "s100", "operator", baudrate=BAUD_RANGE[1]).baud == 12_000_000
    with pytest.raises(ValueError, match="baudrate must be in"):  # pyserial overflows above 2^31
        PortSettings("loop://", "s100", "operator", baudrate=BAUD_RANGE[1] + 1)
    with pytest.raises(ValueError):
        PortSettings("loop://", "s100", "operator", m64_channel=8)
    assert set(_MODEMS) == set(MODEM_KINDS)  # the CLI offers every modem


def test_adapter_per_modem_and_role() -> None:
    s100 = make_adapter(PortSettings("x", "s100", "operator", rtscts=True))
    assert isinstance(s100, S100Adapter) and s100.rtscts
    operator = make_adapter(PortSettings("x", "evologics", "operator"))
    vehicle = make_adapter(PortSettings("x", "evologics", "vehicle"))
    assert isinstance(operator, EvoLogicsAdapter) and isinstance(vehicle, EvoLogicsAdapter)
    assert (operator.local_address, operator.remote_address) == (2, 1)  # telerobotics
    assert (vehicle.local_address, vehicle.remote_address) == (1, 2)
    m64_a = make_adapter(PortSettings("x", "m64", "operator", m64_channel=3))
    m64_b = make_adapter(PortSettings("x", "m64", "vehicle", m64_channel=3))
    assert isinstance(m64_a, M64Adapter) and isinstance(m64_b, M64Adapter)
    assert (m64_a.role, m64_b.role, m64_a.channel, m64_b.channel) == ("a", "b", 3, 3)
    assert isinstance(make_adapter(PortSettings("x", "raw", "vehicle")), RawAdapter)


class ScriptedPort:
    """Records writes; reads return nothing until ``fail`` is set, then raise."""

    def __init__(self) -> None:
        self.written: list[bytes] = []
        self.fail = False
        self.reads: queue.Queue[bytes] = queue.Queue()

    def read(self, size: int = 1) -> bytes:
        if self.fail:
            raise serial.SerialException("device disconnected")
        try:
            return self.reads.get(timeout=0.01)
        except queue.Empty:
            return b""

    def write(self, data: bytes) -> int:
        if self.fail:
            raise serial.SerialException("device disconnected")
        self.written.append(bytes(data))
        return len(data)

    @property
    def in_waiting(self) -> int:
        return 0

    def close(self) -> None:
        pass


def test_setup_goes_out_first_on_every_open() -> None:
    ports: queue.Queue[ScriptedPort] = queue.Queue()
    opened: list[ScriptedPort] = []

    def factory() -> ScriptedPort:
        port = ScriptedPort()
        opened.append(port)
        ports.put(port)
        return port

    settings = PortSettings("fake", "m64", "operator", m64_channel=5)
    setup = [w.data for w in make_adapter(settings).setup()]
    endpoint = open_endpoint(settings, port_factory=factory, backoff_initial_s=0.001)
    try:
        first = ports.get(timeout=WAIT_S)
        assert first.written == setup  # written by the constructor, before any frame
        assert endpoint.send(encode_frame(b"go"))
        first.fail = True  # unplugged: the reader notices, reopens, sets the modem up again
        second = ports.get(timeout=WAIT_S)
        transport = endpoint.transport
        assert transport.connected.wait(WAIT_S)
        assert second.written[: len(setup)] == setup
        assert transport.setup_writes == 2 * len(setup)
        assert transport.port_errors >= 1 and transport.opens >= 2
    finally:
        endpoint.close()
    assert len(opened) >= 2


def test_report_counts_bytes_frames_garbage_corruption_and_latency() -> None:
    endpoint = open_endpoint(PortSettings("loop://", "raw", "vehicle"))
    good = [encode_frame(b"state %d" % k) for k in range(3)]
    bad = bytearray(encode_frame(b"bad crc"))
    bad[-1] ^= 0xFF
    garbage = b"\x00\x01noise"
    try:
        for chunk in (good[0], garbage, good[1], bytes(bad), good[2]):
            assert endpoint.send(chunk)
        got: list[bytes] = []
        while len(got) < len(good):
            events = endpoint.wait(WAIT_S)
            assert events, f"timed out with {len(got)} frames"
            got += [e.payload for e in events if isinstance(e, Frame)]
    finally:
        endpoint.close()
    report = endpoint_report(endpoint)
    total = sum(len(c) for c in good) + len(garbage) + len(bad)
    assert got == [b"state 0", b"state 1", b"state 2"]
    assert report["url"] == "loop://"
    assert report["bytes_in"] == report["bytes_out"] == total
    assert (report["frames_in"], report["frames_out"], report["frames_dropped"]) == (3, 5, 0)
    assert report["corrupt_frames"] == 1
    # The noise, and the bad frame's bytes after its start byte (the decoder hunts on from
    # the byte after a failed start): what one decoder fed the whole stream at once counts.
    reference = FrameDecoder()
    reference.feed(b"".join((good[0], garbage, good[1], bytes(bad), good[2])))
    assert report["garbage_bytes"] == reference.garbage_bytes == len(garbage) + len(bad) - 1
    assert report["reopens"] == report["port_errors"] == 0
    assert report["added_latency_ms"]["n"] == 3
    assert report["adapter"] == {"bytes_in": total}


def test_latency_summary_in_milliseconds() -> None:
    summary = latency_summary_ms([1_000_000, 4_000_000, 2_000_000, 3_000_000])
    assert summary == {
        "p50": 2.5,
        "p95": pytest.approx(3.85),  # linear interpolation between 3 and 4 ms
        "max": 4.0,
        "mean": 2.5,
        "n": 4,
    }
    empty = latency_summary_ms([])
    assert empty["n"] == 0 and all(math.isnan(empty[k]) for k in ("p50", "p95", "max", "mean"))
