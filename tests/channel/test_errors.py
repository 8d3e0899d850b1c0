"""testbed.channel.errors: error statistics against the closed forms of the models.

Independent errors: a frame of L bytes is clean with probability (1 - p)^(8L).
Gilbert–Elliott (per-bit chain, good → bad w.p. a, bad → good w.p. b): the stationary bad
fraction is a / (a + b), a bad sojourn lasts 1/b bits on average, and with ber_good = 0 and
ber_bad = 1 a frame of n bits is clean iff all its bits are good: (b / (a + b))·(1 - a)^(n-1).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import simpy
from scipy import stats

from testbed.channel.config import GilbertElliott, LinkConfig, load_link_config
from testbed.channel.errors import (
    BitErrors,
    GilbertElliottChain,
    TimedGilbertElliottChain,
    flip_bits,
)
from testbed.channel.medium import Medium
from testbed.channel.probe import run_probe
from testbed.config import FieldError

OFF = GilbertElliott()
S100_CLEAN = load_link_config("s100", ["ber=0"])


def per_interval(p_bit: float, n_bytes: int, frames: int) -> tuple[float, float]:
    """99.9 % binomial interval for the number of errored frames, as fractions."""
    per = 1.0 - (1.0 - p_bit) ** (8 * n_bytes)
    lo, hi = stats.binom.interval(0.999, frames, per)
    return lo / frames, hi / frames


def bits_of(data: bytes) -> np.ndarray:
    return np.unpackbits(np.frombuffer(data, dtype=np.uint8))


def test_flip_bits_is_msb_first_and_both_paths_agree() -> None:
    assert flip_bits(bytes(2), [0]) == b"\x80\x00"
    assert flip_bits(bytes(2), [7, 8]) == b"\x01\x80"
    rng = np.random.default_rng(0)
    data = rng.bytes(64)
    positions = sorted(rng.choice(512, 100, replace=False).tolist())  # numpy path (> 32)
    by_numpy = flip_bits(data, positions)
    by_loop = data
    for pos in positions:  # one at a time: the Python path
        by_loop = flip_bits(by_loop, [pos])
    assert by_numpy == by_loop
    assert np.flatnonzero(bits_of(by_numpy) ^ bits_of(data)).tolist() == positions


@pytest.mark.parametrize("ber", [1e-4, 1e-3, 1e-2])
@pytest.mark.parametrize("n_bytes", [13, 60, 255])
def test_per_within_binomial_interval(ber: float, n_bytes: int) -> None:
    frames = 20_000
    errors = BitErrors(OFF, np.random.default_rng(42))
    data = bytes(n_bytes)
    flipped = [errors.corrupt(data, ber) for _ in range(frames)]
    errored = sum(1 for _, n in flipped if n)
    lo, hi = per_interval(ber, n_bytes, frames)
    assert lo <= errored / frames <= hi
    # The count is the true number of flipped bits, and its mean is 8·L·p.
    assert all(int(bits_of(d).sum()) == n for d, n in flipped[:200])
    mean_flips = sum(n for _, n in flipped) / frames
    expected = 8 * n_bytes * ber
    assert mean_flips == pytest.approx(expected, abs=5 * np.sqrt(expected / frames))


def test_changing_probability_between_frames_keeps_each_exact() -> None:
    """The countdown to the next error is redrawn when p changes (memoryless): no carry-over."""
    errors = BitErrors(OFF, np.random.default_rng(3))
    frames = 15_000
    counts = {1e-4: 0, 3e-3: 0}
    for k in range(2 * frames):
        p = 1e-4 if k % 2 else 3e-3
        counts[p] += errors.corrupt(bytes(40), p)[1] > 0
    for p, errored in counts.items():
        lo, hi = per_interval(p, 40, frames)
        assert lo <= errored / frames <= hi


def test_extreme_probabilities() -> None:
    errors = BitErrors(OFF, np.random.default_rng(0))
    assert errors.corrupt(b"\x0f\xf0", 1.0) == (b"\xf0\x0f", 16)
    assert errors.corrupt(b"\x0f\xf0", 0.0) == (b"\x0f\xf0", 0)


def _ge_stream(model: GilbertElliott, n_bytes: int, frames: int, seed: int) -> np.ndarray:
    errors = BitErrors(model, np.random.default_rng(seed))
    data = bytes(n_bytes)
    return np.concatenate([bits_of(errors.corrupt(data, 0.0)[0]) for _ in range(frames)])


def _runs_of_ones(mask: np.ndarray) -> np.ndarray:
    edges = np.diff(np.concatenate(([0], mask.astype(np.int8), [0])))
    return np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)


def test_gilbert_elliott_burst_length_and_stationary_ber() -> None:
    """ber_good = 0, ber_bad = 1: error runs are exactly the bad sojourns (mean 1/b bits).

    Frames are 128 bits and bursts average 50 bits, so many bursts span frame boundaries: the
    run lengths measured over the concatenated stream only match 1/b if the chain's state
    carries over from one frame to the next.
    """
    model = GilbertElliott(p_good_to_bad=0.002, p_bad_to_good=0.02, ber_good=0.0, ber_bad=1.0)
    mask = _ge_stream(model, 16, 20_000, seed=5)
    runs = _runs_of_ones(mask)
    assert len(runs) > 3000
    assert runs.mean() == pytest.approx(1 / 0.02, rel=0.05)
    assert mask.mean() == pytest.approx(model.stationary_bad, rel=0.08)
    # Sojourns are geometric: P(run = 1) = b.
    assert np.mean(runs == 1) == pytest.approx(0.02, abs=0.008)
    frames = mask.reshape(-1, 128)
    clean = 1.0 - frames.any(axis=1).mean()
    expected_clean = (1 - model.stationary_bad) * (1 - 0.002) ** 127
    assert clean == pytest.approx(expected_clean, abs=0.02)
    # Bursty: far fewer errored frames than independent errors at the same mean BER.
    assert 1 - clean < 0.5 * (1 - (1 - model.mean_ber) ** 128)


def test_gilbert_elliott_mean_ber_with_noisy_states() -> None:
    model = GilbertElliott(p_good_to_bad=0.001, p_bad_to_good=0.01, ber_good=1e-3, ber_bad=0.3)
    mask = _ge_stream(model, 32, 10_000, seed=9)
    assert mask.mean() == pytest.approx(model.mean_ber, rel=0.08)


def test_chain_starts_in_the_stationary_distribution() -> None:
    model = GilbertElliott(p_good_to_bad=0.01, p_bad_to_good=0.03)  # bad 25 % of the time
    starts = [GilbertElliottChain(model, np.random.default_rng(s)).bad for s in range(4000)]
    lo, hi = stats.binom.interval(0.999, 4000, 0.25)
    assert lo <= sum(starts) <= hi


def _medium_per(config: LinkConfig, distance_m: float, n_bytes: int, frames: int) -> float:
    env = simpy.Environment()
    medium = Medium(env, config, np.random.default_rng(11))
    a = medium.attach("a")
    b = medium.attach("b", lambda: (distance_m, 0.0, 0.0))
    data = bytes(n_bytes)

    def send(_: simpy.Event) -> None:
        a.send(data)

    for k in range(frames):
        env.timeout(k * 1.0).callbacks.append(send)
    env.run()
    got = b.drain()
    assert len(got) == frames
    return sum(d.bit_errors > 0 for d in got) / frames


def test_range_dependent_errors_or_with_the_base_ber() -> None:
    config = LinkConfig(bitrate_bps=1e4, ber=1e-4, ber_per_m=2e-5)
    p = 1.0 - (1.0 - 1e-4) * (1.0 - 2e-5 * 10.0)
    lo, hi = per_interval(p, 50, 8000)
    assert lo <= _medium_per(config, 10.0, 50, 8000) <= hi
    lo0, hi0 = per_interval(1e-4, 50, 8000)
    assert lo0 <= _medium_per(config, 0.0, 50, 8000) <= hi0


def test_burst_model_ors_with_independent_errors() -> None:
    # A chain that never leaves the good state is independent noise q: p_total = 1-(1-p)(1-q).
    config = LinkConfig(bitrate_bps=1e4, ber=2e-4, burst=GilbertElliott(ber_good=3e-4))
    lo, hi = per_interval(1.0 - (1.0 - 2e-4) * (1.0 - 3e-4), 50, 8000)
    assert lo <= _medium_per(config, 0.0, 50, 8000) <= hi


# --- the chain in time (mean sojourns in seconds) ------------------------------------------

TIMED = GilbertElliott(ber_good=0.0, ber_bad=1.0, mean_good_s=20.0, mean_bad_s=5.0)


@pytest.mark.parametrize("interval_s", [0.1, 1.0, 7.0])
def test_a_chain_in_time_is_the_two_state_markov_process_whatever_the_traffic(
    interval_s: float,
) -> None:
    """Copies received every ``interval_s``: the fraction in the bad state is π_b =
    mean_bad / (mean_good + mean_bad) = 0.2, and a copy after a bad one is bad with
    π_b + (1 − π_b)·exp(−(1/mean_good + 1/mean_bad)·Δt) (the continuous-time chain's
    transition law) — at every rate of traffic, unlike the per-bit chain."""
    chain = TimedGilbertElliottChain(TIMED, np.random.default_rng(11))
    n = 100_000
    bad = np.array([chain.state_at(k * interval_s) for k in range(n)])
    pi_bad = TIMED.stationary_bad
    assert pi_bad == 0.2
    # successive samples are correlated: the standard error grows by √((1+ρ)/(1−ρ))
    rho = np.exp(-(1 / 20.0 + 1 / 5.0) * interval_s)
    se = np.sqrt(pi_bad * (1 - pi_bad) / n * (1 + rho) / (1 - rho))
    assert abs(bad.mean() - pi_bad) < 4 * se
    after_bad = bad[1:][bad[:-1]]
    stay = pi_bad + (1 - pi_bad) * rho
    assert abs(after_bad.mean() - stay) < 4 * np.sqrt(stay * (1 - stay) / after_bad.size) + 0.01


def test_a_probe_of_a_chain_in_time_loses_frames_at_its_bad_fraction_at_any_rate() -> None:
    """ber_bad 1: a frame is lost exactly when it arrives in the bad state, so the PER is π_b
    = 0.2 one frame a second or ten (the per-bit chain's PER would change with the rate)."""
    config = dataclasses.replace(S100_CLEAN, burst=TIMED)
    for interval_s, frames in ((1.0, 40_000), (0.1, 40_000)):
        result = run_probe(config, frames=frames, frame_bytes=20, interval_s=interval_s, seed=5)
        rho = np.exp(-(1 / 20.0 + 1 / 5.0) * interval_s)
        se = np.sqrt(0.2 * 0.8 / frames * (1 + rho) / (1 - rho))
        assert abs(result.per - 0.2) < 4 * se, (interval_s, result.per)


@pytest.mark.parametrize(
    ("burst", "key"),
    [
        ({"mean_good_s": 10.0}, "mean_bad_s"),
        ({"mean_bad_s": 10.0}, "mean_good_s"),
        ({"mean_good_s": 10.0, "mean_bad_s": 1.0, "p_good_to_bad": 1e-4}, "p_good_to_bad"),
        ({"mean_good_s": -1.0, "mean_bad_s": 1.0}, "mean_good_s"),
    ],
)
def test_a_chain_in_time_needs_both_means_and_no_per_bit_probabilities(
    burst: dict[str, float], key: str
) -> None:
    with pytest.raises(FieldError) as info:
        GilbertElliott(**burst)
    assert info.value.key == key
