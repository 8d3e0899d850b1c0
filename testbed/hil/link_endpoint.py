"""The link endpoint: a transport plus a frame decoder, polled by a node for frames.

:class:`LinkEndpoint` joins a :class:`~testbed.hil.transport.Transport` and a
:class:`~testbed.protocol.FrameDecoder`: the simpy side calls :meth:`LinkEndpoint.poll`
(non-blocking) and gets frame events, or :meth:`LinkEndpoint.deliver` to have each frame handed
to a callback as it is decoded, and the software's own latency (port read returned → frame
handed over, [ns] from :func:`time.perf_counter_ns`) is recorded per frame. It runs on the
caller's thread; only the transport's inbox is shared with its reader thread.

Packet boundaries: the decoder gives up a mis-framed candidate (a corrupted length byte
claiming more bytes than came) at the end of each received packet
(:attr:`~testbed.hil.transport.Received.end`), as the simulated modem's receiver does at the end
of each transmission, so the intact frames behind it are not held for the bytes its false
length claims. Where a packet ends is the adapter's and the transport's to say
(:mod:`testbed.hil.transport`).
"""

from __future__ import annotations

import queue
import time
from collections import deque
from collections.abc import Callable

from testbed.protocol import Frame, FrameDecoder, FrameEvent

from .transport import Received, Transport

__all__ = ["LinkEndpoint"]


class LinkEndpoint:
    """A transport plus a frame decoder: what a node polls for frames.

    Args:
        transport: where bytes come from and frames go.
        decoder: the frame decoder (default: WAFrame settings).
        max_latency_samples: latency samples kept (the newest) [frames].

    The decoder gives up a candidate still incomplete at the end of each received packet
    (:attr:`Received.end`; module docstring: packet boundaries).

    Attributes:
        latencies_ns: per delivered frame, port read returned → frame handed over [ns]
            (for a frame freed by a packet's end, from when that end was seen).
        frames_in: frames decoded [frames].
        corrupt_frames: frame candidates the decoder rejected (bad CRC, oversize, truncated).
    """

    def __init__(
        self,
        transport: Transport,
        decoder: FrameDecoder | None = None,
        *,
        max_latency_samples: int = 100_000,
    ) -> None:
        self.transport = transport
        self.decoder = decoder if decoder is not None else FrameDecoder()
        self.latencies_ns: deque[int] = deque(maxlen=max_latency_samples)
        self.frames_in = 0
        self.corrupt_frames = 0

    def send(self, frame: bytes) -> bool:
        """Queue one encoded frame for the port (non-blocking); False if it was dropped."""
        return self.transport.send(frame)

    def poll(self) -> list[FrameEvent]:
        """Frame events from everything received so far; never blocks."""
        events: list[FrameEvent] = []
        while True:
            try:
                received = self.transport.inbox.get_nowait()
            except queue.Empty:
                return events
            self._decode(received, events)

    def wait(self, timeout_s: float) -> list[FrameEvent]:
        """Block until at least one frame event is decoded or ``timeout_s`` passes.

        For tests and command-line tools; nodes use :meth:`poll`.

        Returns:
            The events decoded (empty on timeout).
        """
        deadline = time.monotonic() + timeout_s
        events: list[FrameEvent] = []
        while not events:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                break
            try:
                received = self.transport.inbox.get(timeout=remaining)
            except queue.Empty:
                break
            self._decode(received, events)
        events.extend(self.poll())
        return events

    def deliver(self, handler: Callable[[Frame], None]) -> int:
        """Decode everything received so far and hand each frame to ``handler`` at once; never
        blocks. The latency is stamped just before each hand-over.

        Returns:
            The number of frames handed over.
        """
        inbox = self.transport.inbox
        handed = 0
        while True:
            try:
                received = inbox.get_nowait()
            except queue.Empty:
                return handed
            for event in self._events(received):
                if isinstance(event, Frame):
                    self.frames_in += 1
                    self.latencies_ns.append(time.perf_counter_ns() - received.read_ns)
                    handed += 1
                    handler(event)

    def _events(self, received: Received) -> list[FrameEvent]:
        """Feed one :class:`Received` to the decoder; at the end of a packet give up a candidate
        still incomplete (module docstring: packet boundaries). Counts corrupt candidates."""
        decoder = self.decoder
        events = decoder.feed_packet(received.data, packet_end=received.end)
        self.corrupt_frames += sum(not isinstance(event, Frame) for event in events)
        return events

    def _decode(self, received: Received, events: list[FrameEvent]) -> None:
        new = self._events(received)
        if new:
            now_ns = time.perf_counter_ns()
            frames = sum(isinstance(event, Frame) for event in new)
            self.frames_in += frames
            self.latencies_ns.extend(now_ns - received.read_ns for _ in range(frames))
            events.extend(new)

    def close(self) -> None:
        """Close the transport."""
        self.transport.close()
