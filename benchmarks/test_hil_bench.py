"""Software latency of the HIL receive path: port read returned → frame handed to the node.

A writer pushes WAFrame frames into ``loop://``; the transport's reader thread reads them,
runs the adapter, queues the payload stream; the consumer decodes and hands the frame over.
Reported: frames per second through the whole path, and median / p95 latency (issue target:
median under 1 ms). Fixed payloads, no randomness.

    .venv/bin/python -m pytest benchmarks/test_hil_bench.py -m benchmark --benchmark-enable -s
"""

from __future__ import annotations

import statistics
from typing import Any

import pytest

from testbed.hil import LinkEndpoint, M64Adapter, RawAdapter, S100Adapter, SerialTransport, crc8
from testbed.hil.adapters import Adapter
from testbed.protocol import Frame, encode_frame

pytestmark = pytest.mark.benchmark
FRAMES = 300
PAYLOAD = bytes(range(60))  # the paper's 60 B state + image-chunk reply


def _run(endpoint: LinkEndpoint, wire: bytes) -> int:
    port = endpoint.transport._port
    got = 0
    for _ in range(FRAMES):
        port.write(wire)  # the bytes the peer's modem would deliver
        events = endpoint.wait(5.0)  # returns once the frame is decoded
        got += sum(isinstance(e, Frame) for e in events)
    return got


def _wire(name: str, frame: bytes) -> bytes:
    if name == "s100":
        return b"+++STATUS\r\n" + frame + b"\r\n"
    if name == "m64":
        out = b""
        for i in range(0, len(frame), 8):
            s = b"wrp,8," + frame[i : i + 8].ljust(8, b"\0")
            out += s + b"*%02x\n" % crc8(s)
        return out
    return frame


@pytest.mark.parametrize("name", ["raw", "s100", "m64"])
def test_receive_latency(benchmark: Any, name: str) -> None:
    adapters: dict[str, Adapter] = {
        "raw": RawAdapter(),
        "s100": S100Adapter(),
        "m64": M64Adapter(),
    }
    endpoint = LinkEndpoint(SerialTransport("loop://", adapters[name], baudrate=115200))
    wire = _wire(name, encode_frame(PAYLOAD))
    try:
        got = benchmark.pedantic(_run, args=(endpoint, wire), rounds=3, iterations=1)
        assert got == FRAMES
        lat_us = sorted(ns / 1e3 for ns in endpoint.latencies_ns)
        median = statistics.median(lat_us)
        p95 = lat_us[int(0.95 * (len(lat_us) - 1))]
        fps = FRAMES / benchmark.stats.stats.mean
        benchmark.extra_info.update(
            {"median_latency_us": median, "p95_latency_us": p95, "frames_per_s": fps}
        )
        print(f"\n{name}: median {median:.0f} µs, p95 {p95:.0f} µs, {fps:.0f} frames/s")
        assert median < 1000.0
    finally:
        endpoint.close()
