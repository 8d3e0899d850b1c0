"""testbed.channel.config: presets carry the cited figures; overrides are checked per key."""

from __future__ import annotations

import math

import pytest

from testbed.channel.config import (
    GilbertElliott,
    LinkConfig,
    Propagation,
    load_link_config,
    preset_names,
)
from testbed.config import ConfigError


def test_known_presets() -> None:
    assert preset_names() == ["m64", "s100", "s2c", "tether"]


def test_s100_is_the_paper_reproducing_set() -> None:
    # REFERENCE §2.5: 1900 bps, 85.28 ms, d/3e8, BER 7e-6, half duplex, 500 B FIFO, 100 µs, 15 m.
    c = load_link_config("s100")
    assert c.name == "s100"
    assert c.bitrate_bps == 1900.0
    assert c.intrinsic_delay_s == pytest.approx(85.28e-3, abs=0.01e-3)
    assert c.duplex == "half"
    assert c.tx_buffer_bytes == 500
    assert c.queue_gap_s == pytest.approx(100e-6)
    assert c.packet_bytes == 0
    assert c.ber == 7e-6
    assert c.propagation.speed_mps == 3.0e8
    assert c.max_range_m == 15.0
    assert not c.burst.enabled


def test_other_presets() -> None:
    m64 = load_link_config("m64")
    assert (m64.bitrate_bps, m64.packet_bytes, m64.propagation.speed_mps) == (64.0, 8, 1500.0)
    assert m64.max_range_m == pytest.approx(200.0)
    # One 8-B packet takes 1 s at 64 bps: the modem's "≈ 1 packet/s".
    assert m64.airtime_s(8) == pytest.approx(1.0)
    s2c = load_link_config("s2c")
    assert s2c.bitrate_bps == 13900.0 and s2c.propagation.speed_mps == 1500.0
    assert 0.1 <= s2c.intrinsic_delay_s < 1.0
    tether = load_link_config("tether")
    assert tether.duplex == "full" and tether.ber == 0.0
    assert tether.bitrate_bps == pytest.approx(10e6) and tether.intrinsic_delay_s == 1e-3


def test_overrides_apply_with_types() -> None:
    c = load_link_config(
        "s100", ["ber=1e-3", "propagation.speed_mps=1500", "burst.p_good_to_bad=0.01"]
    )
    assert c.ber == 1e-3
    assert c.propagation == Propagation(0.0, 1500.0)
    assert c.burst.p_good_to_bad == 0.01 and c.burst.enabled
    assert c.bitrate_bps == 1900.0  # untouched


@pytest.mark.parametrize(
    ("overrides", "fragment"),
    [
        (["nope=1"], "--set: nope: unknown key"),
        (["ber=2"], "--set: ber: must be in [0, 1]"),
        (["ber=-0.1"], "--set: ber: must be in [0, 1]"),
        (["bitrate_bps=-5"], "--set: bitrate_bps: must be in [1, 1e+10] bit/s"),
        (["bitrate_bps=0"], "--set: bitrate_bps: must be in [1, 1e+10] bit/s"),
        (["intrinsic_delay_s=-1"], "--set: intrinsic_delay_s: must be in [0, 60] s"),
        (["propagation.speed_mps=0"], "--set: propagation.speed_mps: must be in [1, 1e+09] m/s"),
        (["propagation.bogus=0"], "--set: propagation.bogus: unknown key"),
        (["tx_buffer_bytes=0"], "--set: tx_buffer_bytes: must be in [1, 1000000000] B"),
        (["tx_buffer_bytes=1.5"], "--set: tx_buffer_bytes: expected an integer"),
        (["duplex=simplex"], "--set: duplex: expected one of"),
        (["burst.ber_bad=1.5"], "--set: burst.ber_bad: must be in [0, 1]"),
        (["burst.p_bad_to_good=0"], "--set: burst.p_bad_to_good: must be > 0"),
        (["ber_per_m=-1"], "--set: ber_per_m: must be in [0, 1] 1/m"),
        (["max_range_m=0"], "--set: max_range_m: must be > 0"),
    ],
)
def test_bad_overrides_are_one_line_errors_naming_the_key(
    overrides: list[str], fragment: str
) -> None:
    with pytest.raises(ConfigError) as info:
        load_link_config("s100", overrides)
    assert fragment in str(info.value)
    assert "\n" not in str(info.value)


def test_unknown_preset_names_it_and_the_known_ones() -> None:
    with pytest.raises(ConfigError) as info:
        load_link_config("s300")
    message = str(info.value)
    assert "'s300'" in message and "m64, s100, s2c, tether" in message


def test_gilbert_elliott_closed_forms() -> None:
    ge = GilbertElliott(p_good_to_bad=0.01, p_bad_to_good=0.09, ber_good=1e-4, ber_bad=0.5)
    assert ge.stationary_bad == pytest.approx(0.1)
    assert ge.mean_ber == pytest.approx(0.9 * 1e-4 + 0.1 * 0.5)
    assert not GilbertElliott().enabled


def test_config_defaults_and_helpers() -> None:
    c = LinkConfig(bitrate_bps=1000.0)
    assert c.max_range_m == math.inf and c.duplex == "half"
    assert c.airtime_s(125) == pytest.approx(1.0)
    assert c.propagation.delay_s(300.0) == pytest.approx(1e-6)
