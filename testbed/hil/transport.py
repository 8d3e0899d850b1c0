"""Transports: the threads between a link endpoint and its port (serial or TCP).

A transport owns two threads and never blocks its caller:

* the **reader** reads the port, passes the bytes through the modem adapter
  (:meth:`Adapter.receive <testbed.hil.adapters.Adapter.receive>`) and puts the payload stream
  on :attr:`Transport.inbox` (a :class:`queue.Queue` of :class:`Received`), stamped with the
  time the read returned and marked where a received packet ends; an optional ``on_bytes``
  callback then wakes whoever waits (e.g. a real-time simpy loop);
* the **writer** takes frames queued by :meth:`Transport.send` and writes the adapter's chunks,
  holding after each as the adapter asks (air-rate pacing).

Each time the port opens (the first time and after every fault) the adapter's
:meth:`~testbed.hil.adapters.Adapter.setup` writes go out first (modem configuration, queue
flush), before the writer may use the port.

Faults never stop a run. A read or write that fails (port unplugged, socket closed, write
timeout) closes the port and counts a port error; the reader reopens it with exponential
backoff while frames sent in the meantime are dropped and counted, as on a dead link. Garbage
on the line is the adapter's and the frame decoder's business: counted, never fatal.

This module holds the port-independent part: :class:`Transport` (threads, reopen with backoff,
counters), :class:`Received`, :class:`PortLike`, :data:`PORT_ERRORS` and :func:`packet_gap_s`.
The subclasses that open, read and write a real port are in :mod:`~testbed.hil.serial_tcp`
(:class:`~testbed.hil.serial_tcp.SerialTransport`, :class:`~testbed.hil.serial_tcp.TcpTransport`);
the frame decoding a node polls is :class:`~testbed.hil.link_endpoint.LinkEndpoint`.

Packet boundaries: the stream decoder gives up a mis-framed candidate (a corrupted length byte
claiming more bytes than came) at the end of each received packet, as the simulated modem's
receiver does at the end of each transmission (``LinkPort._receive``), so the intact frames
behind it are not held for the bytes its false length claims. Where a packet ends is the
adapter's to say (:class:`~testbed.hil.adapters.Segment`): the end of a modem's received message
(EvoLogics instant messages, M64 packets: the last one of each frame), or, for a
byte-transparent modem, the line going idle: once the reader has read nothing for
``packet_gap_s`` after the last bytes (default :func:`packet_gap_s`, the larger of 20 ms and 4
byte times), it calls :meth:`Adapter.idle <testbed.hil.adapters.Adapter.idle>`. The gap is
observed, never inferred: only a read that returned nothing ends one, so a reader thread
delayed by a loaded machine can make a boundary late, never early. The flush changes nothing
for a stream of intact frames (the decoder holds nothing at a packet's end).

The adapter's ``receive`` and ``idle`` run on the reader thread and ``writes`` on the writer
thread only.
"""

from __future__ import annotations

import contextlib
import queue
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from .adapters import Adapter

__all__ = [
    "PORT_ERRORS",
    "PortLike",
    "Received",
    "Transport",
    "packet_gap_s",
]

PORT_ERRORS: tuple[type[Exception], ...] = (OSError, AttributeError, TypeError, ValueError)
"""What a failing port raises: pyserial's SerialException is an OSError; a port closed under a
blocked read can surface as AttributeError/TypeError/ValueError from its vanished socket or
file descriptor."""

_LATENESS_SAMPLES = 200_000
"""Thread-lateness samples kept per thread (the newest)."""

_DROPPED_KEPT = 4096
"""Dropped frames' bytes kept for a reader of :attr:`Transport.dropped_frames` (the newest)."""

MIN_PACKET_GAP_S = 0.02
"""Shortest idle time that ends a packet on a byte-transparent modem's line [s]. A USB serial
adapter hands bytes to the host in bursts (an FTDI chip's latency timer is 16 ms by default),
so a packet still arriving can leave the host without a byte for that long; 20 ms is above it,
and far below the gap between two orders (0.594 s on the S100)."""


def packet_gap_s(baudrate: int) -> float:
    """Idle time that ends a received packet on a byte-transparent line [s]: the larger of
    :data:`MIN_PACKET_GAP_S` and 4 byte times (10 bits each) at ``baudrate``."""
    return max(MIN_PACKET_GAP_S, 40.0 / baudrate)


@dataclass(frozen=True, slots=True)
class Received:
    """Payload-stream bytes from one port read.

    Attributes:
        data: bytes for the frame decoder (modem chatter already removed; may be empty when
            only ``end`` is news).
        read_ns: :func:`time.perf_counter_ns` when the port read returned (or, for the end of
            a packet seen as an idle line, when the reader saw it) [ns].
        end: a received packet ends after ``data`` (module docstring: packet boundaries).
    """

    data: bytes
    read_ns: int
    end: bool = False


class PortLike(Protocol):
    """The part of a pyserial port (or a fake) a transport uses."""

    def read(self, size: int = 1) -> bytes: ...

    def write(self, data: bytes) -> int | None: ...

    @property
    def in_waiting(self) -> int: ...

    def close(self) -> None: ...


class Transport:
    """Reader and writer threads around a port that may fail and come back.

    Subclasses provide ``_open`` (may raise one of :data:`PORT_ERRORS`), ``_read`` and
    ``_write``. The first open happens in the constructor and its error propagates (a wrong
    path is the user's mistake); later opens retry with backoff.

    Args:
        adapter: the modem adapter.
        on_bytes: called on the reader thread after each :class:`Received` is queued; must not
            block. Exceptions from it are counted (``callback_errors``), not raised.
        backoff_initial_s: first wait before reopening a failed port [s].
        backoff_max_s: longest wait between reopen attempts [s].
        max_pending_frames: frames :meth:`send` may queue; more are dropped and counted.
        log_bytes: keep every byte read and written, setup included, in :attr:`byte_log`
            (``(perf_counter_ns, "in" | "out", bytes)``, in each thread's order) — a HIL
            session's raw record (``testbed hil --log-bytes``).
        packet_gap_s: idle time after the last bytes read that ends a packet on a transparent
            line [s] (module docstring); a subclass's reads must return empty within about
            this long when nothing arrives.

    Attributes:
        inbox: received payload stream, in order.
        connected: set while the port is open.
        read_wait_s: how long a read waits when nothing arrives [s] (set by the subclass).
        reader_lateness_ns: per read, how much longer than ``read_wait_s`` passed since the
            previous read returned [ns], 0 when not: a reader thread the host held up shows
            here, whatever the port did (bytes that arrived meanwhile were picked up at most
            this plus ``read_wait_s`` late).
        writer_lateness_ns: per chunk written, its write's return less the instant it could
            first have been written (queued by :meth:`send`, or the previous chunk's pacing
            hold ended) [ns]: a writer thread the host held up shows here.
    """

    def __init__(
        self,
        adapter: Adapter,
        *,
        on_bytes: Callable[[], None] | None = None,
        backoff_initial_s: float = 0.05,
        backoff_max_s: float = 2.0,
        max_pending_frames: int = 64,
        packet_gap_s: float = MIN_PACKET_GAP_S,
        log_bytes: bool = False,
    ) -> None:
        if not packet_gap_s > 0:
            raise ValueError(f"packet_gap_s must be > 0, got {packet_gap_s!r}")
        if not 0 < backoff_initial_s <= backoff_max_s:
            raise ValueError(
                f"need 0 < backoff_initial_s <= backoff_max_s, got "
                f"{backoff_initial_s!r}, {backoff_max_s!r}"
            )
        if max_pending_frames < 1:
            raise ValueError(f"max_pending_frames must be >= 1, got {max_pending_frames!r}")
        self.adapter = adapter
        self.packet_gap_s = float(packet_gap_s)
        self.inbox: queue.Queue[Received] = queue.Queue()
        self.connected = threading.Event()
        self._on_bytes = on_bytes
        self._backoff_initial_s = backoff_initial_s
        self._backoff_max_s = backoff_max_s
        self._outbox: queue.Queue[tuple[bytes, float] | None] = queue.Queue(max_pending_frames)
        self.read_wait_s = float(packet_gap_s)
        self.reader_lateness_ns: deque[int] = deque(maxlen=_LATENESS_SAMPLES)
        self.writer_lateness_ns: deque[int] = deque(maxlen=_LATENESS_SAMPLES)
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._port: Any = None
        self._threads: list[threading.Thread] = []
        self.opens = 0
        self.port_errors = 0
        self.reopen_failures = 0
        self.last_error = ""
        self.frames_sent = 0
        self.frames_dropped = 0
        self.dropped_frames: deque[bytes] = deque(maxlen=_DROPPED_KEPT)
        self.byte_log: deque[tuple[int, str, bytes]] | None = deque() if log_bytes else None
        self.bytes_in = 0
        self.bytes_out = 0
        self.callback_errors = 0
        self.setup_writes = 0
        self.write_timeouts = 0  # writes the port timed out once (SerialTransport)
        self.packet_ends = 0

    def _start(self, name: str) -> None:
        port = self._open()
        try:
            self._setup(port)
        except PORT_ERRORS:
            self._safe_close(port)
            raise
        self._set_port(port)
        for role, target in (("reader", self._read_loop), ("writer", self._write_loop)):
            thread = threading.Thread(target=target, name=f"{name}-{role}", daemon=True)
            thread.start()
            self._threads.append(thread)

    # -- subclass hooks -------------------------------------------------------------------
    def _open(self) -> Any:
        raise NotImplementedError

    def _read(self, port: Any) -> bytes:
        raise NotImplementedError

    def _write(self, port: Any, data: bytes) -> None:
        raise NotImplementedError

    def _close_port(self, port: Any) -> None:
        port.close()

    # -- caller side ----------------------------------------------------------------------
    def send(self, frame: bytes) -> bool:
        """Queue one encoded frame for writing; never blocks. A frame it accepts is later
        written whole (``frames_sent``) or dropped (``frames_dropped``, its bytes appended to
        :attr:`dropped_frames`: the port failed or closed first).

        Returns:
            False if the queue was full or the transport closed (the frame is dropped and
            counted), else True.
        """
        if self._stop.is_set():
            self.frames_dropped += 1
            return False
        try:
            self._outbox.put_nowait((bytes(frame), time.monotonic()))
        except queue.Full:
            self.frames_dropped += 1
            return False
        return True

    def counters(self) -> dict[str, int]:
        """Transport counters merged with the adapter's (prefixed ``adapter_``)."""
        counts = {
            "opens": self.opens,
            "port_errors": self.port_errors,
            "reopen_failures": self.reopen_failures,
            "frames_sent": self.frames_sent,
            "frames_dropped": self.frames_dropped,
            "bytes_in": self.bytes_in,
            "bytes_out": self.bytes_out,
            "callback_errors": self.callback_errors,
            "setup_writes": self.setup_writes,
            "packet_ends": self.packet_ends,
            "write_timeouts": self.write_timeouts,
        }
        counts.update({f"adapter_{k}": v for k, v in self.adapter.counters().items()})
        return counts

    def close(self, timeout_s: float = 2.0) -> None:
        """Stop both threads, close the port and join the threads.

        Frames :meth:`send` accepted that were not written by then (still queued, or waiting
        for the previous chunk's pacing) are counted dropped: every accepted frame ends as
        sent or dropped.
        """
        self._stop.set()
        unwritten: list[bytes] = []
        while True:  # make room for the writer's stop sentinel
            try:
                self._outbox.put_nowait(None)
                break
            except queue.Full:
                with contextlib.suppress(queue.Empty):
                    if (item := self._outbox.get_nowait()) is not None:
                        unwritten.append(item[0])
        with self._lock:
            port, self._port = self._port, None
        if port is not None:
            self._safe_close(port)
        self.connected.clear()
        for thread in self._threads:
            thread.join(timeout_s)
        while True:  # what the writer left queued
            try:
                item = self._outbox.get_nowait()
            except queue.Empty:
                break
            if item is not None:
                unwritten.append(item[0])
        for frame in unwritten:
            self._drop(frame)

    def _log(self, direction: str, data: bytes, t_ns: int | None = None) -> None:
        """Keep ``data`` read (``"in"``) or written (``"out"``) at ``t_ns`` (``perf_counter_ns``,
        now if None) in :attr:`byte_log`, when the transport logs bytes."""
        if self.byte_log is not None:
            self.byte_log.append(
                (time.perf_counter_ns() if t_ns is None else t_ns, direction, data)
            )

    def _drop(self, frame: bytes) -> None:
        """Count ``frame``, accepted by :meth:`send`, dropped unwritten (or part written) and
        keep its bytes in :attr:`dropped_frames` for whoever accounts for frames by their bytes
        (the real-time run's frame ledger)."""
        self.frames_dropped += 1
        self.dropped_frames.append(frame)

    def __enter__(self) -> Transport:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- threads --------------------------------------------------------------------------
    def _set_port(self, port: Any) -> None:
        with self._lock:
            self._port = port
            self.opens += 1
        self.connected.set()

    def _setup(self, port: Any) -> None:
        """Write the adapter's setup sequence on a freshly opened port (reader thread, or the
        constructor, before the writer can see the port)."""
        for chunk in self.adapter.setup():
            self._write(port, chunk.data)
            self._log("out", chunk.data)
            self.bytes_out += len(chunk.data)
            self.setup_writes += 1
            if chunk.hold_s > 0:
                self._stop.wait(chunk.hold_s)

    def _safe_close(self, port: Any) -> None:
        with contextlib.suppress(*PORT_ERRORS):
            self._close_port(port)

    def _fail(self, port: Any, exc: BaseException) -> None:
        """The port errored: drop it (once, whichever thread notices first)."""
        with self._lock:
            if self._port is not port:
                return
            self._port = None
            self.port_errors += 1
            self.last_error = f"{type(exc).__name__}: {exc}"
        self.connected.clear()
        self._safe_close(port)

    def _queue(self, segments: list[Any], read_ns: int) -> None:
        """Put the adapter's segments on the inbox (empty ones only for a packet end), then
        wake the consumer."""
        queued = False
        for segment in segments:
            if segment.data or segment.end:
                self.inbox.put(Received(segment.data, read_ns, segment.end))
                self.packet_ends += segment.end
                queued = True
        if queued and self._on_bytes is not None:
            try:
                self._on_bytes()
            except Exception:
                self.callback_errors += 1

    def _read_loop(self) -> None:
        backoff = self._backoff_initial_s
        last_data_s = 0.0
        in_packet = False  # bytes read since the line was last seen idle
        last_return_ns = 0  # 0: no read returned since the port (re)opened
        while not self._stop.is_set():
            port = self._port
            if port is None:
                last_return_ns = 0
                try:
                    port = self._open()
                    try:
                        self._setup(port)
                    except PORT_ERRORS:
                        self._safe_close(port)
                        raise
                except PORT_ERRORS as exc:
                    self.reopen_failures += 1
                    self.last_error = f"{type(exc).__name__}: {exc}"
                    self._stop.wait(backoff)
                    backoff = min(2 * backoff, self._backoff_max_s)
                    continue
                if self._stop.is_set():
                    self._safe_close(port)
                    return
                self._set_port(port)
                backoff = self._backoff_initial_s
            try:
                data = self._read(port)
            except PORT_ERRORS as exc:
                if not self._stop.is_set():
                    self._fail(port, exc)
                continue
            returned_ns = time.perf_counter_ns()
            if last_return_ns:
                wait_ns = round(self.read_wait_s * 1e9)
                self.reader_lateness_ns.append(max(0, returned_ns - last_return_ns - wait_ns))
            last_return_ns = returned_ns
            if not data:
                # an empty read: nothing arrived since the last bytes were read
                if in_packet and time.monotonic() - last_data_s >= self.packet_gap_s:
                    in_packet = False
                    self._queue(self.adapter.idle(), time.perf_counter_ns())
                continue
            read_ns = returned_ns
            last_data_s = time.monotonic()
            in_packet = True
            self.bytes_in += len(data)
            self._log("in", data, read_ns)
            self._queue(self.adapter.receive(data), read_ns)

    def _write_loop(self) -> None:
        next_ok = 0.0
        while True:
            item = self._outbox.get()
            if item is None:
                return
            if self._stop.is_set():
                self._drop(item[0])  # accepted, closed before it was written
                return
            frame, ready_s = item
            for chunk in self.adapter.writes(frame):
                ready_s = max(ready_s, next_ok)
                delay = next_ok - time.monotonic()
                if delay > 0 and self._stop.wait(delay):
                    self._drop(frame)  # closed while it waited for its turn
                    return
                port = self._port
                if port is None:
                    self._drop(frame)
                    break
                try:
                    self._write(port, chunk.data)
                except PORT_ERRORS as exc:
                    self._fail(port, exc)
                    self._drop(frame)
                    break
                written_s = time.monotonic()
                self._log("out", chunk.data)
                self.writer_lateness_ns.append(max(0, round((written_s - ready_s) * 1e9)))
                self.bytes_out += len(chunk.data)
                next_ok = written_s + chunk.hold_s
            else:
                self.frames_sent += 1
