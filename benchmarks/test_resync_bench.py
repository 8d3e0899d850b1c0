"""Resynchronisation after a corrupted length byte: measured loss of intact frames vs derived.

200,000 trials per case (preamble 3 and 1; 7-B order and 54-B reply payloads, i.e. 13-B / 60-B
frames with the WAFrame preamble), back-to-back frames on one byte stream, no flush until the
end. Each trial replaces the length byte of one frame by a random other value. Prints, per
case, the trials, the trials that lost at least one *other* intact frame (with a 95 %
Clopper–Pearson interval), the intact frames lost, the false frames delivered, and the rates
derived in ``tests/protocol/test_resync.py`` (:func:`derived_rates`), side by side. Run:

    .venv/bin/python -m pytest benchmarks/test_resync_bench.py -m benchmark -s
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from tests.protocol.test_resync import (
    CASES,
    assert_invariants,
    derived_rates,
    frame_len,
    run_trials,
)

TRIALS = 200_000


def clopper_pearson(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Exact two-sided binomial interval for k successes in n trials."""
    a = (1 - level) / 2
    lo = 0.0 if k == 0 else float(stats.beta.ppf(a, k, n - k + 1))
    hi = 1.0 if k == n else float(stats.beta.ppf(1 - a, k + 1, n - k))
    return lo, hi


@pytest.mark.benchmark
@pytest.mark.parametrize(
    ("preamble_len", "payload_len"), CASES, ids=[f"preamble{p}-payload{n}" for p, n in CASES]
)
def test_resync_loss_rate(preamble_len: int, payload_len: int) -> None:
    rng = np.random.default_rng([20261201, preamble_len, payload_len])
    tally = run_trials(rng, TRIALS, preamble_len, payload_len)
    assert_invariants(tally)
    d = derived_rates(preamble_len, payload_len)
    lo, hi = clopper_pearson(tally.events, tally.trials)
    flen = frame_len(preamble_len, payload_len)
    print(
        f"\npreamble {preamble_len}, {flen}-B frames: {tally.trials:,} corrupted length bytes"
        f"\n  trials losing another intact frame: {tally.events}"
        f" -> {tally.events / tally.trials:.2e} per error, 95 % CI [{lo:.2e}, {hi:.2e}];"
        f" derived {d.p_event:.2e}"
        f"\n  intact frames lost (besides the corrupted one): {tally.lost}"
        f" -> {tally.lost / tally.trials:.2e} per error; derived {d.lost_per_error:.2e}"
        f"\n  false frames delivered: {tally.false_frames}"
        f" -> {tally.false_frames / tally.trials:.2e} per error;"
        f" derived {d.false_per_error:.2e} (candidate at frame start only)"
    )
    assert stats.binom.sf(tally.events - 1, tally.trials, d.p_event) > 1e-6
    assert stats.binom.cdf(tally.events, tally.trials, d.p_event) > 1e-6
