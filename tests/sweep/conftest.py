"""Fixtures of the sweep tests."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

TWO_POINT_SWEEP = """\
schema = 1
id = "{sweep_id}"
description = "2 BER values x 1 seed"
scenario = "s100-teleop-v1"
seeds = 1
metrics = ["link.uplink.per"]

[set]
duration_s = 6.0
"metrics.settle_s" = 1.0

[grid]
"link.ber" = [0.0, 1e-4]
"""


@pytest.fixture
def two_point_sweep(tmp_path: Path) -> Callable[[str], Path]:
    """Writes ``tmp_path/<name>.toml``: a sweep of id ``<name>-v1`` over BER 0 and 1e-4, one
    seed each, 6-s runs of ``s100-teleop-v1`` (settle 1 s) recording the uplink PER: two short
    runs, for tests of what happens around them (a Dask cluster's start and close). Returns
    its path."""

    def write(name: str) -> Path:
        path = tmp_path / f"{name}.toml"
        path.write_text(TWO_POINT_SWEEP.format(sweep_id=f"{name}-v1"), encoding="utf-8")
        return path

    return write
