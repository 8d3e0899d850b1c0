"""The shared medium and the modems attached to it: timing, FIFOs, collisions, bit errors.

The shape is simpy's ``Cable`` example (a store plus a delay, apart from sender and receiver),
with the semantics of the dccomms_ros custom link (REFERENCE §2.1):

- ``Modem.send`` puts a frame in a byte-counted transmit FIFO (tail drop when it would overflow
  ``tx_buffer_bytes``). With ``packet_bytes > 0`` the frame is cut into fixed-size packets, the
  last zero-padded, each queued and sent as its own transmission.
- A transmission spends ``intrinsic_delay_s`` (the device counts as transmitting), then the
  airtime ``8·len / bitrate_bps`` (the link model's, :meth:`~.model.LinkModel.airtime_s`).
  The next queued transmission starts ``queue_gap_s`` after that. In half duplex a modem
  defers its queue while it is receiving and until ``queue_gap_s`` after the reception ends
  (also for a frame queued as the reception ends: a reply to the frame just received), and
  loses any reception that overlaps its own transmission.
- The medium is a broadcast channel: every other attached modem within ``max_range_m`` (distance
  between the position callables at transmit time) receives its own copy, which arrives after
  the propagation delay ``fixed_s + distance / speed_mps``: the copy is on the air at the
  receiver from ``t0 + intrinsic + propagation`` to ``t0 + intrinsic + airtime + propagation``
  and is handed over at the end. Unloaded latency is therefore exactly
  intrinsic + airtime + propagation; with packets, N·(intrinsic + packet airtime) +
  (N − 1)·``queue_gap_s`` + propagation for the last of a frame's N packets.
- Any overlap of two receptions at one modem destroys both (no capture); destroyed copies are
  counted and traced, never delivered. Other copies are delivered with bits flipped by the
  receiver's error model (the link model's, :meth:`~.model.LinkModel.error_model`: by default
  :class:`~testbed.channel.errors.BitErrors`) — the receiver's decoder must catch them.
  The per-bit probability of independent errors is 1 − (1 − ber)(1 − min(1, ber_per_m·d)), with
  d the distance at transmit time; the receiver's Gilbert–Elliott chain (if enabled) is ORed on
  top and advances over the bits of the copies it is handed (not over destroyed ones).
- Frame ids are given per medium, from 0, in ``send`` order (dropped frames included).

Per copy the model schedules one simpy timeout (its delivery); a transmitter schedules a wake-up
only when its FIFO must wait. There is no process per frame. All of it runs unchanged under
``simpy.rt.RealtimeEnvironment``.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import replace

import numpy as np
import simpy

from testbed.channel.config import LinkConfig
from testbed.channel.delivery import Delivery, ModemCounters, decode_delivery
from testbed.channel.model import (
    LinkModel,
    StandardLink,
    checked_airtime_s,
    checked_corrupt,
    made_error_model,
    wanted_keywords,
)
from testbed.channel.trace import BROADCAST, EventKind, Trace

__all__ = ["Delivery", "Medium", "Modem", "ModemCounters", "Position", "decode_delivery"]

Position = Callable[[], tuple[float, float, float]]
"""A node's position [m], world NED, read at each transmission."""

_ORIGIN = (0.0, 0.0, 0.0)
_TIME_EPS_S = 1e-12
"""Times closer than this are equal (guards float round-off between wake-ups and deadlines)."""


class _Reception:
    """One copy on the air at one receiver (internal, mutable)."""

    __slots__ = (
        "collided",
        "deaf",
        "distance_m",
        "end_s",
        "entry",
        "p_independent",
        "src",
        "start_s",
        "t_tx_start_s",
    )

    def __init__(
        self,
        src: str,
        entry: _Queued,
        t_tx_start_s: float,
        start_s: float,
        end_s: float,
        p_independent: float,
        distance_m: float,
    ) -> None:
        self.src = src
        self.distance_m = distance_m
        self.entry = entry
        self.t_tx_start_s = t_tx_start_s
        self.start_s = start_s
        self.end_s = end_s
        self.p_independent = p_independent
        self.collided = False  # lost: it overlapped another copy, or the receiver transmitted
        self.deaf = False  # lost only because the receiver transmitted (half duplex)


_Queued = tuple[int, int, int, bytes]
"""A transmission waiting in a FIFO: (frame_id, part, parts, data) (internal)."""


class Medium:
    """A broadcast link shared by the modems attached to it.

    Args:
        env: the simpy environment (plain or real-time).
        config: link parameters.
        rng: random generator; each attached modem gets an independent child stream from it
            (``rng.spawn``), so one receiver's errors do not depend on another's traffic.
        trace: event sink, or None for speed.
        model: the link model (air time, bit errors; :mod:`~testbed.channel.model`); None:
            the preset's own (:class:`~testbed.channel.model.StandardLink`).
    """

    def __init__(
        self,
        env: simpy.Environment,
        config: LinkConfig,
        rng: np.random.Generator,
        trace: Trace | None = None,
        model: LinkModel | None = None,
    ) -> None:
        self.env = env
        self.config = config
        self.trace = trace
        self.model: LinkModel = StandardLink(config) if model is None else model
        self._rng = rng
        self._modems: list[Modem] = []
        self._next_frame_id = 0
        # Hot-path copies of the configuration.
        self._intrinsic_s = config.intrinsic_delay_s
        self._fixed_s = config.propagation.fixed_s
        self._speed_mps = config.propagation.speed_mps
        self._max_range_m = config.max_range_m
        self._ber = config.ber
        self._ber_per_m = config.ber_per_m
        self._outages: list[tuple[float, float]] = []

    def add_outage(self, start_s: float, end_s: float) -> None:
        """Black the link out over ``[start_s, end_s)`` [s]: every copy whose reception overlaps
        the window is lost (traced ``OUTAGE``), in both directions — an unplugged modem, a
        shadowed acoustic path.

        Raises:
            ValueError: ``end_s <= start_s`` or ``start_s < 0`` (local misuse).
        """
        if start_s < 0.0 or end_s <= start_s:
            raise ValueError(f"outage window must have 0 <= start < end, got [{start_s}, {end_s})")
        self._outages.append((start_s, end_s))

    def set_ber(self, ber: float) -> None:
        """Change the independent bit error probability of transmissions that start from now on
        (copies already on the air keep theirs); :attr:`config` follows. For live sessions
        (:mod:`testbed.live`): a simulated run sets its link once, in its config.

        Raises:
            ValueError: ``ber`` not in [0, 1] (local misuse).
        """
        if not 0.0 <= ber <= 1.0:
            raise ValueError(f"ber must be in [0, 1], got {ber}")
        self._ber = ber
        self.config = replace(self.config, ber=ber)

    def in_outage(self, start_s: float, end_s: float) -> bool:
        """Whether the interval ``[start_s, end_s]`` overlaps an outage window."""
        return any(a < end_s and start_s < b for a, b in self._outages)

    @property
    def modems(self) -> tuple[Modem, ...]:
        """The attached modems, in attach order."""
        return tuple(self._modems)

    def attach(self, name: str, position: Position | None = None) -> Modem:
        """Attach a node's modem.

        Args:
            name: unique node name (used as ``src``/``dst`` in deliveries and traces).
            position: callable giving the node's position [m], world NED; None = origin.

        Raises:
            ValueError: the name is already attached.
        """
        if any(m.name == name for m in self._modems):
            raise ValueError(f"a modem named {name!r} is already attached")
        modem = Modem(self, name, position, self._rng.spawn(1)[0])
        self._modems.append(modem)
        return modem

    def _broadcast(self, sender: Modem, entry: _Queued, t0: float, busy_s: float) -> None:
        """Hand a transmission that starts at ``t0`` (now) to every other modem in range."""
        env = self.env
        trace = self.trace
        here = sender.position
        for receiver in self._modems:
            if receiver is sender:
                continue
            there = receiver.position
            if here is None and there is None:
                distance_m = 0.0
            else:
                distance_m = math.dist(
                    _ORIGIN if here is None else here(), _ORIGIN if there is None else there()
                )
            if distance_m > self._max_range_m:
                receiver.counters.rx_out_of_range += 1
                if trace is not None:
                    frame_id, part, _, data = entry
                    kind = EventKind.OUT_OF_RANGE
                    trace.record(t0, kind, sender.name, receiver.name, frame_id, part, len(data))
                continue
            prop_s = self._fixed_s + distance_m / self._speed_mps
            p = self._ber
            if self._ber_per_m > 0.0:
                p = 1.0 - (1.0 - p) * (1.0 - min(1.0, self._ber_per_m * distance_m))
            delay_s = busy_s + prop_s
            start_s = t0 + (self._intrinsic_s + prop_s)
            rec = _Reception(sender.name, entry, t0, start_s, t0 + delay_s, p, distance_m)
            receiver._start_reception(rec)
            simpy.Timeout(env, delay_s, rec).callbacks.append(receiver._finish_reception)


class Modem:
    """A node's interface to a :class:`Medium` (made by :meth:`Medium.attach`).

    Received copies go to :attr:`on_receive` if it is set, otherwise to an inbox read with
    :meth:`drain`; :meth:`wait` gives an event that fires when the inbox has something.

    Attributes:
        name: node name.
        position: position callable [m], NED, or None for the origin.
        on_receive: callback called with each :class:`Delivery` at its delivery time (the copy
            then bypasses the inbox), or None.
        counters: this modem's counters.
        last_frame_id: id of the frame most recently handed to :meth:`send` (−1 before any;
            set whether or not it was dropped), for instrumentation.
    """

    def __init__(
        self, medium: Medium, name: str, position: Position | None, rng: np.random.Generator
    ) -> None:
        config = medium.config
        self.name = name
        self.position = position
        self.on_receive: Callable[[Delivery], None] | None = None
        self.counters = ModemCounters()
        self.last_frame_id = -1
        self._medium = medium
        self._env = medium.env
        self._half_duplex = config.duplex == "half"
        self._intrinsic_s = config.intrinsic_delay_s
        self._medium_model = medium.model
        self._gap_s = config.queue_gap_s
        self._buffer_bytes = config.tx_buffer_bytes
        self._packet_bytes = config.packet_bytes
        model = medium.model
        self._errors = made_error_model(model, rng, name)
        # the context a user's laws ask for (none for the preset's: its calls stay as they were)
        self._airtime_context = {key: name for key in wanted_keywords(model.airtime_s, ("sender",))}
        self._corrupt_keys = wanted_keywords(self._errors.corrupt, ("sender", "distance_m"))
        self._fifo: deque[_Queued] = deque()
        self._fifo_bytes = 0
        self._tx_start_s = -math.inf
        self._tx_end_s = -math.inf
        self._free_at_s = -math.inf
        self._rx_end_s = -math.inf  # the end of the last reception this modem finished
        self._wakeup_pending = False
        self._receptions: list[_Reception] = []
        self._inbox: list[Delivery] = []
        self._waiters: list[simpy.Event] = []

    def __repr__(self) -> str:
        return f"Modem({self.name!r})"

    # -- sending -------------------------------------------------------------------------------

    @property
    def queued_bytes(self) -> int:
        """Bytes waiting in the transmit FIFO (not counting the transmission on the air)."""
        return self._fifo_bytes

    @property
    def transmitting(self) -> bool:
        """Whether the modem is sending now (intrinsic delay or airtime)."""
        return self._tx_start_s <= self._env.now < self._tx_end_s

    @property
    def receiving(self) -> bool:
        """Whether a copy is on the air at this modem now."""
        now = self._env.now
        return any(r.start_s <= now < r.end_s for r in self._receptions)

    def send(self, data: bytes) -> bool:
        """Queue one frame for transmission.

        The frame (with its packet padding) must fit in the free FIFO space, even when the
        modem is idle and would start sending it at once.

        Args:
            data: the frame's bytes (non-empty).

        Returns:
            True if queued, False if tail-dropped because the FIFO had no room.

        Raises:
            ValueError: ``data`` is empty (local misuse).
        """
        if not data:
            raise ValueError("cannot send an empty frame")
        data = bytes(data)
        medium = self._medium
        frame_id = medium._next_frame_id
        medium._next_frame_id = frame_id + 1
        self.last_frame_id = frame_id
        packet = self._packet_bytes
        if packet:
            n = -(-len(data) // packet)
            data = data.ljust(n * packet, b"\x00")
        size = len(data)
        self.counters.frames_offered += 1
        trace = medium.trace
        if trace is not None:
            now = self._env.now  # only needed for the trace
            trace.record(now, EventKind.ENQUEUE, self.name, BROADCAST, frame_id, 0, size)
        if self._fifo_bytes + size > self._buffer_bytes:
            self.counters.frames_dropped += 1
            if trace is not None:
                trace.record(now, EventKind.DROP, self.name, BROADCAST, frame_id, 0, size)
            return False
        if packet:
            self._fifo.extend(
                (frame_id, k, n, data[k * packet : (k + 1) * packet]) for k in range(n)
            )
        else:
            self._fifo.append((frame_id, 0, 1, data))
        self._fifo_bytes += size
        if not self._wakeup_pending:
            self._pump()
        return True

    def _pump(self) -> None:
        """Start the head of the FIFO now if the modem is free, else schedule a wake-up."""
        if not self._fifo:
            return
        now = self._env.now
        ready_s = self._free_at_s
        if self._half_duplex:
            for r in self._receptions:  # defer while receiving (carrier sense, as dccomms)
                if r.start_s <= now < r.end_s and r.end_s + self._gap_s > ready_s:
                    ready_s = r.end_s + self._gap_s
            # and for the gap after one that just ended (a reply sent as its order arrives)
            ready_s = max(ready_s, self._rx_end_s + self._gap_s)
        if ready_s - now > _TIME_EPS_S:
            self._wakeup_pending = True
            simpy.Timeout(self._env, ready_s - now).callbacks.append(self._wake)
        else:
            self._transmit(self._fifo.popleft(), now)

    def _wake(self, _event: simpy.Event) -> None:
        self._wakeup_pending = False
        self._pump()

    def _transmit(self, entry: _Queued, now: float) -> None:
        frame_id, part, _, data = entry
        size = len(data)
        self._fifo_bytes -= size
        airtime_s = checked_airtime_s(self._medium_model, size, now, **self._airtime_context)
        busy_s = self._intrinsic_s + airtime_s
        end_s = now + busy_s
        self._tx_start_s = now
        self._tx_end_s = end_s
        self._free_at_s = now + (busy_s + self._gap_s)
        counters = self.counters
        counters.tx_transmissions += 1
        counters.tx_bytes += size
        trace = self._medium.trace
        if trace is not None:
            trace.record(now, EventKind.TX_START, self.name, BROADCAST, frame_id, part, size)
            trace.record(end_s, EventKind.TX_END, self.name, BROADCAST, frame_id, part, size)
        if self._half_duplex:
            for r in self._receptions:  # cannot receive while transmitting
                if r.start_s < end_s and r.end_s > now and not r.collided:
                    r.collided = r.deaf = True
        self._medium._broadcast(self, entry, now, busy_s)
        if self._fifo:
            self._pump()

    # -- receiving -----------------------------------------------------------------------------

    def _start_reception(self, rec: _Reception) -> None:
        start_s = rec.start_s
        end_s = rec.end_s
        for other in self._receptions:  # any overlap destroys both: no capture
            if other.start_s < end_s and other.end_s > start_s:
                other.collided, other.deaf = True, False
                rec.collided = True
        if self._half_duplex and self._tx_start_s < end_s and self._tx_end_s > start_s:
            rec.deaf = not rec.collided
            rec.collided = True
        self._receptions.append(rec)

    def _finish_reception(self, event: simpy.Event) -> None:
        rec: _Reception = event.value  # type: ignore[assignment]  # the Timeout carries it
        self._receptions.remove(rec)
        self._rx_end_s = max(self._rx_end_s, rec.end_s)
        frame_id, part, parts, data = rec.entry
        trace = self._medium.trace
        counters = self.counters
        now = self._env.now
        if self._medium._outages and self._medium.in_outage(rec.start_s, now):
            counters.rx_outage += 1
            if trace is not None:
                kind = EventKind.OUTAGE
                trace.record(now, kind, rec.src, self.name, frame_id, part, len(data))
            return
        if rec.collided:
            counters.rx_collided += 1
            counters.rx_deaf += rec.deaf
            if trace is not None:
                kind = EventKind.DEAF if rec.deaf else EventKind.COLLIDE
                trace.record(now, kind, rec.src, self.name, frame_id, part, len(data))
            return
        if self._corrupt_keys:
            context = {"sender": rec.src, "distance_m": rec.distance_m}
            wanted = {key: context[key] for key in self._corrupt_keys}
            data, n_errors = checked_corrupt(self._errors, data, rec.p_independent, now, **wanted)
        else:
            data, n_errors = checked_corrupt(self._errors, data, rec.p_independent, now)
        if n_errors:
            counters.rx_corrupted += 1
            counters.rx_bit_errors += n_errors
        else:
            counters.rx_delivered += 1
        if trace is not None:
            kind = EventKind.CORRUPT if n_errors else EventKind.DELIVER
            trace.record(now, kind, rec.src, self.name, frame_id, part, len(data), n_errors)
        delivery = Delivery(data, rec.t_tx_start_s, now, frame_id, rec.src, part, parts, n_errors)
        if self.on_receive is not None:
            self.on_receive(delivery)
            return
        self._inbox.append(delivery)
        if self._waiters:
            waiters = self._waiters
            self._waiters = []
            for waiter in waiters:
                waiter.succeed()

    def drain(self) -> list[Delivery]:
        """Everything delivered since the last drain, in delivery order (non-blocking)."""
        inbox = self._inbox
        self._inbox = []
        return inbox

    def wait(self) -> simpy.Event:
        """An event that fires once the inbox is non-empty (at once if it already is)."""
        event = self._env.event()
        if self._inbox:
            event.succeed()
        else:
            self._waiters.append(event)
        return event
