"""Protocol throughput: 60-B reply frames (WAFrame, 40-B image chunk) encoded and decoded.

Two figures, both in frames per second on one core:

* ``frames_per_s``: ``encode_frame`` of a 54-B reply payload, then ``FrameDecoder.feed`` of that
  frame, one frame per feed (how the link delivers them). Target ≥ 200,000 frames/s.
* ``messages_per_s``: the whole path, ``VehicleMessage.encode`` → ``encode_frame`` → ``feed`` →
  ``decode_vehicle_message``.

For scale: the S100 link carries about 4 such frames per second. Run:

    .venv/bin/python -m pytest benchmarks/test_protocol_bench.py -m benchmark --benchmark-enable
"""

from __future__ import annotations

import numpy as np
import pytest

from testbed.protocol import (
    DEFAULT_CHUNK_SIZE,
    Frame,
    FrameDecoder,
    Mode,
    VehicleMessage,
    VehicleState,
    decode_vehicle_message,
    encode_frame,
)

FRAMES_PER_ROUND = 2000


def replies(seed: int, count: int) -> list[VehicleMessage]:
    """Replies with random states and 40-B chunks."""
    rng = np.random.default_rng(seed)
    messages = []
    for k in range(count):
        flags = [bool(b) for b in rng.integers(0, 2, size=5)]
        pose = rng.uniform(-50.0, 50.0, size=6).tolist()
        state = VehicleState(*flags, Mode(k % 5), *pose)
        chunk = rng.bytes(DEFAULT_CHUNK_SIZE)
        messages.append(
            VehicleMessage(k % 64 == 0, k % 64 == 63, state, True, False, k % 64, chunk)
        )
    return messages


def report(benchmark: pytest.FixtureDef, key: str, label: str) -> float:  # type: ignore[type-arg]
    per_s = FRAMES_PER_ROUND / benchmark.stats.stats.median
    benchmark.extra_info[key] = per_s
    benchmark.extra_info["frame_bytes"] = 60
    print(f"\n{label}: {per_s:,.0f} frames/s ({1e6 / per_s:.2f} µs per 60-B frame)")
    return per_s


@pytest.mark.benchmark
def test_frame_encode_and_decode(benchmark: pytest.FixtureDef) -> None:  # type: ignore[type-arg]
    payloads = [m.encode() for m in replies(seed=20240521, count=FRAMES_PER_ROUND)]
    assert {len(encode_frame(p)) for p in payloads} == {60}
    decoder = FrameDecoder()

    def round_trip() -> list[Frame]:
        out: list[Frame] = []
        for payload in payloads:
            out += decoder.feed(encode_frame(payload))  # type: ignore[arg-type]  # only Frames here
        return out

    decoded = benchmark.pedantic(round_trip, rounds=30, warmup_rounds=2)
    assert [f.payload for f in decoded] == payloads
    assert decoder.corrupt == 0 and decoder.garbage_bytes == 0
    report(benchmark, "frames_per_s", "encode_frame + FrameDecoder.feed")


@pytest.mark.benchmark
def test_reply_message_full_path(benchmark: pytest.FixtureDef) -> None:  # type: ignore[type-arg]
    messages = replies(seed=20240522, count=FRAMES_PER_ROUND)
    decoder = FrameDecoder()

    def round_trip() -> list[object]:
        out: list[object] = []
        for message in messages:
            for event in decoder.feed(encode_frame(message.encode())):
                out.append(decode_vehicle_message(event.payload))  # type: ignore[union-attr]  # clean
        return out

    decoded = benchmark.pedantic(round_trip, rounds=20, warmup_rounds=1)
    assert [m.state.quantized() for m in messages] == [m.state for m in decoded]  # type: ignore[attr-defined]  # all parse
    report(benchmark, "messages_per_s", "VehicleMessage encode → frame → feed → decode")
