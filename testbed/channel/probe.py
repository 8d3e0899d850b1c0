"""One-way link probe behind ``testbed link``: frames one way, statistics out.

A sender hands ``frames`` frames of ``frame_bytes`` bytes to its modem, one every ``interval_s``;
each frame is ``encode_frame`` of a payload starting with a 4-byte big-endian sequence number, so
the receiver, which runs :class:`~testbed.protocol.FrameDecoder` on every delivered copy, can
match what it decodes to what was sent. It decodes exactly as the run's nodes do
(:func:`~testbed.channel.delivery.decode_delivery`: the decoder is flushed at the end of each
transmission), so a frame behind a corrupted length byte is not held for later frames. Latency
is measured from handing the frame to the link to the decoder yielding it.

Outcome of each frame (they add up to ``frames_sent``):

- *delivered*: decoded with the exact payload that was sent;
- *dropped*: tail-dropped by the sender's FIFO;
- *collided*: at least one of its transmissions was destroyed by a collision;
- *out of range*: the receiver was beyond ``max_range_m``;
- *corrupted*: everything else that reached the receiver but was not decoded (bit errors; or a
  clean frame lost behind a corrupted one, exactly as a real decoder would lose it).

PER is the frame error rate on the air, 1 − delivered / transmitted (the frames sent less those
dropped), as a run's metrics define it; frames the sender's FIFO dropped are their own rate,
``drop_rate`` = dropped / sent. Goodput counts payload bits of delivered frames over the time
the probe offered them (``frames`` × ``interval_s``), or until the last delivery if the link
took longer, so on a clean link it equals the offered payload rate (dividing by the time to the
last delivery alone made a short probe's goodput exceed what it offered).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import simpy

from testbed.channel.config import LinkConfig
from testbed.channel.delivery import Delivery, decode_delivery
from testbed.channel.mac import run_periodic_sender
from testbed.channel.medium import Medium
from testbed.channel.model import LinkModel, model_name
from testbed.channel.trace import EventKind, Trace
from testbed.protocol import MAX_PAYLOAD, Frame, FrameDecoder, encode_frame, frame_overhead

__all__ = [
    "MAX_FRAMES",
    "SEQ_BYTES",
    "LatencyStats",
    "ProbeResult",
    "format_report",
    "frame_size_limits",
    "run_probe",
]

SEQ_BYTES = 4
"""Sequence number at the start of each probe payload (u32, big-endian)."""

MAX_FRAMES = 1_000_000
"""Most frames one probe sends: a PER resolution of 1e-6, in about 20 s of wall time (≈ 50 k
frames/s) and ≈ 100 MB for the per-frame records; far more would run for hours or not fit
in memory (the per-frame tables grow with it)."""


def frame_size_limits() -> tuple[int, int]:
    """Smallest and largest probe frame [B]: frame overhead + sequence number, and + 255 B."""
    overhead = frame_overhead()
    return overhead + SEQ_BYTES, overhead + MAX_PAYLOAD


@dataclass(frozen=True, slots=True)
class LatencyStats:
    """Latency of delivered frames [s]; all None when nothing was delivered."""

    mean: float | None
    p50: float | None
    p95: float | None
    max: float | None

    @classmethod
    def of(cls, latencies_s: list[float]) -> LatencyStats:
        """Statistics of a list of latencies [s] (percentiles linearly interpolated)."""
        if not latencies_s:
            return cls(None, None, None, None)
        arr = np.asarray(latencies_s, dtype=float)
        p50, p95 = np.percentile(arr, [50.0, 95.0])
        return cls(float(arr.mean()), float(p50), float(p95), float(arr.max()))


@dataclass(frozen=True, slots=True)
class ProbeResult:
    """What ``testbed link`` reports. Frame counts add up to ``frames_sent``.

    ``wall_s`` is the wall-clock time of the simulation itself (running the environment and the
    receiver's decoder), without building the link or computing statistics; ``rtf`` is
    ``sim_s / wall_s``.
    """

    link: str
    frame_bytes: int
    interval_s: float
    distance_m: float
    seed: int
    frames_sent: int
    frames_delivered: int
    frames_corrupted: int
    frames_collided: int
    frames_dropped: int
    frames_out_of_range: int
    per: float
    drop_rate: float
    goodput_bps: float
    latency_s: LatencyStats
    sim_s: float
    wall_s: float
    rtf: float
    link_model: str = ""
    """The class of a link model of the user's own (``module.Name``), or "" for the preset's."""

    def to_json_dict(self) -> dict[str, Any]:
        """The ``--json`` object (the documented keys first; keys are only ever added)."""
        return {
            "frames_sent": self.frames_sent,
            "frames_delivered": self.frames_delivered,
            "frames_corrupted": self.frames_corrupted,
            "frames_collided": self.frames_collided,
            "frames_dropped": self.frames_dropped,
            "per": self.per,
            "drop_rate": self.drop_rate,
            "goodput_bps": self.goodput_bps,
            "latency_s": {
                "mean": self.latency_s.mean,
                "p50": self.latency_s.p50,
                "p95": self.latency_s.p95,
                "max": self.latency_s.max,
            },
            "sim_s": self.sim_s,
            "wall_s": self.wall_s,
            "rtf": self.rtf,
            "frames_out_of_range": self.frames_out_of_range,
            "link": self.link,
            "frame_bytes": self.frame_bytes,
            "interval_s": self.interval_s,
            "distance_m": self.distance_m,
            "seed": self.seed,
            "link_model": self.link_model or None,
        }


def _filler(n: int) -> bytes:
    """Deterministic payload padding (not all zeros, so it looks like data on the wire)."""
    return bytes((i * 37 + 11) & 0xFF for i in range(n))


def run_probe(
    config: LinkConfig,
    *,
    frames: int = 1000,
    frame_bytes: int = 60,
    interval_s: float = 1.0,
    seed: int = 0,
    distance_m: float = 0.0,
    link_model: LinkModel | None = None,
) -> ProbeResult:
    """Send ``frames`` frames one way over a two-node link and measure what arrives.

    Args:
        config: the link.
        frames: number of frames, 1..:data:`MAX_FRAMES`.
        frame_bytes: total frame size incl. preamble, length, sequence number and CRC [B],
            within :func:`frame_size_limits`.
        interval_s: time between frames handed to the sender [s], > 0.
        seed: seed of the run's random generator, ≥ 0 (same seed ⇒ same result).
        distance_m: sender–receiver distance [m], ≥ 0.
        link_model: a link model of your own (:mod:`~testbed.channel.model`); None: the
            preset's.

    Returns:
        The counts, PER, goodput, latency statistics and timing of the run.

    Raises:
        ValueError: an argument out of range (local misuse; the CLI checks before calling).
    """
    lo, hi = frame_size_limits()
    if not 1 <= frames <= MAX_FRAMES:
        raise ValueError(f"frames must be in [1, {MAX_FRAMES}], got {frames}")
    if not lo <= frame_bytes <= hi:
        raise ValueError(f"frame_bytes must be in [{lo}, {hi}], got {frame_bytes}")
    if not (interval_s > 0.0 and math.isfinite(interval_s)):
        raise ValueError(f"interval_s must be > 0, got {interval_s}")
    if not (distance_m >= 0.0 and math.isfinite(distance_m)):
        raise ValueError(f"distance_m must be ≥ 0, got {distance_m}")
    if seed < 0:
        raise ValueError(f"seed must be ≥ 0, got {seed}")

    env = simpy.Environment()
    losses = Trace(kinds=(EventKind.COLLIDE, EventKind.DEAF, EventKind.OUT_OF_RANGE))
    medium = Medium(env, config, np.random.default_rng(seed), trace=losses, model=link_model)
    sender = medium.attach("sender")
    far = (float(distance_m), 0.0, 0.0)
    receiver = medium.attach("receiver", None if distance_m == 0.0 else lambda: far)

    filler = _filler(frame_bytes - frame_overhead() - SEQ_BYTES)
    sent_at_s: list[float] = []
    received = bytearray(frames)
    latencies_s: list[float] = []
    decoder = FrameDecoder()

    def make_frame() -> bytes:
        seq = len(sent_at_s)
        sent_at_s.append(env.now)
        return encode_frame(seq.to_bytes(SEQ_BYTES, "big") + filler)

    def accept(events: list[Any], now: float) -> None:
        for item in events:
            if type(item) is Frame:
                payload = item.payload
                seq = int.from_bytes(payload[:SEQ_BYTES], "big")
                if seq < frames and not received[seq] and payload[SEQ_BYTES:] == filler:
                    received[seq] = 1
                    latencies_s.append(now - sent_at_s[seq])

    def on_receive(delivery: Delivery) -> None:
        accept(decode_delivery(decoder, delivery), delivery.t_delivered_s)

    receiver.on_receive = on_receive
    env.process(
        run_periodic_sender(env, lambda: sender.send(make_frame()), interval_s, count=frames)
    )
    wall_start = time.perf_counter()
    env.run()
    sim_s = float(env.now)
    wall_s = time.perf_counter() - wall_start

    delivered = len(latencies_s)
    dropped = sender.counters.frames_dropped
    lost = (*losses.of_kind(EventKind.COLLIDE), *losses.of_kind(EventKind.DEAF))
    collided = len({e.frame_id for e in lost})
    out_of_range = len({e.frame_id for e in losses.of_kind(EventKind.OUT_OF_RANGE)})
    corrupted = frames - delivered - dropped - collided - out_of_range
    payload_bits = 8 * (frame_bytes - frame_overhead())
    latency = LatencyStats.of(latencies_s)
    return ProbeResult(
        link=config.name,
        frame_bytes=frame_bytes,
        interval_s=interval_s,
        distance_m=distance_m,
        seed=seed,
        frames_sent=frames,
        frames_delivered=delivered,
        frames_corrupted=corrupted,
        frames_collided=collided,
        frames_dropped=dropped,
        frames_out_of_range=out_of_range,
        per=1.0 - delivered / (frames - dropped) if frames > dropped else math.nan,
        drop_rate=dropped / frames,
        goodput_bps=delivered * payload_bits / max(frames * interval_s, sim_s),
        latency_s=latency,
        sim_s=sim_s,
        wall_s=wall_s,
        rtf=sim_s / wall_s,
        link_model="" if link_model is None else model_name(link_model),
    )


def _percent(fraction: float) -> str:
    return "n/a" if math.isnan(fraction) else f"{fraction * 100:.3f} %"


def _ms(value: float | None) -> str:
    return "n/a" if value is None else f"{value * 1e3:.1f} ms"  # n/a, as every summary says


def format_report(result: ProbeResult) -> str:
    """Human-readable multi-line summary of a probe run."""
    lat = result.latency_s
    return "\n".join(
        [
            f"link {result.link}: {result.frames_sent} frames of {result.frame_bytes} B, "
            f"one every {result.interval_s:g} s, {result.distance_m:g} m, seed {result.seed}",
            f"  sent {result.frames_sent}  delivered {result.frames_delivered}  "
            f"corrupted {result.frames_corrupted}  collided {result.frames_collided}  "
            f"dropped {result.frames_dropped}  out of range {result.frames_out_of_range}",
            f"  PER {_percent(result.per)} of {result.frames_sent - result.frames_dropped} "
            f"transmitted  dropped {_percent(result.drop_rate)} of {result.frames_sent} sent  "
            f"goodput {result.goodput_bps:.1f} bit/s",
            f"  latency mean {_ms(lat.mean)}  p50 {_ms(lat.p50)}  p95 {_ms(lat.p95)}  "
            f"max {_ms(lat.max)}",
            f"  simulated {result.sim_s:.1f} s in {result.wall_s:.3f} s "
            f"(real-time factor {result.rtf:,.0f}x)",
        ]
    )
