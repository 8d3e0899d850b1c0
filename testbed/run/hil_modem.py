"""A node's modem on a real serial port, and the frame ledger and poll that go with it.

:class:`HilModem` gives a node of a real-time run the simulated modem's interface (``send``,
``on_receive``, ``last_frame_id``) on a :class:`~testbed.hil.LinkEndpoint`, i.e. a serial port
(any pyserial URL) through a modem adapter. :func:`~testbed.run.realtime.run_hil`, the live
console and the MAVLink gateway put their nodes on these.

Threads: each transport reads its port on its own thread and queues the bytes. The
:func:`run_poll` process drains the queues every ``poll_s`` (:data:`POLL_S`, 1 ms): each
endpoint decodes the stream (hunting through garbage, counting corrupt candidates) and each
whole frame is handed to its node's ``on_receive`` as a :class:`~testbed.channel.Delivery`
holding that frame's bytes, which the node feeds to its own decoder exactly as in a simulated
run. Nodes never block on I/O and nothing calls into simpy from another thread. Node code is
unchanged. Each time :func:`run_poll` wakes it may record how late it runs
(:func:`~testbed.run.wall_clock.rt_lateness_ns`).

Ground truth the wire does not carry: with both nodes on this computer one :class:`FrameLedger`
numbers the frames both nodes send and recognises each received frame by its bytes, so the
recorder follows a command from its sampling to its application (command lag, age of
information) as in simulation. A node alone cannot know its peer's frame ids or clock: see
:func:`~testbed.run.hil_metrics.hil_metrics` for what is then left out.

Link events in the recording: ``enqueue`` when a node hands a frame to its modem, ``drop``
when the port refuses it (queue full, port down), ``tx_start`` when it is queued for the port,
``deliver`` when a frame is handed to the receiving node and, with both nodes here,
``tx_end`` at that same instant for the frame the ledger recognised; so the timeline plot
draws each frame's whole time in the link (port, modem, air, host), not its airtime.
``outage`` marks frames refused or discarded in a scenario outage window.

The run that builds the nodes on these modems is in :mod:`testbed.run.realtime`; the metrics
drawn from them in :mod:`testbed.run.hil_metrics`.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Generator, Iterable, Sequence
from typing import Any

import simpy
import simpy.rt

from testbed.channel import Delivery, EventKind, Trace
from testbed.channel.trace import BROADCAST
from testbed.hil import LinkEndpoint
from testbed.protocol import Frame, encode_frame
from testbed.run.wall_clock import rt_lateness_ns

__all__ = [
    "DIRECTIONS",
    "POLL_S",
    "FrameLedger",
    "HilModem",
    "poll_modems",
    "run_poll",
]

POLL_S = 0.001
"""Period at which received bytes are taken from the reader threads [s]."""

DIRECTIONS = {"uplink": ("operator", "vehicle"), "downlink": ("vehicle", "operator")}
"""Link direction → (sender, receiver)."""

_LEDGER_HORIZON = 256
"""Frames per sender the ledger keeps outstanding; older ones are counted lost."""


class FrameLedger:
    """Frame ids on a real link: which sent frame a received frame is.

    Ids are given in send order from 0, one sequence for every sender using the ledger, as the
    simulated medium gives them. A received frame is matched with the oldest outstanding frame
    from its sender that has the same bytes; outstanding frames before it are counted lost (a
    modem link delivers in order). Identical frames sent back to back with the first lost are
    matched to the first: its id is then one frame early — harmless for the recorder's lags,
    which differ by one inter-packet gap only in that case.

    Args:
        horizon: outstanding frames kept per sender; older ones are counted lost.
    """

    def __init__(self, horizon: int = _LEDGER_HORIZON) -> None:
        self._horizon = horizon
        self._next_id = 0
        self._outstanding: dict[str, deque[tuple[int, bytes, float]]] = {}
        self.sent: dict[str, int] = {}
        self.matched: dict[str, int] = {}
        self.lost: dict[str, int] = {}

    def record_sent(self, src: str, data: bytes, t_s: float) -> int:
        """Number a frame ``src`` sends at ``t_s`` [s]; returns its id."""
        frame_id = self._next_id
        self._next_id += 1
        self.sent[src] = self.sent.get(src, 0) + 1
        queue = self._outstanding.setdefault(src, deque())
        queue.append((frame_id, bytes(data), t_s))
        if len(queue) > self._horizon:
            queue.popleft()
            self.lost[src] = self.lost.get(src, 0) + 1
        return frame_id

    def match(self, src: str, data: bytes) -> tuple[int, float] | None:
        """The id and send time [s] of the frame from ``src`` that ``data`` is, or None if no
        outstanding frame has these bytes (a peer on another computer, or garbage that passed
        the CRC)."""
        queue = self._outstanding.get(src)
        if not queue:
            return None
        for k, (frame_id, sent, t_s) in enumerate(queue):
            if sent == data:
                for _ in range(k + 1):
                    queue.popleft()
                self.lost[src] = self.lost.get(src, 0) + k
                self.matched[src] = self.matched.get(src, 0) + 1
                return frame_id, t_s
        return None

    def dropped(self, src: str, data: bytes) -> int:
        """The id of the oldest outstanding frame from ``src`` with bytes ``data``, which its
        port dropped before it reached the line: no longer outstanding, and neither delivered
        nor lost on the air (not in :meth:`settled`); −1 if none is outstanding."""
        queue = self._outstanding.get(src)
        for k, (frame_id, sent, _) in enumerate(queue or ()):
            if sent == data:
                assert queue is not None
                del queue[k]
                return frame_id
        return -1

    def settled(self, src: str) -> int:
        """Frames from ``src`` known to have arrived or been lost."""
        return self.matched.get(src, 0) + self.lost.get(src, 0)


class HilModem:
    """A node's modem on a real port, with the simulated modem's interface.

    Args:
        env: the (real-time) environment.
        name: this node (``"operator"`` or ``"vehicle"``).
        peer: the node at the other end.
        endpoint: the port and its frame decoder.
        trace: where the link events go (see the module docstring).
        ledger: frame numbering (shared by both nodes when both run here).
        outages: ``(start_s, end_s)`` windows in which frames are refused and discarded.

    Attributes:
        on_receive: called with one :class:`~testbed.channel.Delivery` per received frame (its
            bytes; ``frame_id`` −1 and ``t_tx_start_s`` NaN when the ledger does not know it).
        last_frame_id: id of the frame most recently handed to :meth:`send`.
        frames_offered: frames handed to :meth:`send`.
        bytes_offered: their bytes [B].
        outage_refused: frames refused in an outage window.
        outage_discarded: frames received in an outage window and discarded.
    """

    def __init__(
        self,
        env: simpy.Environment,
        name: str,
        peer: str,
        endpoint: LinkEndpoint,
        *,
        trace: Trace,
        ledger: FrameLedger,
        outages: Sequence[tuple[float, float]] = (),
    ) -> None:
        self.env = env
        self.name = name
        self.peer = peer
        self.endpoint = endpoint
        self.on_receive: Callable[[Delivery], None] | None = None  # the node's port sets it
        self.last_frame_id = -1
        self.frames_offered = 0
        self.bytes_offered = 0
        self.outage_refused = 0
        self.outage_discarded = 0
        self._trace = trace
        self._ledger = ledger
        self._outages = tuple(outages)

    def _in_outage(self, t_s: float) -> bool:
        return any(start <= t_s < end for start, end in self._outages)

    def send(self, data: bytes) -> bool:
        """Hand one frame to the port's writer thread (never blocks).

        Returns:
            False if it was refused (outage window) or dropped (queue full, port closed).
        """
        now = self.env.now
        frame_id = self._ledger.record_sent(self.name, data, now)
        self.last_frame_id = frame_id
        self.frames_offered += 1
        self.bytes_offered += len(data)
        trace = self._trace
        trace.record(now, EventKind.ENQUEUE, self.name, BROADCAST, frame_id, 0, len(data))
        if self._in_outage(now):
            self.outage_refused += 1
            trace.record(now, EventKind.OUTAGE, self.name, self.peer, frame_id, 0, len(data))
            return False
        if not self.endpoint.send(data):  # the queue full or the port closed: not on the air
            self._ledger.dropped(self.name, data)
            trace.record(now, EventKind.DROP, self.name, BROADCAST, frame_id, 0, len(data))
            return False
        trace.record(now, EventKind.TX_START, self.name, BROADCAST, frame_id, 0, len(data))
        return True

    def note_drops(self) -> None:
        """Record a drop for each frame the port dropped since the last call (accepted by
        :meth:`send`, then the port failed or closed before writing it): out of the PER, as a
        simulated sender's drops are. Call it for every modem before any :meth:`poll`
        (:func:`poll_modems`), so no frame received after a drop counts it lost."""
        dropped = self.endpoint.transport.dropped_frames
        while dropped:
            data = dropped.popleft()
            frame_id = self._ledger.dropped(self.name, data)
            self._trace.record(
                self.env.now, EventKind.DROP, self.name, BROADCAST, frame_id, 0, len(data)
            )

    def poll(self) -> int:
        """Hand every frame received so far to :attr:`on_receive`; returns how many."""
        self.note_drops()
        return self.endpoint.deliver(self._hand_over)

    def _hand_over(self, frame: Frame) -> None:
        now = self.env.now
        data = encode_frame(frame.payload)  # the bytes that crossed, byte for byte
        known = self._ledger.match(self.peer, data)
        frame_id, t_sent = known if known is not None else (-1, math.nan)
        trace = self._trace
        if self._in_outage(now):
            self.outage_discarded += 1
            trace.record(now, EventKind.OUTAGE, self.peer, self.name, frame_id, 0, len(data))
            return
        if known is not None:
            trace.record(now, EventKind.TX_END, self.peer, BROADCAST, frame_id, 0, len(data))
        trace.record(now, EventKind.DELIVER, self.peer, self.name, frame_id, 0, len(data))
        if self.on_receive is not None:
            self.on_receive(Delivery(data, t_sent, now, frame_id, self.peer))


def poll_modems(modems: Iterable[HilModem]) -> None:
    """Note every modem's port drops, then hand each one's received frames to its node."""
    modems = list(modems)
    for modem in modems:
        modem.note_drops()
    for modem in modems:
        modem.poll()


def run_poll(
    env: simpy.Environment,
    modems: Sequence[HilModem],
    period_s: float = POLL_S,
    lateness_ns: deque[int] | list[int] | None = None,
) -> Generator[simpy.Event, Any, None]:
    """simpy process: every ``period_s`` [s], hand each modem's received frames to its node.

    With ``lateness_ns`` (and a real-time ``env``), each wake-up first appends how late it ran
    (:func:`rt_lateness_ns`) [ns]."""
    rt_env = env if isinstance(env, simpy.rt.RealtimeEnvironment) else None
    while True:
        if rt_env is not None and lateness_ns is not None:
            lateness_ns.append(rt_lateness_ns(rt_env))
        poll_modems(modems)
        yield env.timeout(period_s)
