"""Thrusters on the plant side: spin-up lag and plant faults.

The T200's force ⇄ PWM ⇄ current lookup (:class:`T200` and its constants) lives in ``t200.py``
and is re-exported here.

:class:`ThrusterDynamics` is the plant side: a first-order spin-up lag per thruster and the
faults the plant applies (dead, stuck, degraded), whether or not the allocator knows of them.

The geometry names (:class:`ThrusterSpec`, :class:`ThrusterConfig`,
:func:`load_thruster_config`) live in ``thruster_config.py`` and are re-exported here.
Allocation lives in ``allocation.py``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np

from testbed.common import jit
from testbed.common.jit import F64, I64, MARK, TABLE, VECTOR
from testbed.vehicle.t200 import (
    DEAD_BAND_US,
    NEUTRAL_PWM_US,
    PUBLISHED_MAXIMA,
    T200,
    ZERO_FORCE_N,
)
from testbed.vehicle.thrust_kernels import actuate_rows, lag_step
from testbed.vehicle.thruster_config import (
    Handedness,
    ThrusterConfig,
    ThrusterSpec,
    known_thruster_configs,
    load_thruster_config,
    mate_rov_to_frd,
    read_thruster_config,
)

if TYPE_CHECKING:
    from testbed.ecs.store import RowView

__all__ = [
    "DEAD_BAND_US",
    "NEUTRAL_PWM_US",
    "PUBLISHED_MAXIMA",
    "SPIN_UP_TIME_CONSTANT_S",
    "T200",
    "ZERO_FORCE_N",
    "FaultMode",
    "Handedness",
    "ThrusterConfig",
    "ThrusterDynamics",
    "ThrusterFault",
    "ThrusterSpec",
    "known_thruster_configs",
    "lag_blend",
    "load_thruster_config",
    "mate_rov_to_frd",
    "read_thruster_config",
]

SPIN_UP_TIME_CONSTANT_S = 0.020
"""Default first-order spin-up time constant [s].

Fitted (least squares on the unit-step response, 63 % rise at 20 ms) to the T200 thrust
dynamics (6136 s + 108700) / (s³ + 89 s² + 9258 s + 108700) identified by von Benzon et al.
2022 (REFERENCE §3.4). That model's slowest pole alone would give 0.076 s, but its zero at
-17.7 rad/s nearly cancels it (95 % of the step is reached at 32 ms).
"""

FaultMode = Literal["dead", "stuck", "degraded"]

# The frame's thruster kernel, called without numba's dispatcher (testbed.common.jit.entry): the
# plant's, the actuation's and the store's contiguous float64 arrays (int64 mark).
_ACTUATE_ROWS = jit.entry(
    actuate_rows, *(VECTOR,) * 5, F64, TABLE, F64, VECTOR, VECTOR, MARK, I64, VECTOR
)


@dataclass(frozen=True, slots=True)
class ThrusterFault:
    """A thruster fault.

    Attributes:
        mode: ``"dead"`` (0 N), ``"stuck"`` (holds ``value`` N) or ``"degraded"`` (its force is
            ``value`` × the command, 0 ≤ value ≤ 1).
        value: the held force [N] (stuck) or the factor (degraded); unused when dead.
    """

    mode: FaultMode
    value: float = 0.0

    def __post_init__(self) -> None:
        if self.mode not in ("dead", "stuck", "degraded"):
            raise ValueError(f"fault mode must be 'dead', 'stuck' or 'degraded', got {self.mode!r}")
        if not math.isfinite(self.value):
            raise ValueError(f"fault value must be finite, got {self.value}")
        if self.mode == "degraded" and not 0.0 <= self.value <= 1.0:
            raise ValueError(f"degraded factor must be in [0, 1], got {self.value}")


def lag_blend(dt_s: float, time_constant_s: float) -> float:
    """The first-order lag's step over ``dt_s`` [s] with the command held: 1 − exp(−dt/τ)
    (1 for τ = 0, no lag)."""
    if time_constant_s == 0.0:
        return 1.0
    return -math.expm1(-dt_s / time_constant_s)


class ThrusterDynamics:
    """Plant-side thruster response: first-order spin-up lag and faults, per thruster.

    Each healthy thruster follows τ dF/dt = F_cmd - F, integrated exactly over a step with the
    command held (zero-order hold): F += (F_cmd - F)(1 - exp(-dt/τ)). Faults:

    * dead: the thruster gives 0 N from the moment of failure;
    * stuck: it holds a force (given, or the force it had when it stuck) whatever is commanded;
    * degraded: it lags toward ``factor`` × the command.

    Clearing a fault resumes the lag from the force the thruster had.

    Args:
        n_thrusters: number of thrusters.
        time_constant_s: spin-up time constant τ [s] (default :data:`SPIN_UP_TIME_CONSTANT_S`);
            0 makes the thrusters follow their command at once.
        initial_forces_n: (n,) initial forces [N]; zeros by default.

    Raises:
        ValueError: n_thrusters < 1, negative τ, or a wrongly shaped initial force vector.
    """

    def __init__(
        self,
        n_thrusters: int,
        *,
        time_constant_s: float = SPIN_UP_TIME_CONSTANT_S,
        initial_forces_n: np.ndarray | None = None,
    ) -> None:
        if n_thrusters < 1:
            raise ValueError(f"n_thrusters must be >= 1, got {n_thrusters}")
        if not time_constant_s >= 0.0:
            raise ValueError(f"time_constant_s must be >= 0, got {time_constant_s}")
        self.n_thrusters = n_thrusters
        self.time_constant_s = float(time_constant_s)
        self._forces = np.zeros(n_thrusters)
        self._start = np.zeros(n_thrusters)  # step_applied's forces at the interval's start
        self._faults: dict[int, ThrusterFault] = {}
        self._gain = np.ones(n_thrusters)  # command multiplier: 0 dead, factor degraded
        self._held = np.full(n_thrusters, math.nan)  # dead or stuck: the force it gives, else NaN
        self._blend = (math.nan, math.nan, 1.0)  # (dt_s, τ, 1 - exp(-dt/τ)) of the last step
        # compiled (or loaded) now, on scratch forces, not in the first frame of a timed run
        lag_step(np.zeros(n_thrusters), self._forces, self._gain, self._held, 0.0)
        if initial_forces_n is not None:
            self.reset(initial_forces_n)

    @property
    def forces_n(self) -> np.ndarray:
        """(n,) current actual forces [N] (a copy)."""
        return self._forces.copy()

    @property
    def live_forces_n(self) -> np.ndarray:
        """(n,) current actual forces [N], the plant's own array: :meth:`step_applied`
        overwrites it (read it, do not keep it)."""
        return self._forces

    @property
    def faults(self) -> dict[int, ThrusterFault]:
        """Active faults by thruster index (a copy)."""
        return dict(self._faults)

    def reset(self, forces_n: np.ndarray | None = None) -> None:
        """Set the actual forces (zeros by default); faults are kept and re-applied."""
        forces = np.zeros(self.n_thrusters) if forces_n is None else np.asarray(forces_n, float)
        if forces.shape != (self.n_thrusters,):
            raise ValueError(f"forces_n must have shape ({self.n_thrusters},), got {forces.shape}")
        held = self._held
        self._forces = np.where(np.isnan(held), forces, held)

    def set_fault(self, index: int, mode: FaultMode, value: float | None = None) -> None:
        """Fail thruster ``index``.

        Args:
            index: thruster index (column of the configuration matrix).
            mode: ``"dead"``, ``"stuck"`` or ``"degraded"``.
            value: stuck: the held force [N] (default: the force it has now); degraded: the
                factor in [0, 1] (required); dead: ignored.

        Raises:
            IndexError: bad index. ValueError: bad mode or value.
        """
        self._check_index(index)
        if mode == "stuck" and value is None:
            value = float(self._forces[index])
        if mode == "degraded" and value is None:
            raise ValueError("a degraded fault needs its factor as value")
        fault = ThrusterFault(mode, 0.0 if value is None or mode == "dead" else float(value))
        self._faults[index] = fault
        self._gain[index] = fault.value if mode == "degraded" else 1.0
        if mode == "degraded":
            self._held[index] = math.nan
        else:
            held = self._held[index] = fault.value if mode == "stuck" else 0.0
            self._forces[index] = held

    def clear_fault(self, index: int | None = None) -> None:
        """Repair thruster ``index`` (all thrusters when None)."""
        indices = list(self._faults) if index is None else [index]
        for i in indices:
            self._check_index(i)
            self._faults.pop(i, None)
            self._gain[i] = 1.0
            self._held[i] = math.nan

    def step(self, commanded_forces_n: np.ndarray, dt_s: float) -> np.ndarray:
        """Advance ``dt_s`` seconds with the command held; return the (n,) actual forces [N].

        Args:
            commanded_forces_n: (n,) commanded forces [N] (e.g. ``ThrusterCommand.forces_n``).
            dt_s: step length [s], >= 0.

        Returns:
            A new (n,) array (the previous one is not modified).

        Raises:
            ValueError: wrong shape or negative dt_s.
        """
        command = np.asarray(commanded_forces_n, dtype=np.float64)
        if command.shape != (self.n_thrusters,):
            raise ValueError(
                f"commanded_forces_n must have shape ({self.n_thrusters},), got {command.shape}"
            )
        forces = self._forces.copy()
        lag_step(forces, command, self._gain, self._held, self._blend_over(dt_s))
        self._forces = forces
        return forces

    def step_applied(
        self,
        commanded_forces_n: np.ndarray,
        dt_s: float,
        matrix: np.ndarray,
        weight: float,
        requested: np.ndarray,
        applied: RowView,
        tick: int,
        out: np.ndarray,
    ) -> None:
        """:meth:`step` in place over a frame's interval, with the wrench of the interval's mean
        forces written into an AppliedWrench row (the frame's path,
        :func:`~testbed.vehicle.systems.actuate_thrusters`; one compiled call,
        :func:`~testbed.vehicle.thrust_kernels.actuate_rows`).

        The kernel is called without numba's type checks (:func:`testbed.common.jit.entry`):
        every array is contiguous float64 (the mark int64), as the frame's are.

        Args:
            commanded_forces_n: (n,) float64 command held over the interval [N].
            dt_s: the interval [s], >= 0.
            matrix: (6, n) the thrusters' configuration T [N, N·m per N], body FRD.
            weight: the end forces' weight in the interval's mean force
                (:func:`~testbed.vehicle.systems.mean_force_weight`).
            requested: (6,) the wrench that was asked for [N, N·m] (the row's first half).
            applied: the AppliedWrench row, marked at ``tick`` when it changed.
            tick: the running system's world tick.
            out: (6,) float64, written with the interval's wrench [N, N·m], FRD.

        Raises:
            ValueError: negative dt_s.
        """
        _ACTUATE_ROWS(
            self._forces,
            self._start,
            commanded_forces_n,
            self._gain,
            self._held,
            self._blend_over(dt_s),
            matrix,
            weight,
            requested,
            applied.values,
            applied.mark,
            tick,
            out,
        )

    def _blend_over(self, dt_s: float) -> float:
        """:func:`lag_blend` of ``dt_s`` and τ (the last one kept: the frame interval is almost
        always the same).

        Raises:
            ValueError: negative dt_s.
        """
        tau = self.time_constant_s
        last_dt, last_tau, blend = self._blend
        if dt_s != last_dt or tau != last_tau:
            if not dt_s >= 0.0:
                raise ValueError(f"dt_s must be >= 0, got {dt_s}")
            blend = lag_blend(dt_s, tau)
            self._blend = (dt_s, tau, blend)
        return blend

    def _check_index(self, index: int) -> None:
        if not 0 <= index < self.n_thrusters:
            raise IndexError(f"thruster index {index} out of range 0..{self.n_thrusters - 1}")
