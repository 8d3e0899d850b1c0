"""The concrete transports: :class:`SerialTransport` (any pyserial URL) and :class:`TcpTransport`.

Each only opens, reads and writes its port; the reader and writer threads, the reopen with
backoff, the counters and the packet-boundary rule are :class:`~testbed.hil.transport.Transport`'s
(:mod:`testbed.hil.transport`). ``_open`` runs in the constructor (its error propagates) and on
the reader thread when the port is reopened; ``_read`` runs on the reader thread and must
return empty within about the read timeout (default: the packet gap [s]) when nothing
arrives; ``_write`` runs on the writer thread (and for the adapter's setup writes, on whichever
thread opened the port).
"""

from __future__ import annotations

import socket
from collections.abc import Callable
from typing import Any

import serial

from .adapters import Adapter
from .transport import PortLike, Transport, packet_gap_s

__all__ = ["SerialTransport", "TcpTransport"]

_MAX_READ = 4096


class SerialTransport(Transport):
    """A link endpoint on a serial port: any pyserial URL (``/dev/ttyUSB0``, ``loop://``,
    ``socket://host:port``, ``rfc2217://host:port``).

    Args:
        url: port name or pyserial URL.
        adapter: the modem adapter.
        baudrate: port speed [bit/s].
        on_bytes: see :class:`Transport`.
        rtscts: RTS/CTS hardware flow control (pair it with ``S100Adapter(rtscts=True)``).
        read_timeout_s: how long a read waits for a first byte [s]; None = the packet gap, so
            an idle line ends a packet as soon as it has been idle that long. Bounds how fast
            :meth:`close` returns and when an idle line is seen, not latency (a read returns on
            its first byte).
        write_timeout_s: two writes in a row blocked longer than this (flow control stuck)
            count as a port error [s]; one alone is counted in ``write_timeouts``
            (:meth:`_write`).
        port_factory: opens the port (tests inject fakes); defaults to
            :func:`serial.serial_for_url` with the settings above.
        **kwargs: :class:`Transport` options (backoff, queue size, ``packet_gap_s``: default
            :func:`packet_gap_s` at ``baudrate``).

    Raises:
        serial.SerialException: the port cannot be opened the first time.
    """

    def __init__(
        self,
        url: str,
        adapter: Adapter,
        *,
        baudrate: int,
        on_bytes: Callable[[], None] | None = None,
        rtscts: bool = False,
        read_timeout_s: float | None = None,
        write_timeout_s: float = 2.0,
        port_factory: Callable[[], PortLike] | None = None,
        **kwargs: Any,
    ) -> None:
        kwargs.setdefault("packet_gap_s", packet_gap_s(baudrate))
        super().__init__(adapter, on_bytes=on_bytes, **kwargs)
        self.url = url
        timeout_s = self.packet_gap_s if read_timeout_s is None else read_timeout_s
        self.read_wait_s = timeout_s
        if port_factory is None:

            def port_factory() -> PortLike:
                port: PortLike = serial.serial_for_url(
                    url,
                    baudrate=baudrate,
                    rtscts=rtscts,
                    timeout=timeout_s,
                    write_timeout=write_timeout_s,
                )
                return port

        self._factory = port_factory
        self._timeouts_in_row = 0
        self._start(f"serial:{url}")

    def _open(self) -> PortLike:
        return self._factory()

    def _read(self, port: PortLike) -> bytes:
        data = port.read(1)
        if data:
            waiting = port.in_waiting
            if waiting:
                data += port.read(min(waiting, _MAX_READ))
        return data

    def _write(self, port: PortLike, data: bytes) -> None:
        """Write ``data``; pyserial's write timeout is a port error only twice in a row.

        pyserial also raises its ``SerialTimeoutException`` when the write went through but
        the host held the thread past the timeout before it looked at the clock (it checks
        after a complete ``os.write``): one timeout alone is counted (``write_timeouts``) and
        the frame taken as sent; flow control that is really stuck times out the next write
        too, and that one fails the port.
        """
        try:
            port.write(data)
        except serial.SerialTimeoutException:
            self.write_timeouts += 1
            self._timeouts_in_row += 1
            if self._timeouts_in_row >= 2:
                raise
            return
        self._timeouts_in_row = 0


class TcpTransport(Transport):
    """A link endpoint on a TCP connection (a modem's TCP port, e.g. EvoLogics 9200, or a
    peer testbed). Reconnects with backoff when the connection drops.

    Args:
        host: address to connect to.
        port: TCP port.
        adapter: the modem adapter.
        on_bytes: see :class:`Transport`.
        read_timeout_s: how long a receive waits [s] (bounds :meth:`close` and when an idle
            line is seen, not latency); None = the packet gap.
        connect_timeout_s: connection attempt timeout [s].
        **kwargs: :class:`Transport` options.

    Raises:
        OSError: the first connection fails.
    """

    def __init__(
        self,
        host: str,
        port: int,
        adapter: Adapter,
        *,
        on_bytes: Callable[[], None] | None = None,
        read_timeout_s: float | None = None,
        connect_timeout_s: float = 2.0,
        **kwargs: Any,
    ) -> None:
        super().__init__(adapter, on_bytes=on_bytes, **kwargs)
        self.address = (host, port)
        self._read_timeout_s = self.packet_gap_s if read_timeout_s is None else read_timeout_s
        self.read_wait_s = self._read_timeout_s
        self._connect_timeout_s = connect_timeout_s
        self._start(f"tcp:{host}:{port}")

    def _open(self) -> socket.socket:
        sock = socket.create_connection(self.address, timeout=self._connect_timeout_s)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.settimeout(self._read_timeout_s)
        return sock

    def _read(self, port: socket.socket) -> bytes:
        try:
            data = port.recv(_MAX_READ)
        except TimeoutError:
            return b""
        if not data:
            raise ConnectionError("connection closed by peer")
        return data

    def _write(self, port: socket.socket, data: bytes) -> None:
        port.sendall(data)
