"""Hardware in the loop: serial and TCP transports and modem adapters (REFERENCE §1.10–1.12).

* :mod:`~testbed.hil.adapters` — sans-IO :class:`Adapter` protocol, :class:`Write`,
  :class:`RawAdapter` (transparent cable/socket) and :class:`S100Adapter` (WFS Seatooth S100).
* :mod:`~testbed.hil.evologics` — :class:`EvoLogicsAdapter` (S2C data mode, instant messages).
* :mod:`~testbed.hil.m64` — :class:`M64Adapter` (Water Linked Modem-M64, 8-byte packets).
* :mod:`~testbed.hil.transport` — :class:`Transport` (reader and writer threads, reopen with
  backoff, counters), :class:`Received`, :class:`PortLike` and :func:`packet_gap_s`.
* :mod:`~testbed.hil.serial_tcp` — :class:`SerialTransport` (any pyserial URL) and
  :class:`TcpTransport`.
* :mod:`~testbed.hil.link_endpoint` — :class:`LinkEndpoint` (transport + frame decoder, polled
  by nodes).
* :mod:`~testbed.hil.endpoint` — :class:`PortSettings`, :func:`open_endpoint` (the adapter a
  node's role needs, on its port) and :func:`endpoint_report` (counters, added latency).

The real-time run that puts the nodes on these endpoints is :mod:`testbed.run.realtime` (it knows
nodes and scenarios, so it lives above this layer).

The bytes written are the frames the simulation would have carried; the receiver runs the same
:class:`~testbed.protocol.FrameDecoder`, which gives up a mis-framed candidate at the end of
each received packet as the simulator does (:mod:`~testbed.hil.transport`). Imports only
:mod:`testbed.protocol`, pyserial and the standard library.
"""

from __future__ import annotations

from .adapters import (
    S100_MAX_STATUS_LEN,
    S100_MAX_WRITE,
    Adapter,
    RawAdapter,
    S100Adapter,
    Segment,
    Write,
)
from .endpoint import (
    BAUD_RANGE,
    DEFAULT_BAUD,
    MODEM_KINDS,
    PortSettings,
    endpoint_report,
    latency_summary_ms,
    make_adapter,
    open_endpoint,
)
from .evologics import SENDIM_MAX, EvoLogicsAdapter, parse_received_message
from .link_endpoint import LinkEndpoint
from .m64 import CRC8_CHECK_VALUE, M64_PACKET_SIZE, M64Adapter, crc8, m64_sentence
from .serial_tcp import SerialTransport, TcpTransport
from .transport import PORT_ERRORS, PortLike, Received, Transport, packet_gap_s

__all__ = [
    "BAUD_RANGE",
    "CRC8_CHECK_VALUE",
    "DEFAULT_BAUD",
    "M64_PACKET_SIZE",
    "MODEM_KINDS",
    "PORT_ERRORS",
    "S100_MAX_STATUS_LEN",
    "S100_MAX_WRITE",
    "SENDIM_MAX",
    "Adapter",
    "EvoLogicsAdapter",
    "LinkEndpoint",
    "M64Adapter",
    "PortLike",
    "PortSettings",
    "RawAdapter",
    "Received",
    "S100Adapter",
    "Segment",
    "SerialTransport",
    "TcpTransport",
    "Transport",
    "Write",
    "crc8",
    "endpoint_report",
    "latency_summary_ms",
    "m64_sentence",
    "make_adapter",
    "open_endpoint",
    "packet_gap_s",
    "parse_received_message",
]
