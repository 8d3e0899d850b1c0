"""Modem emulator: two pseudo-terminals joined in real time by the simulated link.

:class:`ModemEmulator` opens two PTYs, ``A`` and ``B``, and runs a :class:`~testbed.channel.Medium`
with two modems under ``simpy.rt.RealtimeEnvironment`` in a background thread, so a program that
talks to a serial modem (pyserial, :class:`~testbed.hil.SerialTransport`) can run end to end with
no hardware: what is written on A arrives on B after the channel model's intrinsic delay, airtime
and propagation, with its bit errors, FIFO tail drops and half-duplex collisions, and vice versa.

Framing rule (a byte-transparent modem such as the S100): the bytes a user writes on a port are
collected until the line has been idle for ``idle_s`` (default 3 ms) or ``max_burst_bytes`` have
accumulated (default: the preset's ``tx_buffer_bytes``); each such burst is one transmission,
handed to the modem at the wall-clock instant the burst closed. One ``write()`` of a frame is
therefore one transmission; writes closer together than ``idle_s`` merge. Presets with
``packet_bytes > 0`` cut a burst into zero-padded packets, and the padding reaches the other port,
as the model delivers it. Delivered copies are written to the other port as they are delivered;
bytes the other PTY cannot take (nobody reading, its buffer full) are dropped and counted.

Modem personalities (``modem="evologics"`` or ``"m64"``, :mod:`testbed.emulator.personalities`):
each
port then behaves as that modem's serial interface instead of a transparent one. Every burst is
fed to the port's personality at the instant it closed; its replies (``OK``, ``wrq,a``…) go
straight back to the same port, and what it queues for the water (instant messages, 8-byte
packets) is handed to the simulated modem one packet at a time, whenever that modem's FIFO is
empty (the next packet waits in the modem while the previous one is on the air). What the link
delivers goes through the receiving port's personality, which writes it as that modem would
(``RECVIM`` events, ``wrp`` sentences) or drops it (bit errors, wrong address, role or
channel). Port A starts as EvoLogics address 1 or M64 role ``a``, port B as address 2 or role
``b`` (both M64 on channel 4), until the user's own setup commands change them. The default,
``"transparent"``, is the byte-transparent modem above, unchanged.

Threads: one reader thread (``select`` on both PTY masters) and one simulation thread. The only
thing they share is a :class:`queue.Queue` of bursts, drained by a simpy process every
``poll_s`` (default 1 ms); nothing calls into simpy from outside its thread. Wall time maps to
simulated time as the real-time environment does (``env_start + (wall − real_start) / factor``),
so a burst polled late is still sent at the simulated instant it closed, whenever that is not
already past. POSIX only (``os.openpty``).

Scheduler lateness (instrumentation, :attr:`ModemEmulator.scheduler_lateness_ms`): each poll of
the simulation thread records how late it ran against its real-time schedule, and the reader
records how late it closed each burst against the instant its idle gap ended, and how much
longer than its select timeout passed between two of its wake-ups (a reader the host held up
picks bytes up that late, whatever it stamps them). A delivery is written to its port as late
as the simulation thread runs, and a burst enters the link as late as the reader closes it or
is held up; tests add these to the channel model's latency on a loaded machine.

Size: one class, the two ports and the simulation thread that joins them; a little over the
500-line guideline, kept whole because its threads share the ports' state.
"""

from __future__ import annotations

import contextlib
import os
import queue
import select
import threading
import time
import tty
from collections import deque
from collections.abc import Callable, Generator
from dataclasses import dataclass
from types import TracebackType

import numpy as np
import simpy
import simpy.rt

from testbed.channel import Delivery, LinkConfig, Medium, Modem
from testbed.emulator.personalities import (
    EVOLOGICS_IM_MAX,
    AirPacket,
    EvoLogicsPersonality,
    M64Personality,
    ModemPersonality,
)

__all__ = ["MODEM_PERSONALITIES", "ModemEmulator", "PortCounters"]

MODEM_PERSONALITIES = ("transparent", "evologics", "m64")
"""What the emulated modems are: byte-transparent (S100 style), EvoLogics S2C in data mode, or
Water Linked M64."""

_READ_CHUNK = 4096
_SELECT_TIMEOUT_S = 0.02
_JOIN_TIMEOUT_S = 2.0
_MAX_IN_FLIGHT = 4096
"""Headers of transmissions kept for their delivery (copies lost in collisions never claim
theirs; the oldest are forgotten beyond this many)."""
_ACK_MARGIN_S = 0.5
"""Added to the round trip of an EvoLogics instant message and its ack to time it out [s]."""
_LATENESS_SAMPLES = 100_000
"""Scheduler lateness samples kept per thread (the newest)."""


@dataclass(slots=True)
class PortCounters:
    """Counters of one emulated port (read them; the emulator updates them).

    Attributes:
        bytes_in: bytes the user wrote on this port.
        bursts: transmissions made from them (see the module's framing rule).
        bursts_dropped: bursts the modem's FIFO tail-dropped.
        deliveries: copies delivered to this port by the other modem (with a personality,
            including those it then drops).
        bytes_out: bytes written to this port (deliveries, bit errors included; with a modem
            personality, its replies and events).
        bytes_overflowed: delivered bytes the PTY could not take (nobody reading).
    """

    bytes_in: int = 0
    bursts: int = 0
    bursts_dropped: int = 0
    deliveries: int = 0
    bytes_out: int = 0
    bytes_overflowed: int = 0


class _Port:
    """One PTY pair and the burst being collected on it (internal)."""

    __slots__ = ("burst", "counters", "last_byte_s", "master", "name", "path", "slave")

    def __init__(self, name: str) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)  # no echo, no CR/LF translation before a user opens it
        os.set_blocking(master, False)
        self.name = name
        self.master = master
        self.slave = slave  # kept open so the master never sees a hang-up between users
        self.path = os.ttyname(slave)
        self.burst = bytearray()
        self.last_byte_s = 0.0
        self.counters = PortCounters()

    def close(self) -> None:
        for fd in (self.master, self.slave):
            with contextlib.suppress(OSError):
                os.close(fd)


class ModemEmulator:
    """Two pseudo-terminals joined in real time by a simulated link.

    Args:
        config: link parameters (a preset from :func:`~testbed.channel.load_link_config`).
        seed: seed of the link's random generator (bit errors).
        time_factor: wall-clock seconds per simulated second (1 = real time, 2 = twice as slow).
        distance_m: distance between the two modems [m].
        idle_s: line idle time that closes a burst [s, wall clock].
        max_burst_bytes: largest burst [B]; None = ``config.tx_buffer_bytes``.
        poll_s: period at which the simulation takes bursts from the reader [s, wall clock].
        modem: the modems' serial interface, one of :data:`MODEM_PERSONALITIES`.

    Raises:
        ValueError: a non-positive ``time_factor``, ``idle_s``, ``poll_s`` or
            ``max_burst_bytes``, a negative ``distance_m`` or an unknown ``modem`` (local
            misuse).
        OSError: the PTYs could not be opened.
    """

    def __init__(
        self,
        config: LinkConfig,
        *,
        seed: int,
        time_factor: float = 1.0,
        distance_m: float = 0.0,
        idle_s: float = 0.003,
        max_burst_bytes: int | None = None,
        poll_s: float = 0.001,
        modem: str = "transparent",
    ) -> None:
        if modem not in MODEM_PERSONALITIES:
            raise ValueError(f"modem must be one of {MODEM_PERSONALITIES}, got {modem!r}")
        if not time_factor > 0.0:
            raise ValueError(f"time_factor must be > 0, got {time_factor}")
        if not (idle_s > 0.0 and poll_s > 0.0):
            raise ValueError(f"idle_s and poll_s must be > 0, got {idle_s}, {poll_s}")
        if not distance_m >= 0.0:
            raise ValueError(f"distance_m must be ≥ 0, got {distance_m}")
        burst_cap = config.tx_buffer_bytes if max_burst_bytes is None else max_burst_bytes
        if burst_cap < 1:
            raise ValueError(f"max_burst_bytes must be ≥ 1, got {burst_cap}")
        self.config = config
        self.time_factor = time_factor
        self._idle_s = idle_s
        self._poll_s = poll_s
        self._burst_cap = burst_cap
        self._env = simpy.rt.RealtimeEnvironment(factor=time_factor, strict=False)
        medium = Medium(self._env, config, np.random.default_rng(seed))
        self._modems = (
            medium.attach("a"),
            medium.attach("b", lambda: (distance_m, 0.0, 0.0)),
        )
        self._ports: tuple[_Port, _Port] = (_Port("a"), _Port("b"))
        self.modem = modem
        self._personalities = _personalities(modem, config, distance_m)
        self._in_flight: dict[int, AirPacket] = {}
        for side, port in enumerate(self._ports):
            # what modem b receives comes out of port B
            self._modems[side].on_receive = (
                self._writer(port) if self._personalities is None else self._receiver(side)
            )
        self._inbox: queue.Queue[tuple[int, bytes, float]] = queue.Queue()
        self._stop = threading.Event()
        self._wake_r, self._wake_w = os.pipe()
        self._threads: list[threading.Thread] = []
        self._started = False
        self._closed = False
        self._error: BaseException | None = None
        self._sim_lateness_ns: deque[int] = deque(maxlen=_LATENESS_SAMPLES)
        self._reader_lateness_ns: deque[int] = deque(maxlen=_LATENESS_SAMPLES)
        self._reader_stall_ns: deque[int] = deque(maxlen=_LATENESS_SAMPLES)

    # -- public --------------------------------------------------------------------------------

    @property
    def paths(self) -> tuple[str, str]:
        """Device paths of ports A and B (open them with pyserial)."""
        return self._ports[0].path, self._ports[1].path

    @property
    def counters(self) -> tuple[PortCounters, PortCounters]:
        """Counters of ports A and B (live objects)."""
        return self._ports[0].counters, self._ports[1].counters

    @property
    def modems(self) -> tuple[Modem, Modem]:
        """The simulated modems behind ports A and B (read their ``counters`` only)."""
        return self._modems

    @property
    def personality_counters(self) -> tuple[dict[str, int], dict[str, int]] | None:
        """Counters of the modem personalities behind ports A and B (copies); None when the
        modems are transparent."""
        if self._personalities is None:
            return None
        return self._personalities[0].counters(), self._personalities[1].counters()

    @property
    def scheduler_lateness_ms(self) -> dict[str, dict[str, float]]:
        """How late the emulator's threads ran [ms]: ``simulation``, each poll of the simulation
        thread against its real-time schedule (deliveries are written as late); ``reader``, each
        burst closed by the reader against the instant its line went idle for ``idle_s`` (or its
        byte count was reached: 0); ``reader_stall``, each wake-up of the reader less its
        previous one and the timeout it waited with (0 when not longer). Each
        ``{p50, p95, max, mean, n}``, NaN (``n`` 0) before any sample.
        A snapshot: read it again after more traffic."""
        return {
            "simulation": _summary_ms(list(self._sim_lateness_ns.copy())),
            "reader": _summary_ms(list(self._reader_lateness_ns.copy())),
            "reader_stall": _summary_ms(list(self._reader_stall_ns.copy())),
        }

    @property
    def error(self) -> BaseException | None:
        """The exception that stopped a background thread, if one did."""
        return self._error

    def start(self) -> None:
        """Start the reader and simulation threads.

        Raises:
            RuntimeError: already started, or closed.
        """
        if self._closed or self._started:
            raise RuntimeError("a ModemEmulator starts once and cannot restart after close()")
        self._started = True
        self._threads = [
            threading.Thread(target=self._guard(self._run_reader), name="emulator-reader"),
            threading.Thread(target=self._guard(self._run_simulation), name="emulator-sim"),
        ]
        for thread in self._threads:
            thread.daemon = True
            thread.start()

    def close(self) -> None:
        """Stop and join the threads, then close the PTYs (idempotent)."""
        if self._closed:
            return
        self._closed = True
        self._stop.set()
        with contextlib.suppress(OSError):
            os.write(self._wake_w, b"x")
        for thread in self._threads:
            thread.join(_JOIN_TIMEOUT_S)
        for port in self._ports:
            port.close()
        for fd in (self._wake_r, self._wake_w):
            with contextlib.suppress(OSError):
                os.close(fd)

    def __enter__(self) -> ModemEmulator:
        if not self._started:
            self.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # -- threads -------------------------------------------------------------------------------

    def _guard(self, target: Callable[[], None]) -> Callable[[], None]:
        """Wrap a thread body: an exception is kept in :attr:`error` and stops the other thread."""

        def body() -> None:
            try:
                target()
            except BaseException as err:  # reported through .error
                if self._error is None:
                    self._error = err
                self._stop.set()
                with contextlib.suppress(OSError):
                    os.write(self._wake_w, b"x")

        return body

    def _run_reader(self) -> None:
        """Read both PTY masters; close bursts on idle or size and queue them for the link."""
        ports = self._ports
        fds = {port.master: port for port in ports}
        watched = [*fds, self._wake_r]
        woke_s = time.monotonic()
        while not self._stop.is_set():
            timeout_s = _SELECT_TIMEOUT_S
            now = time.monotonic()
            for port in ports:
                if port.burst:
                    timeout_s = min(timeout_s, max(0.0, port.last_byte_s + self._idle_s - now))
            readable, _, _ = select.select(watched, [], [], timeout_s)
            now = time.monotonic()
            self._reader_stall_ns.append(max(0, round((now - woke_s - timeout_s) * 1e9)))
            woke_s = now
            for fd in readable:
                if fd not in fds:
                    continue  # the wake-up pipe: the loop condition decides
                port = fds[fd]
                try:
                    data = os.read(fd, _READ_CHUNK)
                except (BlockingIOError, InterruptedError):
                    continue
                except OSError:  # EIO: no slave side open (cannot happen while we hold it)
                    continue
                port.counters.bytes_in += len(data)
                port.burst += data
                port.last_byte_s = now
                while len(port.burst) >= self._burst_cap:
                    self._close_burst(port, self._burst_cap, now)
                    self._reader_lateness_ns.append(0)
            for port in ports:
                if port.burst and now - port.last_byte_s >= self._idle_s:
                    late_s = now - (port.last_byte_s + self._idle_s)
                    self._close_burst(port, len(port.burst), now)
                    self._reader_lateness_ns.append(round(late_s * 1e9))

    def _close_burst(self, port: _Port, size: int, now_s: float) -> None:
        data = bytes(port.burst[:size])
        del port.burst[:size]
        port.counters.bursts += 1
        self._inbox.put((0 if port is self._ports[0] else 1, data, now_s))

    def _run_simulation(self) -> None:
        env = self._env
        env.sync()
        env.run(until=env.process(self._run_inbox(env)))

    def _run_inbox(self, env: simpy.rt.RealtimeEnvironment) -> Generator[simpy.Event, None, None]:
        """simpy process: hand queued bursts to their modems at the instant they closed."""
        poll_sim_s = self._poll_s / env.factor
        inbox = self._inbox
        lateness_ns = self._sim_lateness_ns
        while not self._stop.is_set():
            scheduled_s = env.real_start + (env.now - env.env_start) * env.factor
            lateness_ns.append(round((time.monotonic() - scheduled_s) * 1e9))
            while True:
                try:
                    side, data, wall_s = inbox.get_nowait()
                except queue.Empty:
                    break
                at_s = env.env_start + (wall_s - env.real_start) / env.factor
                send = self._sender(side, data)
                if at_s > env.now:
                    env.timeout(at_s - env.now).callbacks.append(send)
                else:
                    send(None)
            if self._personalities is not None:
                for side, personality in enumerate(self._personalities):
                    self._write_port(self._ports[side], personality.poll(env.now))
                    self._pump(side)
            yield env.timeout(poll_sim_s)

    def _sender(self, side: int, data: bytes) -> Callable[[simpy.Event | None], None]:
        modem = self._modems[side]
        counters = self._ports[side].counters
        personalities = self._personalities

        def send(_event: simpy.Event | None) -> None:
            if personalities is not None:
                replies = personalities[side].feed(data, self._env.now)
                self._write_port(self._ports[side], replies)
                self._pump(side)
            elif not modem.send(data):
                counters.bursts_dropped += 1

        return send

    def _pump(self, side: int) -> None:
        """Hand the personality's next packet to its modem when the modem's FIFO is empty (so
        it follows the one on the air after exactly the link's queue gap)."""
        assert self._personalities is not None
        personality = self._personalities[side]
        modem = self._modems[side]
        in_flight = self._in_flight
        while modem.queued_bytes == 0:
            packet = personality.next_packet(self._env.now)
            if packet is None:
                return
            if not modem.send(packet.data):
                self._ports[side].counters.bursts_dropped += 1
                continue
            in_flight[modem.last_frame_id] = packet
            if len(in_flight) > _MAX_IN_FLIGHT:
                del in_flight[next(iter(in_flight))]

    def _receiver(self, side: int) -> Callable[[Delivery], None]:
        """The ``on_receive`` callback that passes deliveries through port ``side``'s
        personality."""
        assert self._personalities is not None
        personality = self._personalities[side]
        port = self._ports[side]
        airtime_s = self.config.airtime_s

        def receive(delivery: Delivery) -> None:
            port.counters.deliveries += 1
            packet = self._in_flight.pop(delivery.frame_id, None)
            if packet is None:
                return
            data = personality.receive(
                packet,
                delivery.data,
                bit_errors=delivery.bit_errors,
                duration_s=airtime_s(len(delivery.data)),
                now_s=self._env.now,
            )
            self._write_port(port, data)
            self._pump(side)

        return receive

    def _write_port(self, port: _Port, data: bytes) -> None:
        """Write a personality's output to ``port`` (what the PTY cannot take is counted)."""
        if not data:
            return
        try:
            written = os.write(port.master, data)
        except BlockingIOError:
            written = 0
        except OSError:
            if self._closed:
                return
            raise
        port.counters.bytes_out += written
        port.counters.bytes_overflowed += len(data) - written

    def _writer(self, port: _Port) -> Callable[[Delivery], None]:
        """The ``on_receive`` callback that writes a modem's deliveries to ``port``."""
        counters = port.counters

        def write(delivery: Delivery) -> None:
            counters.deliveries += 1
            self._write_port(port, delivery.data)

        return write


def _summary_ms(values_ns: list[int]) -> dict[str, float]:
    """``{p50, p95, max, mean, n}`` of nanosecond samples, in ms (NaN and 0 when empty)."""
    if not values_ns:
        nan = float("nan")
        return {"p50": nan, "p95": nan, "max": nan, "mean": nan, "n": 0}
    values = np.asarray(values_ns, dtype=float) / 1e6
    return {
        "p50": float(np.median(values)),
        "p95": float(np.percentile(values, 95)),
        "max": float(values.max()),
        "mean": float(values.mean()),
        "n": int(values.size),
    }


def _personalities(
    modem: str, config: LinkConfig, distance_m: float
) -> tuple[ModemPersonality, ModemPersonality] | None:
    """The personalities behind ports A and B, or None for transparent modems."""
    if modem == "evologics":
        # An instant message and its 1-byte ack, each with the modem's latency and the
        # propagation, plus a margin.
        one_way_s = config.intrinsic_delay_s + config.propagation.delay_s(distance_m)
        # The message may wait in the modem behind one on the air: one more message airtime.
        round_trip_s = (
            2 * one_way_s + config.airtime_s(2 * EVOLOGICS_IM_MAX + 1) + 2 * config.queue_gap_s
        )
        return (
            EvoLogicsPersonality(
                1, queue_bytes=config.tx_buffer_bytes, ack_timeout_s=round_trip_s + _ACK_MARGIN_S
            ),
            EvoLogicsPersonality(
                2, queue_bytes=config.tx_buffer_bytes, ack_timeout_s=round_trip_s + _ACK_MARGIN_S
            ),
        )
    if modem == "m64":
        packets = max(1, config.tx_buffer_bytes // 8)
        return M64Personality("a", queue_packets=packets), M64Personality(
            "b", queue_packets=packets
        )
    return None
