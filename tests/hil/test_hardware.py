"""Real modems (marker ``hil``; excluded from the default run).

Set ``TESTBED_HIL_PORT`` to a serial port (or any pyserial URL) and optionally
``TESTBED_HIL_PORT_B`` to the port of the second modem; without it the first port must have a
loopback plug (TX→RX) or a transparent modem echoing the peer. ``TESTBED_HIL_BAUD`` sets the
speed (default 9600, the S100 bridge rate), ``TESTBED_HIL_RTSCTS=1`` enables flow control.
Frames go through :class:`S100Adapter` (transparent modems) and must arrive intact.

The whole-run test needs two modems: ``TESTBED_HIL_PORT`` (operator) and ``TESTBED_HIL_PORT_B``
(vehicle), ``TESTBED_HIL_MODEM`` = ``s100`` (default), ``evologics`` or ``m64``; it runs
``s100-teleop-v1`` in real time for 20 s and asks for orders and state both ways.
"""

from __future__ import annotations

import os

import pytest

from testbed.hil import LinkEndpoint, PortSettings, S100Adapter, SerialTransport, open_endpoint
from testbed.protocol import Frame, encode_frame
from testbed.run.realtime import run_hil
from testbed.run.scenario import load_scenario

pytestmark = pytest.mark.hil


def _endpoint(url: str, baud: int, rtscts: bool) -> LinkEndpoint:
    adapter = S100Adapter(rtscts=rtscts, pace_bps=min(baud, 2400))
    return LinkEndpoint(SerialTransport(url, adapter, baudrate=baud, rtscts=rtscts))


def test_frames_cross_a_real_link() -> None:
    url_a = os.environ.get("TESTBED_HIL_PORT")
    if not url_a:
        pytest.skip("set TESTBED_HIL_PORT to a real serial port")
    url_b = os.environ.get("TESTBED_HIL_PORT_B")
    baud = int(os.environ.get("TESTBED_HIL_BAUD", "9600"))
    rtscts = os.environ.get("TESTBED_HIL_RTSCTS") == "1"
    sender = _endpoint(url_a, baud, rtscts)
    receiver = _endpoint(url_b, baud, rtscts) if url_b else sender
    payloads = [bytes([k]) * 20 for k in range(10)]
    try:
        for p in payloads:
            assert sender.send(encode_frame(p))
        got: list[bytes] = []
        while len(got) < len(payloads):
            events = receiver.wait(10.0)
            if not events:
                break
            got += [e.payload for e in events if isinstance(e, Frame)]
        # A radio link may lose frames; what arrives must be intact and in order.
        assert got, "no frame crossed the link"
        assert got == [p for p in payloads if p in got]
        assert len(receiver.latencies_ns) == len(got)
    finally:
        sender.close()
        if receiver is not sender:
            receiver.close()


def test_a_whole_run_over_two_real_modems() -> None:
    url_a = os.environ.get("TESTBED_HIL_PORT")
    url_b = os.environ.get("TESTBED_HIL_PORT_B")
    if not (url_a and url_b):
        pytest.skip("set TESTBED_HIL_PORT and TESTBED_HIL_PORT_B to two modems' ports")
    modem = os.environ.get("TESTBED_HIL_MODEM", "s100")
    baud = int(os.environ["TESTBED_HIL_BAUD"]) if "TESTBED_HIL_BAUD" in os.environ else None
    rtscts = os.environ.get("TESTBED_HIL_RTSCTS") == "1"
    endpoints = {
        "operator": open_endpoint(PortSettings(url_a, modem, "operator", baud, rtscts)),
        "vehicle": open_endpoint(PortSettings(url_b, modem, "vehicle", baud, rtscts)),
    }
    result = run_hil(load_scenario("s100-teleop-v1"), endpoints, duration_s=20.0, modem=modem)
    link = result.metrics["link"]
    assert link["uplink"]["frames_delivered"] > 0
    assert link["downlink"]["frames_delivered"] > 0
    assert result.metrics["hil"]["added_latency_ms"]["n"] > 0
