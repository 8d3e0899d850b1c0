"""Decode time of the adversarial 11-byte stream (a header claiming 1024 x 1024 with a full-image
ROI and no data) next to a real 160 x 120 stream at the link's budget. Run:

    .venv/bin/python -m pytest benchmarks/test_imaging_decode_bench.py -m benchmark \
        --benchmark-enable -s
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from testbed.imaging import Header, decode, encode, pool_scene

STREAMS = {
    "adversarial-11B-1024x1024-roi": Header(1024, 1024, 7, 31, True, (0, 0, 1023, 1023), 15).pack(),
    "real-160x120-2400B": encode(pool_scene(160, 120, np.random.default_rng(7)), 2400),
}


@pytest.mark.benchmark
@pytest.mark.parametrize("name", list(STREAMS))
def test_decode_adversarial_vs_real(benchmark: Any, name: str) -> None:
    stream = STREAMS[name]
    out = benchmark(decode, stream)
    assert out.size > 0
    mean_s = benchmark.stats.stats.mean
    benchmark.extra_info["bytes"] = len(stream)
    benchmark.extra_info["ms_per_decode"] = 1e3 * mean_s
    print(f"\n{name:32s} {len(stream):5d} B  {out.shape[1]}x{out.shape[0]}  {1e3 * mean_s:8.3f} ms")
