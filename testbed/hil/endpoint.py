"""Link endpoints from a user's settings, and what an endpoint measured.

:class:`PortSettings` names one node's port: its pyserial URL, the modem behind it
(:data:`MODEM_KINDS`), the node's role on the link and the serial options. :func:`make_adapter`
builds the modem adapter that role needs (addresses, M64 role and channel), and
:func:`open_endpoint` opens the :class:`~testbed.hil.serial_tcp.SerialTransport` and wraps it in
a :class:`~testbed.hil.link_endpoint.LinkEndpoint`. :func:`endpoint_report` reduces an endpoint to
JSON-ready numbers: bytes and frames each way, garbage, port faults and the software's own
added latency (port read returned → frame handed to the node).

Role conventions (REFERENCE §1.3, §1.12): telerobotics addresses the ROV as 1 and the operator
as 2, so an EvoLogics modem is given local address 2 at the operator and 1 at the vehicle, each
sending to the other; a Water Linked M64 pair needs different roles on one channel, and the
operator, the token master, takes role ``a``.

Imports pyserial (through the transport), numpy and :mod:`testbed.protocol` only.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .adapters import Adapter, RawAdapter, S100Adapter
from .evologics import EvoLogicsAdapter
from .link_endpoint import LinkEndpoint
from .m64 import M64Adapter
from .serial_tcp import SerialTransport
from .transport import PortLike

__all__ = [
    "BAUD_RANGE",
    "DEFAULT_BAUD",
    "EVOLOGICS_ADDRESS",
    "M64_ROLE",
    "MODEM_KINDS",
    "ROLES",
    "PortSettings",
    "endpoint_report",
    "latency_summary_ms",
    "make_adapter",
    "open_endpoint",
]

MODEM_KINDS = ("s100", "evologics", "m64", "raw")
"""Modems a port can carry: WFS S100 (transparent), EvoLogics S2C (AT data mode), Water Linked
M64, or ``raw`` (a cable or socket, no modem)."""

ROLES = ("operator", "vehicle")
"""The node a port belongs to."""

DEFAULT_BAUD = {"s100": 9600, "evologics": 19200, "m64": 115200, "raw": 115200}
"""Port speed by modem when none is given [bit/s]: S100 9600 (the dccomms S100 bridge and v3
nodes of 2021, REFERENCE §1.10), M64 115200 8N1 (REFERENCE §1.12). The EvoLogics figure is a
common serial setting, not a verified default: check the modem (or use its TCP port,
``socket://host:9200``)."""

BAUD_RANGE = (50, 12_000_000)
"""Accepted port speeds [bit/s]: from 50 (B50, the slowest POSIX rate) to 12 Mbit/s (an FTDI
FT232H, the fastest common USB serial adapter). pyserial itself overflows above 2^31 − 1."""

EVOLOGICS_ADDRESS = {"operator": 2, "vehicle": 1}
"""Acoustic address by role (telerobotics: ROV 1, operator 2)."""

M64_ROLE = {"operator": "a", "vehicle": "b"}
"""Water Linked M64 role by node role."""


@dataclass(frozen=True, slots=True)
class PortSettings:
    """One node's port.

    Attributes:
        url: port name or pyserial URL (``/dev/ttyUSB0``, ``socket://host:port``, ``loop://``).
        modem: one of :data:`MODEM_KINDS`.
        role: ``"operator"`` or ``"vehicle"``.
        baudrate: port speed [bit/s]; None = :data:`DEFAULT_BAUD` for the modem.
        rtscts: RTS/CTS hardware flow control (S100: frames go out whole, unpaced).
        m64_channel: Water Linked acoustic channel, 1..7 (both ends the same).

    Raises:
        ValueError: unknown modem or role, baud rate outside :data:`BAUD_RANGE`, channel out
            of range.
    """

    url: str
    modem: str
    role: str
    baudrate: int | None = None
    rtscts: bool = False
    m64_channel: int = 4

    def __post_init__(self) -> None:
        if self.modem not in MODEM_KINDS:
            raise ValueError(f"modem must be one of {MODEM_KINDS}, got {self.modem!r}")
        if self.role not in ROLES:
            raise ValueError(f"role must be one of {ROLES}, got {self.role!r}")
        low, high = BAUD_RANGE
        if self.baudrate is not None and not low <= self.baudrate <= high:
            raise ValueError(f"baudrate must be in [{low}, {high}], got {self.baudrate}")
        if not 1 <= self.m64_channel <= 7:
            raise ValueError(f"m64_channel must be in 1..7, got {self.m64_channel}")

    @property
    def baud(self) -> int:
        """The port speed in use [bit/s]."""
        return DEFAULT_BAUD[self.modem] if self.baudrate is None else self.baudrate

    @property
    def peer_role(self) -> str:
        """The role at the other end of the link."""
        return ROLES[1 - ROLES.index(self.role)]


def make_adapter(settings: PortSettings) -> Adapter:
    """The modem adapter for ``settings`` (see the module's role conventions)."""
    if settings.modem == "s100":
        return S100Adapter(rtscts=settings.rtscts)
    if settings.modem == "evologics":
        return EvoLogicsAdapter(
            EVOLOGICS_ADDRESS[settings.peer_role],
            local_address=EVOLOGICS_ADDRESS[settings.role],
        )
    if settings.modem == "m64":
        return M64Adapter(role=M64_ROLE[settings.role], channel=settings.m64_channel)
    return RawAdapter()


def open_endpoint(
    settings: PortSettings,
    *,
    port_factory: Callable[[], PortLike] | None = None,
    **transport_options: Any,
) -> LinkEndpoint:
    """Open the port of ``settings`` (the adapter's setup is written first) as an endpoint.

    Args:
        settings: the port.
        port_factory: opens the port instead of pyserial (tests inject failing ports).
        **transport_options: :class:`~testbed.hil.serial_tcp.SerialTransport` options
            (``backoff_initial_s``, ``backoff_max_s``, ``read_timeout_s``…).

    Raises:
        serial.SerialException: the port cannot be opened (an ``OSError``).
    """
    transport = SerialTransport(
        settings.url,
        make_adapter(settings),
        baudrate=settings.baud,
        rtscts=settings.rtscts,
        port_factory=port_factory,
        **transport_options,
    )
    return LinkEndpoint(transport)


def latency_summary_ms(latencies_ns: Iterable[int]) -> dict[str, float]:
    """Median, 95th percentile, maximum and mean of latencies [ms], and their count.

    NaN for every statistic (and ``n`` 0) when there are none.
    """
    values = np.fromiter(latencies_ns, dtype=float) / 1e6
    if values.size == 0:
        return {"p50": math.nan, "p95": math.nan, "max": math.nan, "mean": math.nan, "n": 0}
    return {
        "p50": float(np.median(values)),
        "p95": float(np.percentile(values, 95)),
        "max": float(values.max()),
        "mean": float(values.mean()),
        "n": int(values.size),
    }


def endpoint_report(endpoint: LinkEndpoint) -> dict[str, Any]:
    """What one endpoint measured, JSON-ready.

    Keys: ``url``; ``bytes_in``/``bytes_out`` (raw port bytes, setup included);
    ``frames_in`` (decoded), ``frames_out`` (written whole), ``frames_dropped`` (queue full or
    port down); ``garbage_bytes`` (bytes the frame decoder skipped while hunting, plus bytes the
    adapter dropped as malformed modem sentences); ``corrupt_frames`` (candidates with a bad CRC,
    oversize or truncated); ``reopens`` (successful opens after the first), ``port_errors``,
    ``reopen_failures``, ``write_timeouts`` (single pyserial write timeouts, not port errors:
    :meth:`~.SerialTransport._write`), ``last_error``; ``added_latency_ms``
    (:func:`latency_summary_ms`);
    ``thread_lateness_ms``, how long the host held up the transport's ``reader`` and ``writer``
    threads (:attr:`~.Transport.reader_lateness_ns`, :attr:`~.Transport.writer_lateness_ns`; the
    same summary keys); and ``adapter``, the adapter's own counters.
    """
    transport = endpoint.transport
    adapter = transport.adapter.counters()
    return {
        "url": str(getattr(transport, "url", getattr(transport, "address", ""))),
        "bytes_in": transport.bytes_in,
        "bytes_out": transport.bytes_out,
        "frames_in": endpoint.frames_in,
        "frames_out": transport.frames_sent,
        "frames_dropped": transport.frames_dropped,
        "garbage_bytes": endpoint.decoder.garbage_bytes + adapter.get("garbage_bytes", 0),
        "corrupt_frames": endpoint.corrupt_frames,
        "reopens": max(0, transport.opens - 1),
        "port_errors": transport.port_errors,
        "reopen_failures": transport.reopen_failures,
        "write_timeouts": transport.write_timeouts,
        "last_error": transport.last_error,
        "added_latency_ms": latency_summary_ms(endpoint.latencies_ns),
        "thread_lateness_ms": {
            "reader": latency_summary_ms(transport.reader_lateness_ns.copy()),
            "writer": latency_summary_ms(transport.writer_lateness_ns.copy()),
        },
        "adapter": adapter,
    }
