"""testbed.run.metrics against closed forms on hand-made inputs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from testbed.channel import EventKind, direction_counts
from testbed.report.closed_forms import aoi_periodic_closed_form
from testbed.run.metrics import (
    age_of_information,
    distribution,
    signal_lag_s,
    summary,
)
from testbed.run.runner import run_scenario
from testbed.run.scenario import load_scenario


def test_age_of_periodic_lossless_updates_is_delay_plus_half_period() -> None:
    period, delay = 0.5, 0.12
    updates = [(k * period + delay, k * period) for k in range(2000)]
    aoi = age_of_information(updates, 10.0 + delay, 900.0 + delay)
    assert aoi["mean"] == pytest.approx(delay + period / 2, rel=1e-9)
    assert aoi["p95"] == pytest.approx(delay + 0.95 * period, abs=0.011)


def test_age_of_updates_with_random_losses_follows_the_renewal_formula() -> None:
    rng = np.random.default_rng(3)
    period, delay, q = 0.6, 0.3, 0.7
    kept = rng.random(200_000) < q
    updates = [(k * period + delay, k * period) for k in np.flatnonzero(kept)]
    mean = age_of_information(updates, updates[0][0], updates[-1][0])["mean"]
    expected = aoi_periodic_closed_form(period, q, delay)
    assert mean == pytest.approx(expected, rel=0.01)


def test_age_ignores_stale_updates_and_counts_the_held_one_at_the_start() -> None:
    # held at t0 = 1: sampled 0 -> age 1 at t0, grows to 3 at t = 3 when an update sampled at 2.5
    # arrives (age 0.5), then grows to 1.5 at t1 = 4; a stale update (sampled 0.1) is ignored.
    updates = [(0.5, 0.0), (2.0, -1.0), (3.0, 2.5), (3.5, 0.1)]
    mean = age_of_information(updates, 1.0, 4.0)["mean"]
    area = 0.5 * (3.0**2 - 1.0**2) + 0.5 * (1.5**2 - 0.5**2)
    assert mean == pytest.approx(area / 3.0)


def test_age_is_infinite_when_nothing_was_ever_held() -> None:
    assert age_of_information([], 0.0, 1.0)["mean"] == math.inf


def test_closed_form_rejects_impossible_probability() -> None:
    with pytest.raises(ValueError, match="probability"):
        aoi_periodic_closed_form(1.0, 0.0, 0.1)


def test_signal_lag_recovers_a_known_delay_between_grid_points() -> None:
    t = np.arange(0.0, 120.0, 0.01)
    lag = 0.347
    commanded = np.sin(2 * np.pi * t / 17.0) + 0.5 * np.sin(2 * np.pi * t / 5.3 + 1.0)
    received = np.interp(t - lag, t, commanded, left=0.0)
    assert signal_lag_s(t, commanded, received) == pytest.approx(lag, abs=0.004)


def test_signal_lag_leaves_out_samples_a_failsafe_held_centred() -> None:
    """Slow sticks (29-47 s periods, as the scenarios' pilots) delayed by 0.5 s, with forty
    1.5-s stretches where the vehicle held its sticks centred (a failsafe): the centred
    stretches pull the plain estimate off the delay; marked invalid they take no part, and
    the delay is found again."""
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 120.0, 0.05)
    commanded = 0.4 * np.sin(2 * np.pi * t / 29.0) + 0.15 * np.sin(2 * np.pi * t / 9.0 + 2.0)
    commanded += 0.3 * np.sin(2 * np.pi * t / 47.0 + 1.0)
    lag = 0.5
    received = np.interp(t - lag, t, commanded, left=0.0)
    valid = np.ones(t.size, dtype=bool)
    for start in rng.uniform(0.0, 118.0, 40):
        valid[(t >= start) & (t < start + 1.5)] = False
    held = np.where(valid, received, 0.0)
    assert abs(signal_lag_s(t, commanded, held, 2.0) - lag) > 0.3  # 0.85 s: the bias it had
    # the slow sticks' flat correlation peak: within half a 50-ms sample
    assert signal_lag_s(t, commanded, held, 2.0, valid=valid) == pytest.approx(lag, abs=0.025)
    assert signal_lag_s(t, commanded, received, 2.0, valid=np.ones(t.size, dtype=bool)) == (
        signal_lag_s(t, commanded, received, 2.0)
    )


def test_signal_lag_of_a_staircase_hold_is_about_half_the_hold_plus_delay() -> None:
    """A signal sampled every T and held, after a delay D, lags by D + T/2 on average."""
    t = np.arange(0.0, 200.0, 0.01)
    commanded = np.sin(2 * np.pi * t / 23.0) + 0.3 * np.sin(2 * np.pi * t / 7.0)
    period, delay = 0.6, 0.14
    sample_index = np.floor((t - delay) / period)
    held_times = np.clip(sample_index * period, 0.0, None)
    received = np.interp(held_times, t, commanded)
    assert signal_lag_s(t, commanded, received) == pytest.approx(delay + period / 2, abs=0.02)


def _delayed(t: np.ndarray, lag_s: float) -> tuple[np.ndarray, np.ndarray]:
    """A pilot-like signal and the same signal ``lag_s`` later (exact, not interpolated)."""

    def f(x: np.ndarray) -> np.ndarray:
        return np.sin(2 * np.pi * x / 23.0) + 0.4 * np.sin(2 * np.pi * x / 7.3 + 1.0)

    return f(t), f(t - lag_s)


def test_signal_lag_beyond_the_search_window_is_no_measurement() -> None:
    t = np.arange(0.0, 120.0, 0.05)
    commanded, received = _delayed(t, 5.1)
    assert math.isnan(signal_lag_s(t, commanded, received, max_lag_s=5.0))  # not 5.0
    assert signal_lag_s(t, commanded, received, max_lag_s=10.0) == pytest.approx(5.1, abs=0.005)


def test_signal_lag_leading_the_command_is_no_measurement() -> None:
    t = np.arange(0.0, 120.0, 0.05)
    commanded, received = _delayed(t, -0.5)  # received ahead of the command: no delay
    assert math.isnan(signal_lag_s(t, commanded, received))


@pytest.mark.parametrize("lag", [0.0, 0.004, 0.012, 0.02, 0.03])
def test_signal_lag_below_the_sampling_step_is_interpolated(lag: float) -> None:
    """20-Hz samples (50 ms apart), lags of 0 to 30 ms: the peak at zero or one shift is refined
    by the parabola through its neighbours (one negative shift included), to a few ms."""
    t = np.arange(0.0, 120.0, 0.05)
    commanded, received = _delayed(t, lag)
    assert signal_lag_s(t, commanded, received) == pytest.approx(lag, abs=0.002)


def test_signal_lag_of_a_constant_is_nan() -> None:
    t = np.arange(0.0, 10.0, 0.1)
    assert math.isnan(signal_lag_s(t, np.ones_like(t), np.sin(t)))


def test_summary_and_distribution() -> None:
    s = summary([1.0, 2.0, 3.0, 4.0])
    assert s == {"mean": 2.5, "p50": 2.5, "p95": pytest.approx(3.85), "max": 4.0, "n": 4}
    d = distribution([-2.0, 2.0])
    assert d == {"mean": 0.0, "std": 2.0, "p95": 2.0}
    assert summary([])["n"] == 0


def test_signal_lag_on_an_uneven_grid_uses_real_time() -> None:
    """Frames 8.3 or 12.5 ms apart (2 or 3 steps at 240 Hz): the lag is still in seconds."""
    steps = np.tile([2, 3, 2, 3, 2], 4000)
    t = np.concatenate([[0.0], np.cumsum(steps) / 240.0])
    commanded = np.sin(2 * np.pi * t / 19.0) + 0.4 * np.sin(2 * np.pi * t / 6.1)
    lag = 0.4
    received = np.sin(2 * np.pi * (t - lag) / 19.0) + 0.4 * np.sin(2 * np.pi * (t - lag) / 6.1)
    assert signal_lag_s(t, commanded, received) == pytest.approx(lag, abs=0.005)


def test_frame_outcomes_add_up_when_bit_errors_fall_in_packet_padding() -> None:
    """m64 cuts frames into 8-B packets, the last zero-padded: bit errors that fall only in
    the padding leave the frame whole (the decoder takes it) though the trace marks the
    packet corrupt. A frame is then delivered, not corrupted: delivered + corrupted +
    collided + outage + out of range = the settled frames (the trace's second count), never
    more than were sent."""
    scenario = load_scenario("m64-teleop-v1", ["duration_s=300", "link.ber=3e-3"])
    result = run_scenario(scenario, seed=1)
    trace = result.recorder.trace
    for src, dst, key in (("operator", "vehicle", "uplink"), ("vehicle", "operator", "downlink")):
        link = result.metrics["link"][key]
        counts = direction_counts(trace.events, src, dst)
        outcomes = link["frames_delivered"] + link["frames_corrupted"] + link["frames_collided"]
        outcomes += link["frames_outage"] + link["frames_out_of_range"]
        assert outcomes == counts.frames_settled <= link["frames_sent"] - link["frames_dropped"]
        # the case happened: more frames had a corrupt packet than were lost to bit errors
        assert counts.frames_corrupted > link["frames_corrupted"] > 0


def test_with_two_nodes_every_collision_is_the_receiver_transmitting() -> None:
    """On s2c (acoustic, half duplex) s100-teleop's 0.594-s gap sends orders over the replies
    still arriving: the operator loses them while it transmits. With two nodes no copy can meet
    another at a receiver (that needs a second sender), so every collide event in the trace is
    a copy lost to its receiver's own transmission, traced as ``deaf`` (never ``collide``), and
    ``copies_lost_transmitting`` counts them."""
    scenario = load_scenario("s100-teleop-v1", ["link.preset=s2c", "duration_s=60"])
    result = run_scenario(scenario)
    trace = result.recorder.trace
    for key, receiver in (("uplink", "vehicle"), ("downlink", "operator")):
        assert [e for e in trace.of_kind(EventKind.COLLIDE) if e.dst == receiver] == []
        lost = [e for e in trace.of_kind(EventKind.DEAF) if e.dst == receiver]
        assert result.metrics["link"][key]["copies_lost_transmitting"] == len(lost)
    assert result.metrics["link"]["downlink"]["copies_lost_transmitting"] > 10
