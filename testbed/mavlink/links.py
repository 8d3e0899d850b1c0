"""Ground-station links: UDP (out and in), TCP (listening) and serial, each with a reader thread.

A link's reader thread queues every datagram or read as a :class:`~testbed.hil.Received`
(bytes and :func:`time.perf_counter_ns` when the read returned) on :attr:`inbox`; the real-time
run drains it from its own process (nothing calls into simpy from a reader thread).

Packet boundaries (:attr:`~testbed.hil.Received.end`): each UDP datagram ends a packet, so the
decoder never joins a stray or truncated datagram with the next one (a stray start byte would
otherwise swallow the ≈ 265 B behind it); on ``tcpin`` the end of a client's stream (it hung up,
or a new client replaced it) is an empty read with ``end``, so the next client starts with no
piece of the old one's packet. A serial line is a plain stream with no boundaries (MAVLink
frames itself, and a telemetry radio delivers a packet in bursts with gaps between them).
:meth:`send` is called from the run's thread and never blocks for long (UDP ``sendto``; TCP with
a short timeout; serial through :class:`~testbed.hil.SerialTransport`'s writer thread).

URLs (MAVProxy's and ArduPilot SITL's words):

* ``udpout:HOST:PORT`` — send to HOST:PORT from an ephemeral local port and take what comes
  back from it only (SITL's ``--out``; the default, ``udpout:127.0.0.1:14550``, is where
  QGroundControl and MAVProxy listen);
* ``udpin:HOST:PORT`` — listen on HOST:PORT, answer the last sender;
* ``tcpin:HOST:PORT`` — listen for one TCP client at a time (a new one replaces the old; one
  thread accepts and reads);
* ``serial:PORT[,BAUD]`` or a pyserial URL (``/dev/ttyUSB0``, ``socket://…``, ``loop://``) —
  115200 baud by default.

Addresses bind to 127.0.0.1 unless the URL names another host (an IPv6 one, e.g. ``::1``,
opens an IPv6 socket). Bad URLs raise ``ValueError``;
ports that cannot be opened raise ``OSError`` (the CLI turns both into one line).
"""

from __future__ import annotations

import queue
import select
import socket
import threading
import time
from typing import Any, Protocol

from testbed.hil import BAUD_RANGE, RawAdapter, Received, Segment, SerialTransport

__all__ = [
    "DEFAULT_BAUD",
    "DEFAULT_URL",
    "INBOX_PACKETS",
    "INGEST_BYTES_PER_FRAME",
    "MAX_UDP_DATAGRAM",
    "Intake",
    "Link",
    "SerialLink",
    "TcpServerLink",
    "UdpLink",
    "open_link",
    "parse_url",
]

DEFAULT_URL = "udpout:127.0.0.1:14550"
DEFAULT_BAUD = 115200
_READ_TIMEOUT_S = 0.1
_MAX_DATAGRAM = 65535
INBOX_PACKETS = 256
"""Reads a link's inbox holds at most; a read that finds it full is dropped and counted
(``inbox_full``): a flood costs the reader thread a count, not the run its memory."""
MAX_UDP_DATAGRAM = 4096
"""Longest UDP datagram queued [B] (≈ 15 full MAVLink 2 packets; ground stations and routers
send one packet a datagram); a longer one is dropped and counted (``oversize``), so a backlog
of a full inbox is at most ≈ 1 MiB, 64 frames' share."""
INGEST_BYTES_PER_FRAME = 16384
"""Bytes an :class:`Intake` hands a frame from one link (≈ 1.6 MB/s at 100 Hz, hundreds of
times a ground station's uplink; decoding that much garbage costs ≈ 2 ms): what is left waits
in the inbox for the next frame, so a flood cannot stall the frame loop."""


class Link(Protocol):
    """What the run needs of a ground-station link."""

    url: str
    inbox: queue.Queue[Received]

    def send(self, data: bytes) -> bool:
        """Send one packet; False if it was dropped."""
        ...

    def counters(self) -> dict[str, int]:
        """Bytes and packets in and out, drops."""
        ...

    def close(self) -> None:
        """Stop the threads and close the port."""
        ...


def parse_url(url: str) -> tuple[str, str, int]:
    """``(kind, host or port name, port number or baud)`` of a link URL.

    Raises:
        ValueError: an unknown scheme, a missing or bad port number, a baud rate outside
            :data:`testbed.hil.BAUD_RANGE`.
    """
    for kind in ("udpout", "udpin", "tcpin"):
        if url.startswith(kind + ":"):
            host, sep, port = url[len(kind) + 1 :].rpartition(":")
            if not sep or not port.isdigit() or not 0 < int(port) < 65536:
                raise ValueError(f"{url!r}: expected {kind}:HOST:PORT with a port 1..65535")
            return kind, host or "127.0.0.1", int(port)
    rest = url.removeprefix("serial:")
    if not rest or (rest == url and ":" in url and "://" not in url):
        raise ValueError(f"{url!r}: expected udpout:, udpin:, tcpin:, serial: or a pyserial URL")
    name, _, baud = rest.partition(",")
    low, high = BAUD_RANGE
    if baud and not (baud.isdigit() and low <= int(baud) <= high):
        raise ValueError(f"{url!r}: baud must be an integer in [{low}, {high}], got {baud!r}")
    return "serial", name, int(baud) if baud else DEFAULT_BAUD


class Intake:
    """A frame's share of one link's reads: at most ``max_bytes`` a call, oldest first. A read
    longer than what is left of the share is split and its rest handed out first next time
    (the decoder continues a packet across calls), so neither a flood nor one huge datagram
    can stall the frame loop; what waits stays in order.

    Args:
        inbox: the link's :attr:`Link.inbox`.
        max_bytes: the share [B], > 0.
    """

    __slots__ = ("_carry", "_inbox", "max_bytes")

    def __init__(
        self, inbox: queue.Queue[Received], max_bytes: int = INGEST_BYTES_PER_FRAME
    ) -> None:
        if max_bytes <= 0:
            raise ValueError(f"max_bytes must be > 0, got {max_bytes}")
        self._inbox = inbox
        self.max_bytes = max_bytes
        self._carry: Received | None = None

    def take(self) -> list[Received]:
        """This frame's reads (their ``read_ns`` kept; a split read's first part not ``end``)."""
        taken: list[Received] = []
        budget = self.max_bytes
        while budget > 0:
            received = self._carry
            self._carry = None
            if received is None:
                try:
                    received = self._inbox.get_nowait()
                except queue.Empty:
                    break
            data = received.data
            if len(data) > budget:
                self._carry = Received(data[budget:], received.read_ns, received.end)
                received = Received(data[:budget], received.read_ns)
            taken.append(received)
            budget -= len(received.data)
        return taken


class _Counted:
    def __init__(self, url: str) -> None:
        self.url = url
        self.inbox: queue.Queue[Received] = queue.Queue(maxsize=INBOX_PACKETS)
        self.inbox_full = 0
        self.oversize = 0
        self.bytes_in = 0
        self.bytes_out = 0
        self.packets_in = 0
        self.packets_out = 0
        self.dropped = 0
        self._end_pending = False
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []

    def _start(self, target: Any) -> None:
        thread = threading.Thread(target=target, name=f"mavlink:{self.url}", daemon=True)
        thread.start()
        self._threads.append(thread)

    def _queue(self, data: bytes, end: bool = False) -> None:
        if self._end_pending and not self._mark_end():
            self.inbox_full += 1  # the end of the last stream first: this read cannot follow it
            return
        try:
            self.inbox.put_nowait(Received(data, time.perf_counter_ns(), end))
        except queue.Full:  # a flood: counted, not kept
            self.inbox_full += 1
            return
        self.bytes_in += len(data)
        self.packets_in += 1

    def _mark_end(self) -> bool:
        """Queue the end of a stream (an empty read with ``end``); if the inbox is full, it is
        queued before the next read instead (False)."""
        try:
            self.inbox.put_nowait(Received(b"", time.perf_counter_ns(), True))
        except queue.Full:
            self._end_pending = True
            return False
        self._end_pending = False
        return True

    def counters(self) -> dict[str, int]:
        return {
            "bytes_in": self.bytes_in,
            "bytes_out": self.bytes_out,
            "packets_in": self.packets_in,
            "packets_out": self.packets_out,
            "dropped": self.dropped,
            "inbox_full": self.inbox_full,
            "oversize": self.oversize,
        }

    def _join(self) -> None:
        self._stop.set()
        for thread in self._threads:
            thread.join(timeout=2.0)


class UdpLink(_Counted):
    """UDP: ``udpout`` sends to a fixed peer and takes datagrams from that peer only (a
    connected socket); ``udpin`` listens and answers the last sender.

    Args:
        url: the link's URL (for the record).
        host: peer (out) or bind (in) address.
        port: peer (out) or bind (in) port.
        listen: True for ``udpin``.
    """

    def __init__(self, url: str, host: str, port: int, *, listen: bool) -> None:
        super().__init__(url)
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self._sock = socket.socket(family, socket.SOCK_DGRAM)
        self._sock.settimeout(_READ_TIMEOUT_S)
        self._peer: tuple[Any, ...] | None = None
        try:
            if listen:
                self._sock.bind((host, port))
            else:
                # connected: the local address is the one that routes to the peer (loopback for
                # a local peer, never every interface), and the kernel drops datagrams from
                # anyone but the peer
                self._sock.connect((host, port))
        except OSError:
            self._sock.close()
            raise
        if not listen:
            self._peer = (host, port)
        self.local_address = self._sock.getsockname() if listen else None
        self._start(self._read_loop)

    def _read_loop(self) -> None:
        while not self._stop.is_set():
            try:
                data, sender = self._sock.recvfrom(_MAX_DATAGRAM)
            except TimeoutError:
                continue
            except OSError:
                if self._stop.is_set():
                    return
                continue  # e.g. ICMP port unreachable from a peer not listening yet
            if self.local_address is not None:
                self._peer = sender
            if len(data) > MAX_UDP_DATAGRAM:
                self.oversize += 1
                continue
            self._queue(data, end=True)  # a datagram is a packet boundary

    def send(self, data: bytes) -> bool:
        peer = self._peer
        if peer is None:
            self.dropped += 1
            return False
        try:
            if self.local_address is None:
                self._sock.send(data)  # connected to the peer
            else:
                self._sock.sendto(data, peer)
        except OSError:
            self.dropped += 1
            return False
        self.bytes_out += len(data)
        self.packets_out += 1
        return True

    def close(self) -> None:
        self._stop.set()
        self._join()
        self._sock.close()


class TcpServerLink(_Counted):
    """``tcpin``: listen on HOST:PORT; one client at a time, the newest wins. One thread
    accepts and reads, so what the old client sent is queued before its stream's end and the
    new client's bytes after it."""

    def __init__(self, url: str, host: str, port: int) -> None:
        super().__init__(url)
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self._server = socket.create_server((host, port), family=family, reuse_port=False)
        self._server.settimeout(_READ_TIMEOUT_S)
        self.local_address = self._server.getsockname()
        self._client: socket.socket | None = None
        self._lock = threading.Lock()
        self.clients = 0
        self._start(self._serve)

    def _serve(self) -> None:
        server = self._server
        while not self._stop.is_set():
            client = self._client  # only this thread replaces it
            watched = [server] if client is None else [server, client]
            try:
                readable, _, _ = select.select(watched, [], [], _READ_TIMEOUT_S)
            except (OSError, ValueError):  # closed under us
                return
            if client is not None and client in readable:
                try:
                    data = client.recv(_MAX_DATAGRAM)
                except TimeoutError:
                    data = None
                except OSError:
                    data = b""
                if data:
                    self._queue(data)
                elif data is not None:  # hung up
                    self._end_stream(client, None)
            if server in readable:
                try:
                    new, _ = server.accept()
                except TimeoutError:
                    continue
                except OSError:
                    if self._stop.is_set():
                        return
                    continue
                new.settimeout(_READ_TIMEOUT_S)
                self.clients += 1
                self._end_stream(self._client, new)

    def _end_stream(self, old: socket.socket | None, new: socket.socket | None) -> None:
        """Replace the client (``old`` hung up or ``new`` takes its place) and end the old
        stream: a packet it left incomplete is not continued by the next client's bytes."""
        with self._lock:
            self._client = new
        if old is not None:
            old.close()
            self._mark_end()

    def send(self, data: bytes) -> bool:
        with self._lock:
            client = self._client
        if client is None:
            self.dropped += 1
            return False
        try:
            client.sendall(data)
        except OSError:
            self.dropped += 1
            return False
        self.bytes_out += len(data)
        self.packets_out += 1
        return True

    def close(self) -> None:
        self._join()
        self._server.close()
        with self._lock:
            client, self._client = self._client, None
        if client is not None:
            client.close()


class _StreamAdapter(RawAdapter):
    """:class:`~testbed.hil.RawAdapter` whose idle line ends nothing: a MAVLink stream."""

    def idle(self) -> list[Segment]:
        """Nothing: a pause on the line (a radio's burst gap) is no packet boundary."""
        return []


class SerialLink:
    """A serial port or pyserial URL through :class:`~testbed.hil.SerialTransport` (a
    transparent adapter: MAVLink frames itself; no packet ends at a pause)."""

    def __init__(self, url: str, port: str, baudrate: int) -> None:
        self.url = url
        self.transport = SerialTransport(port, _StreamAdapter(), baudrate=baudrate)
        self.inbox = self.transport.inbox

    def send(self, data: bytes) -> bool:
        return self.transport.send(data)

    def counters(self) -> dict[str, int]:
        c = self.transport.counters()
        return {
            "bytes_in": c.get("bytes_in", 0),
            "bytes_out": c.get("bytes_out", 0),
            "packets_in": 0,
            "packets_out": c.get("frames_sent", 0),
            "dropped": c.get("frames_dropped", 0),
        }

    def close(self) -> None:
        self.transport.close()


def open_link(url: str) -> Link:
    """Open the link a URL names (module docstring).

    Raises:
        ValueError: a malformed URL.
        OSError: the address or port cannot be opened (in use, no such device…).
    """
    kind, host, number = parse_url(url)
    if kind in ("udpout", "udpin"):
        return UdpLink(url, host, number, listen=kind == "udpin")
    if kind == "tcpin":
        return TcpServerLink(url, host, number)
    return SerialLink(url, host, number)
