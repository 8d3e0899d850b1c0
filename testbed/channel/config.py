"""Link configuration: the frozen :class:`LinkConfig` and the packaged modem presets.

A link is described by the parameters of the dccomms_ros custom link (REFERENCE §2.1): bitrate,
intrinsic delay, propagation (fixed part plus distance over speed), half or full duplex, a
byte-counted transmit FIFO with tail drop, the gap between queued frames, an optional fixed packet
size (modems such as the Water Linked M64 send 8-byte packets), a maximum range and the bit-error
models of :mod:`testbed.channel.errors`.

Presets live as TOML files in ``testbed/channel/presets/`` (package data, with their sources in
comments) and are loaded with :func:`load_link_config`, which applies ``--set KEY=VALUE``
overrides through :mod:`testbed.config`, so a bad key or value is a one-line
:class:`~testbed.config.ConfigError` naming it.

Nothing here touches simpy or randomness.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from importlib import resources
from typing import Literal

from testbed.config import (
    apply_overrides,
    build,
    check,
    check_range,
    load_toml,
    user_file,
)

__all__ = [
    "GilbertElliott",
    "LinkConfig",
    "Propagation",
    "load_link_config",
    "preset_names",
]

_PRESET_PACKAGE = "testbed.channel"
_PRESET_DIR = "presets"


MAX_DELAY_S = 60.0
"""Largest accepted fixed delay or gap [s] (intrinsic delay, fixed propagation, queue gap)."""
BITRATE_RANGE_BPS = (1.0, 1.0e10)
"""Accepted bitrates [bit/s]: 1 bit/s to 10 Gbit/s."""
SPEED_RANGE_MPS = (1.0, 1.0e9)
"""Accepted signal speeds [m/s]: acoustic (≈ 1500) to RF (≈ 3e8)."""
MAX_BUFFER_BYTES = 1_000_000_000
"""Largest accepted transmit FIFO [B]."""
MAX_PACKET_BYTES = 65535
"""Largest accepted fixed packet size [B]."""


def _probability(value: float, key: str) -> None:
    check_range(value, key, 0.0, 1.0)


@dataclass(frozen=True, slots=True)
class Propagation:
    """Propagation delay ``fixed_s + distance_m / speed_mps`` (dccomms_ros minPropTime + inc·d).

    Attributes:
        fixed_s: distance-independent part [s], in [0, 60].
        speed_mps: signal speed [m/s], in [1, 1e9]: ≈ 3e8 for RF, ≈ 1500 for acoustic links.
    """

    fixed_s: float = 0.0
    speed_mps: float = 3.0e8

    def __post_init__(self) -> None:
        check_range(self.fixed_s, "fixed_s", 0.0, MAX_DELAY_S, "s")
        check_range(self.speed_mps, "speed_mps", *SPEED_RANGE_MPS, "m/s")

    def delay_s(self, distance_m: float) -> float:
        """Propagation delay [s] over ``distance_m`` [m]."""
        return self.fixed_s + distance_m / self.speed_mps


@dataclass(frozen=True, slots=True)
class GilbertElliott:
    """Two-state (good/bad) Markov bit-error model, per receiver, on one of two clocks.

    **Per bit** (the default, dccomms' model): after each bit the receiver is handed, the
    chain leaves the good state with probability ``p_good_to_bad`` and the bad state with
    ``p_bad_to_good``. It stands still while the link is idle, and a spell's length in seconds
    depends on the traffic. **In time** (``mean_good_s`` and ``mean_bad_s`` given, a fading
    channel): the state holds for exponentially distributed sojourns of those means, whatever
    the traffic, and a copy takes the state at its arrival for all its bits. Either way a bit is
    flipped with probability ``ber_good`` or ``ber_bad`` of its state, and the state persists
    across frames. Off by default (never leaves the good state, which is error-free).

    Attributes:
        p_good_to_bad: per-bit transition probability good → bad, in [0, 1].
        p_bad_to_good: per-bit transition probability bad → good, in (0, 1].
        ber_good: bit error probability in the good state, in [0, 1].
        ber_bad: bit error probability in the bad state, in [0, 1].
        mean_good_s: mean sojourn in the good state [s], > 0 for the chain in time; 0: per
            bit (then ``mean_bad_s`` must be 0 too). Not with ``p_good_to_bad``.
        mean_bad_s: mean sojourn in the bad state [s], > 0 with ``mean_good_s``.
    """

    p_good_to_bad: float = 0.0
    p_bad_to_good: float = 1.0
    ber_good: float = 0.0
    ber_bad: float = 0.5
    mean_good_s: float = 0.0
    mean_bad_s: float = 0.0

    def __post_init__(self) -> None:
        _probability(self.p_good_to_bad, "p_good_to_bad")
        _probability(self.p_bad_to_good, "p_bad_to_good")
        check(self.p_bad_to_good > 0.0, "p_bad_to_good", "must be > 0 (bad state would absorb)")
        _probability(self.ber_good, "ber_good")
        _probability(self.ber_bad, "ber_bad")
        for key in ("mean_good_s", "mean_bad_s"):
            check_range(getattr(self, key), key, 0.0, MAX_DELAY_S * 1e3, "s")
        if self.mean_good_s or self.mean_bad_s:
            check(
                self.mean_good_s > 0.0 and self.mean_bad_s > 0.0,
                "mean_bad_s" if self.mean_good_s else "mean_good_s",
                "the chain in time needs both mean_good_s and mean_bad_s > 0",
            )
            for key, default in (("p_good_to_bad", 0.0), ("p_bad_to_good", 1.0)):
                check(
                    getattr(self, key) == default,
                    key,
                    "give per-bit probabilities or mean sojourns in seconds, not both",
                )

    @property
    def timed(self) -> bool:
        """Whether the chain runs in time (mean sojourns in seconds) rather than per bit."""
        return self.mean_good_s > 0.0

    @property
    def enabled(self) -> bool:
        """Whether the model can flip any bit at all."""
        leaves_good = self.timed or self.p_good_to_bad > 0.0
        return self.ber_good > 0.0 or (leaves_good and self.ber_bad > 0.0)

    @property
    def stationary_bad(self) -> float:
        """Long-run fraction in the bad state: of bits, p_gb / (p_gb + p_bg); of time (the
        chain in time), mean_bad_s / (mean_good_s + mean_bad_s)."""
        if self.timed:
            return self.mean_bad_s / (self.mean_good_s + self.mean_bad_s)
        return self.p_good_to_bad / (self.p_good_to_bad + self.p_bad_to_good)

    @property
    def mean_ber(self) -> float:
        """Long-run bit error rate of the chain."""
        bad = self.stationary_bad
        return (1.0 - bad) * self.ber_good + bad * self.ber_bad


@dataclass(frozen=True, slots=True)
class LinkConfig:
    """One link class: timing, buffering, range and bit-error models (REFERENCE §2.1, §2.5).

    Error sources compose by OR of their error masks: a bit is flipped when any source flips it
    (independent BER ``ber``, range-dependent ``ber_per_m · distance`` and the Gilbert–Elliott
    chain), so the independent part alone gives a per-bit flip probability of
    1 − (1 − ber)(1 − min(1, ber_per_m · d)).

    Every number is checked against its domain at construction (docs/channel.md lists them).

    Attributes:
        bitrate_bps: bitrate on the air [bit/s], in [1, 1e10]; airtime of L bytes is
            8·L / bitrate.
        intrinsic_delay_s: modem latency before the first bit [s], in [0, 60]; the device
            counts as transmitting during it (dccomms_ros intrinsicDelay).
        propagation: propagation delay model.
        duplex: ``"half"`` (one channel: a node cannot receive while transmitting and defers its
            queue while receiving) or ``"full"`` (transmit and receive independent).
        tx_buffer_bytes: transmit FIFO capacity [B], in [1, 1e9]; a frame that would overflow
            it is dropped.
        queue_gap_s: idle gap between consecutive transmissions from the FIFO [s], in [0, 60]
            (dccomms 100 µs).
        packet_bytes: 0 to send frames whole; 1..65535 to cut each frame into packets of this
            many bytes (the last zero-padded), each a separate transmission with its own delay.
        max_range_m: beyond this distance [m] nothing is received (nor interferes); > 0,
            ``inf`` = unlimited.
        ber: independent bit error probability, in [0, 1].
        ber_per_m: range-dependent bit error probability per metre [1/m] (dccomms ``k*m``),
            in [0, 1]; the product with the distance is capped at 1.
        burst: Gilbert–Elliott burst error model.
        name: preset name, for reports.
    """

    bitrate_bps: float
    intrinsic_delay_s: float = 0.0
    propagation: Propagation = field(default_factory=Propagation)
    duplex: Literal["half", "full"] = "half"
    tx_buffer_bytes: int = 500
    queue_gap_s: float = 100e-6
    packet_bytes: int = 0
    max_range_m: float = math.inf
    ber: float = 0.0
    ber_per_m: float = 0.0
    burst: GilbertElliott = field(default_factory=GilbertElliott)
    name: str = "custom"

    def __post_init__(self) -> None:
        check_range(self.bitrate_bps, "bitrate_bps", *BITRATE_RANGE_BPS, "bit/s")
        check_range(self.intrinsic_delay_s, "intrinsic_delay_s", 0.0, MAX_DELAY_S, "s")
        check(
            1 <= self.tx_buffer_bytes <= MAX_BUFFER_BYTES,
            "tx_buffer_bytes",
            f"must be in [1, {MAX_BUFFER_BYTES}] B, got {self.tx_buffer_bytes}",
        )
        check_range(self.queue_gap_s, "queue_gap_s", 0.0, MAX_DELAY_S, "s")
        check(
            0 <= self.packet_bytes <= MAX_PACKET_BYTES,
            "packet_bytes",
            f"must be in [0, {MAX_PACKET_BYTES}] B, got {self.packet_bytes}",
        )
        check_range(
            self.max_range_m, "max_range_m", 0.0, math.inf, "m", low_open=True, allow_inf=True
        )
        _probability(self.ber, "ber")
        check_range(self.ber_per_m, "ber_per_m", 0.0, 1.0, "1/m")

    def airtime_s(self, n_bytes: int) -> float:
        """Time on the air of ``n_bytes`` [s], 8·n / bitrate (one packet or whole frame)."""
        return 8.0 * n_bytes / self.bitrate_bps


def preset_names() -> list[str]:
    """Names of the packaged link presets, sorted."""
    folder = resources.files(_PRESET_PACKAGE).joinpath(_PRESET_DIR)
    return sorted(
        p.name.removesuffix(".toml") for p in folder.iterdir() if p.name.endswith(".toml")
    )


def load_link_config(preset: str, overrides: Sequence[str] = ()) -> LinkConfig:
    """Load a packaged preset, or the user's own preset file (the packaged files' layout), and
    apply ``KEY=VALUE`` overrides.

    Args:
        preset: preset name (``s100``, ``m64``, ``s2c``, ``tether``; see :func:`preset_names`)
            or the path of a ``.toml`` preset file.
        overrides: ``--set`` strings such as ``"ber=1e-4"`` or ``"propagation.speed_mps=1500"``.

    Returns:
        The checked link configuration.

    Raises:
        ConfigError: neither a packaged preset nor a file (naming it and the packaged ones),
            a bad preset file (naming the file and the key), or an override with an unknown
            key, a wrong type or a value out of range (naming the key).
    """
    own = user_file(preset, preset_names(), "link preset")
    if own is not None:
        data = load_toml(own)
        source = str(own)
    else:
        resource = resources.files(_PRESET_PACKAGE).joinpath(_PRESET_DIR).joinpath(f"{preset}.toml")
        with resources.as_file(resource) as path:
            data = load_toml(path)
        source = f"preset {preset}"
    base = build(LinkConfig, data, source=source)  # a broken preset is named as such
    if not overrides:
        return base
    return build(LinkConfig, apply_overrides(data, overrides), source="--set")
