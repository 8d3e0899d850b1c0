"""Blue Robotics T200 thruster: force ⇄ PWM ⇄ current lookup from the published 12 V table.

:class:`T200` interpolates Blue Robotics' published 12 V performance table (package data
``data/t200_12v.csv``, credited there) linearly, as the ECS paper's lookup tables do. Forces are
signed [N]: positive is the propeller's stronger "forward" thrust along the thruster's
``direction``, negative the weaker reverse thrust. A CW propeller takes the table's PWM as is; a
CCW (reversed) propeller mirrors it about neutral, pwm -> 3000 - pwm. Every lookup, here and in
the allocator's kernels, is :func:`~testbed.vehicle.thrust_kernels.lookup` on one of three
(2, k) tables (:attr:`T200.pwm_table`, :attr:`T200.inverse_table`, :attr:`T200.current_table`).
The plant side (spin-up lag, faults) is :mod:`testbed.vehicle.thrusters`.
"""

from __future__ import annotations

import csv
import functools
import io
from importlib import resources

import numpy as np

from testbed.common import jit
from testbed.common.jit import CONST_TABLE, F64, VECTOR
from testbed.vehicle.thrust_kernels import lookup, lookup_many, total_current
from testbed.vehicle.thruster_config import Handedness

__all__ = [
    "DEAD_BAND_US",
    "NEUTRAL_PWM_US",
    "PUBLISHED_MAXIMA",
    "SUPPLY_VOLTAGE_RANGE_V",
    "T200",
    "ZERO_FORCE_N",
]

NEUTRAL_PWM_US = 1500.0
"""Neutral (stopped) PWM pulse [µs]; a CCW propeller's pulse is mirrored about it."""

DEAD_BAND_US = (1464.0, 1536.0)
"""12 V dead band [µs]: every pulse in it gives 0 N (Blue Robotics, REFERENCE §3.4)."""

PUBLISHED_MAXIMA: tuple[tuple[float, float, float], ...] = (
    (12.0, 36.4, 28.6),
    (14.0, 44.4, 34.5),
    (16.0, 51.4, 39.9),
    (18.0, 59.0, 45.0),
    (20.0, 65.9, 49.4),
)
"""Blue Robotics' T200 maxima per supply: (voltage [V], max forward [N], max reverse [N])."""

SUPPLY_VOLTAGE_RANGE_V = (PUBLISHED_MAXIMA[0][0], PUBLISHED_MAXIMA[-1][0])
"""Supply voltages [V] the scaled table covers, (12, 20): :meth:`T200.from_table`'s domain."""

ZERO_FORCE_N = 1e-9
"""Half-width [N] of the force gap across which the inverse table crosses the dead band."""

_TABLE_RESOURCE = "t200_12v.csv"
_TABLE_VOLTAGE_V = 12.0

_TOTAL_CURRENT = jit.entry(total_current, VECTOR, F64, CONST_TABLE)
"""The power meter's kernel without numba's dispatcher (forces and the read-only table)."""


class T200:
    """A T200 thruster's lookup tables at one supply voltage.

    Three views of the same table:

    * PWM -> force (:meth:`force_for_pwm`) interpolates the table as published, with the
      merged dead-band row expanded back to two zero rows at 1464 and 1536 µs, so every pulse
      in the dead band gives exactly 0 N. Outside 1100-1900 µs the end rows hold.
    * force -> PWM and force -> current (:meth:`pwm_for_force`, :meth:`current_for_force`)
      use the table's monotone envelope, so the inverse is a function and strictly monotone on
      each side of 0 N. Walking outward from the dead band, a row is kept only if its force is
      strictly beyond every row nearer neutral. The 12 V table is non-monotonic only in its
      last rows: 1896 and 1900 µs (36.20 and 36.40 N, not beyond 1892 µs's 36.3951 N) and
      1100 µs (-28.449 N, not beyond 1104 µs's -28.6452 N) are dropped, so forces saturate at
      +36.3951 / -28.6452 N, reached at 1892 / 1104 µs (CW) with 16.74 / 17.08 A. The inverse
      crosses the dead band linearly between -1e-9 and +1e-9 N (:data:`ZERO_FORCE_N`), so
      0 N maps to 1500 µs exactly, round-off from T⁺ stays within a nanosecond of it, and any
      real force maps outside the dead band; PWM(F) is continuous and strictly increasing.

    Voltage: the data are the 12 V sheet. At another supply V (12-20 V), the forward rows'
    force *and* current are multiplied by k_fwd(V) = F_fwd,max(V) / 36.4 N and the reverse
    rows' by k_rev(V) = F_rev,max(V) / 28.6 N, where F_max(V) is Blue Robotics' published
    maximum (:data:`PUBLISHED_MAXIMA`), linearly interpolated between the listed voltages. The
    PWM axis and the 12 V dead band are kept (the published band shrinks from 1464-1536 µs to
    1476-1528 µs at 20 V). Scaling current with force roughly reproduces Blue Robotics'
    (unverified) peak currents: max(16.74 A × k_fwd, 17.08 A × k_rev) = 23.8 A at 16 V
    (published ≈ 24 A) and 30.3 A at 20 V (≈ 32 A); at 12 V nothing changes.

    Args:
        pwm_us: (k,) table PWM [µs], strictly increasing, one row at 1500 µs for the dead band.
        force_n: (k,) signed force [N] at each PWM (CW propeller).
        current_a: (k,) current [A] at each PWM.
        voltage_v: the supply voltage the table describes [V] (informational).

    Raises:
        ValueError: malformed table (shapes, order, no neutral row, wrong signs).
    """

    __slots__ = (
        "_current_table",
        "_inverse_table",
        "_max_forward_n",
        "_max_reverse_n",
        "_pwm_table",
        "voltage_v",
    )

    def __init__(
        self, pwm_us: np.ndarray, force_n: np.ndarray, current_a: np.ndarray, *, voltage_v: float
    ) -> None:
        pwm = np.asarray(pwm_us, dtype=np.float64)
        force = np.asarray(force_n, dtype=np.float64)
        current = np.asarray(current_a, dtype=np.float64)
        if not (pwm.ndim == 1 and pwm.shape == force.shape == current.shape and pwm.size >= 3):
            raise ValueError("T200 table: pwm, force and current must be equal-length 1-D arrays")
        if np.any(np.diff(pwm) <= 0):
            raise ValueError("T200 table: pwm must be strictly increasing")
        neutral = np.flatnonzero(pwm == NEUTRAL_PWM_US)
        if neutral.size != 1 or force[neutral[0]] != 0.0:
            raise ValueError("T200 table: needs exactly one 0 N row at 1500 µs")
        i0 = int(neutral[0])
        if np.any(force[:i0] >= 0) or np.any(force[i0 + 1 :] <= 0) or np.any(current < 0):
            raise ValueError("T200 table: force must be < 0 below 1500 µs and > 0 above")
        self.voltage_v = float(voltage_v)

        # PWM -> force: the table as published, dead band expanded to its edges.
        lo, hi = DEAD_BAND_US
        below, above = pwm < lo, pwm > hi
        self._pwm_table = _table(
            np.concatenate([pwm[below], [lo, hi], pwm[above]]),
            np.concatenate([force[below], [0.0, 0.0], force[above]]),
        )

        # Force -> PWM / current: the monotone envelope, walking outward from neutral.
        fwd = _outward_envelope(force[i0 + 1 :])
        rev = _outward_envelope(-force[:i0][::-1])
        fwd_pwm, fwd_force, fwd_current = (
            pwm[i0 + 1 :][fwd],
            force[i0 + 1 :][fwd],
            current[i0 + 1 :][fwd],
        )
        rev_pwm = pwm[:i0][::-1][rev]
        rev_force = force[:i0][::-1][rev]
        rev_current = current[:i0][::-1][rev]
        # Force -> PWM: ascending force, crossing the dead band between -/+ZERO_FORCE_N.
        self._inverse_table = _table(
            np.concatenate([rev_force[::-1], [-ZERO_FORCE_N, ZERO_FORCE_N], fwd_force]),
            np.concatenate([rev_pwm[::-1], [lo, hi], fwd_pwm]),
        )
        self._current_table = _table(
            np.concatenate([rev_force[::-1], [0.0], fwd_force]),
            np.concatenate([rev_current[::-1], [0.0], fwd_current]),
        )
        self._max_forward_n = float(fwd_force[-1])
        self._max_reverse_n = float(-rev_force[-1])

    @classmethod
    def from_table(cls, voltage_v: float = 12.0) -> T200:
        """The T200 from the packaged Blue Robotics 12 V table, scaled to ``voltage_v``.

        Args:
            voltage_v: supply voltage [V], 12-20 (see the class docstring for the scaling).

        Raises:
            ValueError: voltage outside the published 12-20 V range.
        """
        volts = [row[0] for row in PUBLISHED_MAXIMA]
        if not (volts[0] <= voltage_v <= volts[-1]):
            raise ValueError(
                f"T200 voltage must be in [{volts[0]}, {volts[-1]}] V, got {voltage_v}"
            )
        pwm, force, current = _packaged_table()
        forward = _table(np.array(volts), np.array([r[1] for r in PUBLISHED_MAXIMA]))
        reverse = _table(np.array(volts), np.array([r[2] for r in PUBLISHED_MAXIMA]))
        k_fwd = lookup(float(voltage_v), forward) / 36.4
        k_rev = lookup(float(voltage_v), reverse) / 28.6
        scale = np.where(pwm > NEUTRAL_PWM_US, k_fwd, np.where(pwm < NEUTRAL_PWM_US, k_rev, 1.0))
        return cls(pwm, force * scale, current * scale, voltage_v=voltage_v)

    @property
    def max_forward_n(self) -> float:
        """Largest forward force [N] (positive; 36.3951 at 12 V)."""
        return self._max_forward_n

    @property
    def max_reverse_n(self) -> float:
        """Largest reverse force magnitude [N] (positive; 28.6452 at 12 V)."""
        return self._max_reverse_n

    @property
    def force_limits_n(self) -> tuple[float, float]:
        """(lowest, highest) signed force [N]: (-max_reverse_n, max_forward_n)."""
        return (-self._max_reverse_n, self._max_forward_n)

    @property
    def max_current_a(self) -> float:
        """Largest current on the monotone envelope [A] (17.08 at 12 V)."""
        return float(self._current_table[1].max())

    @property
    def pwm_table(self) -> np.ndarray:
        """(2, k) PWM [µs] → force [N] of a CW propeller, dead band expanded (read-only)."""
        return self._pwm_table

    @property
    def inverse_table(self) -> np.ndarray:
        """(2, k) force [N] → CW PWM [µs] on the monotone envelope (read-only)."""
        return self._inverse_table

    @property
    def current_table(self) -> np.ndarray:
        """(2, k) force [N] → current [A] on the monotone envelope, 0 A at 0 N (read-only)."""
        return self._current_table

    @property
    def inverse_force_n(self) -> np.ndarray:
        """(k,) strictly increasing forces [N] of the force -> PWM table (read-only)."""
        row: np.ndarray = self._inverse_table[0]
        return row

    @property
    def inverse_pwm_us(self) -> np.ndarray:
        """(k,) CW PWM pulse [µs] at each of :attr:`inverse_force_n` (read-only)."""
        row: np.ndarray = self._inverse_table[1]
        return row

    @property
    def force_axis_n(self) -> np.ndarray:
        """(k,) strictly increasing signed forces [N] of the monotone envelope (read-only)."""
        row: np.ndarray = self._current_table[0]
        return row

    @property
    def current_axis_a(self) -> np.ndarray:
        """(k,) current [A] at each of :attr:`force_axis_n` (read-only); 0 A at 0 N."""
        row: np.ndarray = self._current_table[1]
        return row

    def force_for_pwm(self, pwm_us: float, handedness: Handedness = "cw") -> float:
        """Force [N] a thruster produces at PWM pulse ``pwm_us`` [µs]."""
        pulse = 3000.0 - pwm_us if handedness == "ccw" else pwm_us
        return lookup(float(pulse), self._pwm_table)

    def pwm_for_force(self, force_n: float, handedness: Handedness = "cw") -> float:
        """PWM pulse [µs] that commands ``force_n`` [N], saturating at the envelope's ends."""
        pulse = lookup(float(force_n), self._inverse_table)
        return 3000.0 - pulse if handedness == "ccw" else pulse

    def current_for_force(self, force_n: float) -> float:
        """Current [A] drawn to produce ``force_n`` [N] (saturates at the envelope's ends)."""
        return lookup(float(force_n), self._current_table)

    def forces_for_pwms(self, pwms_us: np.ndarray, ccw: np.ndarray) -> np.ndarray:
        """Vectorised :meth:`force_for_pwm`: (n,) forces [N] for (n,) pulses [µs].

        Args:
            pwms_us: (n,) PWM pulses [µs].
            ccw: (n,) bool, True for counter-clockwise propellers.
        """
        pwms = np.asarray(pwms_us, dtype=np.float64)
        return _lookup_array(np.where(ccw, 3000.0 - pwms, pwms), self._pwm_table)

    def pwms_for_forces(self, forces_n: np.ndarray, ccw: np.ndarray) -> np.ndarray:
        """Vectorised :meth:`pwm_for_force`: (n,) pulses [µs] for (n,) forces [N].

        Args:
            forces_n: (n,) signed forces [N].
            ccw: (n,) bool, True for counter-clockwise propellers.
        """
        pulse = _lookup_array(forces_n, self._inverse_table)
        pwms: np.ndarray = np.where(ccw, 3000.0 - pulse, pulse)
        return pwms

    def currents_for_forces(self, forces_n: np.ndarray) -> np.ndarray:
        """Vectorised :meth:`current_for_force`: (n,) currents [A] for (n,) forces [N]."""
        return _lookup_array(forces_n, self._current_table)

    def total_current_a(self, forces_n: np.ndarray) -> float:
        """Σ current [A] drawn by (n,) contiguous float64 forces [N] (the power meter's, per
        frame: called without numba's type checks, :func:`testbed.common.jit.entry`)."""
        return _TOTAL_CURRENT(forces_n, 1.0, self._current_table)

    def __repr__(self) -> str:
        return (
            f"T200(voltage_v={self.voltage_v:g}, max_forward_n={self._max_forward_n:.4f}, "
            f"max_reverse_n={self._max_reverse_n:.4f})"
        )


def _outward_envelope(magnitudes: np.ndarray) -> np.ndarray:
    """Indices of rows whose magnitude is strictly beyond every earlier row (walking outward)."""
    best = np.maximum.accumulate(magnitudes)
    keep = np.ones(magnitudes.size, dtype=bool)
    keep[1:] = magnitudes[1:] > best[:-1]
    return np.flatnonzero(keep)


def _table(xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """A read-only (2, k) lookup table: abscissae (strictly increasing) over values."""
    return _frozen(np.vstack([xs, ys]))


def _lookup_array(values: np.ndarray, table: np.ndarray) -> np.ndarray:
    """:func:`~testbed.vehicle.thrust_kernels.lookup` at every element of ``values``."""
    xs = np.ascontiguousarray(values, dtype=np.float64)
    out = np.empty(xs.shape)
    lookup_many(xs.reshape(-1), table, out.reshape(-1))
    return out


def _frozen(array: np.ndarray) -> np.ndarray:
    array = np.ascontiguousarray(array, dtype=np.float64)
    array.setflags(write=False)
    return array


@functools.cache
def _packaged_table() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(pwm [µs], force [N], current [A]) from the packaged 12 V CSV, '#' comments skipped."""
    text = resources.files("testbed.vehicle").joinpath("data", _TABLE_RESOURCE).read_text()
    lines = [line for line in text.splitlines() if line and not line.startswith("#")]
    rows = list(csv.DictReader(io.StringIO("\n".join(lines))))
    if any(float(r["voltage"]) != _TABLE_VOLTAGE_V for r in rows):
        raise ValueError(f"{_TABLE_RESOURCE}: expected every row at {_TABLE_VOLTAGE_V} V")
    pwm, force, current = (
        _frozen(np.array([float(r[key]) for r in rows])) for key in ("pwm", "force", "current")
    )
    return pwm, force, current
