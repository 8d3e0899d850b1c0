"""testbed.channel.probe: the one-way probe's counts, PER, latency and goodput vs closed forms."""

from __future__ import annotations

import pytest
from scipy import stats

from testbed.channel.config import load_link_config
from testbed.channel.probe import ProbeResult, format_report, frame_size_limits, run_probe

S100 = load_link_config("s100")
I_S = S100.intrinsic_delay_s


def outcomes(r: ProbeResult) -> int:
    return (
        r.frames_delivered
        + r.frames_corrupted
        + r.frames_collided
        + r.frames_dropped
        + r.frames_out_of_range
    )


def test_frame_size_limits() -> None:
    # 6 B WAFrame overhead + 4 B sequence number; at most 255 B of payload.
    assert frame_size_limits() == (10, 261)


def test_clean_link_latency_and_goodput_are_the_closed_forms() -> None:
    n, size, interval = 200, 60, 1.0
    r = run_probe(load_link_config("s100", ["ber=0"]), frames=n, frame_bytes=size)
    latency = I_S + 8 * size / 1900.0
    assert r.frames_delivered == n and r.per == 0.0 and outcomes(r) == n
    assert r.latency_s.mean == pytest.approx(latency, abs=1e-9)
    assert r.latency_s.max == pytest.approx(latency, abs=1e-9)
    assert r.latency_s.p50 == pytest.approx(latency, abs=1e-9)
    assert r.sim_s == pytest.approx((n - 1) * interval + latency)
    assert r.goodput_bps == pytest.approx(8 * (size - 6) / interval)  # the offered payload rate
    assert r.wall_s > 0 and r.rtf == pytest.approx(r.sim_s / r.wall_s)


@pytest.mark.parametrize(("ber", "size"), [(1e-3, 60), (2e-4, 255), (5e-3, 13)])
def test_end_to_end_per_within_binomial_interval(ber: float, size: int) -> None:
    n = 6000
    config = load_link_config("s100", [f"ber={ber}"])
    r = run_probe(config, frames=n, frame_bytes=size, interval_s=2.0, seed=2)  # unloaded
    per = 1.0 - (1.0 - ber) ** (8 * size)
    lo, hi = stats.binom.interval(0.999, n, per)
    assert lo / n <= r.per <= hi / n
    assert r.frames_corrupted == n - r.frames_delivered and outcomes(r) == n


def test_m64_packetised_latency() -> None:
    m64 = load_link_config("m64")
    r = run_probe(m64, frames=50, frame_bytes=20, interval_s=4.0, distance_m=150.0)
    # 20 B → 3 packets of 8 B, 1 s each, a guard gap apart, then 0.1 s of propagation.
    assert r.frames_delivered == 50
    expected = 3 * 1.0 + 2 * m64.queue_gap_s + 150.0 / 1500.0
    assert r.latency_s.max == pytest.approx(expected, abs=1e-9)


def test_overload_drops_and_range_loses_everything() -> None:
    r = run_probe(load_link_config("m64"), frames=100, frame_bytes=60, interval_s=1.0)
    assert r.frames_dropped > 50 and outcomes(r) == 100
    # PER is the air's (as a run's): what the FIFO dropped never flew and has its own rate
    transmitted = 100 - r.frames_dropped
    assert r.drop_rate == r.frames_dropped / 100
    assert r.per == 1.0 - r.frames_delivered / transmitted
    assert r.per < 0.05  # m64's BER over the frames that flew, not the 50+ % dropped
    far = run_probe(S100, frames=20, distance_m=15.5)
    assert far.frames_out_of_range == 20 and far.frames_delivered == 0 and far.per == 1.0
    assert far.latency_s.mean is None
    # nothing delivered: n/a, as every other summary says (it printed "latency mean -")
    assert "  latency mean n/a  p50 n/a  p95 n/a  max n/a" in format_report(far).splitlines()


def test_same_seed_same_result() -> None:
    def key(seed: int) -> dict[str, object]:
        r = run_probe(load_link_config("s100", ["ber=1e-3"]), frames=500, seed=seed)
        out = r.to_json_dict()
        del out["wall_s"], out["rtf"]
        return out

    assert key(3) == key(3)
    assert key(3) != key(4)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"frames": 0},
        {"frame_bytes": 9},
        {"frame_bytes": 262},
        {"interval_s": 0.0},
        {"interval_s": float("nan")},
        {"distance_m": -1.0},
        {"seed": -1},
    ],
)
def test_bad_arguments_raise(kwargs: dict[str, float]) -> None:
    with pytest.raises(ValueError):
        run_probe(S100, **kwargs)  # type: ignore[arg-type]


@pytest.mark.parametrize(("preset", "size", "interval"), [("s100", 13, 1.0), ("m64", 20, 4.0)])
def test_high_ber_delivered_frames_wait_for_no_later_frame(
    preset: str, size: int, interval: float
) -> None:
    # At BER 1e-2 about one frame in ten has a corrupted length byte; the probe decodes as the
    # run's nodes do (flush at the end of each transmission), so every delivered frame arrives
    # after exactly its own delay + airtime (a frame held behind a corrupted candidate would
    # arrive one or more intervals later).
    config = load_link_config(preset, ["ber=1e-2"])
    r = run_probe(config, frames=3000, frame_bytes=size, interval_s=interval, seed=1)
    if preset == "s100":
        closed_form = I_S + 8 * size / config.bitrate_bps
    else:  # 20 B → 3 packets of 8 B, a guard gap apart, no distance
        closed_form = 3 * 8 * 8 / config.bitrate_bps + 2 * config.queue_gap_s
    assert r.frames_delivered > 0
    assert r.latency_s.mean == pytest.approx(closed_form, abs=1e-9)
    assert r.latency_s.max == pytest.approx(closed_form, abs=1e-9)
    # and the PER is still the closed form over the frame's bits
    per = 1.0 - (1.0 - 1e-2) ** (8 * size)
    lo, hi = stats.binom.interval(0.999, 3000, per)
    assert lo / 3000 <= r.per <= hi / 3000
