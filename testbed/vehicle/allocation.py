"""Generalised thruster allocation (ECS paper §IV): f = T⁺m, then the vehicle's limits.

:class:`Allocator` turns a requested body wrench m (6,) [N, N·m], FRD, rows X Y Z K M N, into
per-thruster forces, PWM pulses and currents for any :class:`ThrusterConfig`:

1. f = T⁺m, T⁺ the SVD pseudoinverse with singular values below 1e-5 × the largest dropped,
   computed once per configuration / failure set (never per call). ``method="lsq"`` instead
   solves the bounded least-squares problem min ‖T f - m‖ on the thrusters' force limits when
   T⁺m would saturate (scipy ``lsq_linear``, BVLS).
2. Saturation: if a thruster would exceed its asymmetric T200 limit (+36.40 / -28.65 N at
   12 V), the whole f is scaled by the worst thruster's f_max / f_req, keeping the wrench's
   direction.
3. Current limit: if Σ I(f_i) exceeds the budget, f is scaled by the largest common α with
   Σ I(α f_i) ≤ I_max, found by Illinois regula falsi (the paper uses a binary search,
   mate-rov a bracket + regula falsi); the result is within 0.01 A below the budget.
4. Slew limit (when ``dt_s`` is given): |f - f_prev| ≤ slew · dt per thruster. If that lets
   Σ I exceed the budget (one thruster slewing down slowly while another ramps up), the
   current limit is applied again and wins.

Failures reconfigure at run time without rebuilding: a dead or stuck thruster's column leaves
T and T⁺ is recomputed; a stuck thruster's constant wrench is subtracted from each request and
its current from the budget; a degraded thruster's column is scaled by its factor. The axis
maxima (how far the vehicle can push along each axis, for pilot scaling) are recomputed.

The arithmetic of steps 1-4 is one compiled implementation (:mod:`.thrust_kernels`), called
by :meth:`Allocator.step` (the per-frame path) and so by :meth:`Allocator.allocate`, and by the
axis-maxima probe; this class holds the configuration, the failures, the limits and the
validation. The linear algebra over the layout (T and T⁺ under the failures, computed once per
configuration; the bounded least-squares solve; the axis maxima) is :mod:`.allocation_geometry`.

This is the controller's model of the thrusters; ``thrusters.ThrusterDynamics`` is the plant.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np

from testbed.common import jit
from testbed.common.jit import CONST_TABLE, I64, MARK, MARKS, TABLE, VECTOR
from testbed.vehicle.allocation_geometry import effective_layout, probe_axis_maxima, solve_bounded
from testbed.vehicle.t200 import T200
from testbed.vehicle.thrust_kernels import (
    FORCES,
    PREVIOUS,
    PWM_OFFSET,
    PWM_SIGN,
    STUCK,
    allocate_pinv,
    allocate_rows,
    limit_forces,
    pinv_forces,
    put_output,
    sum_rows,
    total_current,
)
from testbed.vehicle.thruster_config import ThrusterConfig
from testbed.vehicle.thrusters import FaultMode, ThrusterFault

if TYPE_CHECKING:
    from testbed.ecs.store import RowView, Table

__all__ = [
    "CURRENT_TOLERANCE_A",
    "AllocationMethod",
    "Allocator",
    "ThrusterCommand",
]

CURRENT_TOLERANCE_A = 0.01
"""A binding current limit is met to within this [A], from below."""

AllocationMethod = Literal["pinv", "lsq"]

# The frame's allocation kernel, called without numba's dispatcher (testbed.common.jit.entry):
# the store's intents and rows and the allocator's own arrays, contiguous float64 (int64 marks;
# the T200 tables read-only).
_ALLOCATE_ROWS = jit.entry(
    allocate_rows,
    TABLE,
    MARKS,
    VECTOR,
    VECTOR,
    TABLE,
    VECTOR,
    TABLE,
    TABLE,
    CONST_TABLE,
    CONST_TABLE,
    VECTOR,
    MARK,
    I64,
    VECTOR,
)


@dataclass(frozen=True, slots=True, eq=False)
class ThrusterCommand:
    """One allocation result. Arrays are read-only; ``==`` is identity (they hold arrays).

    Attributes:
        forces_n: (n,) force commanded to each thruster [N] (stuck: its held force; dead: 0).
        pwm_us: (n,) PWM pulse for each thruster [µs], handedness applied.
        currents_a: (n,) expected current of each thruster [A].
        achieved_wrench: (6,) body wrench [N, N·m], FRD, the thrusters are expected to give
            (degraded factors and stuck forces included).
        scale: the common factor applied for saturation × current limit (1 if neither bound;
            ``method="lsq"`` reports 1 for its bounded solution; a later slew limit or second
            current limit is not included).
    """

    forces_n: np.ndarray
    pwm_us: np.ndarray
    currents_a: np.ndarray
    achieved_wrench: np.ndarray
    scale: float

    @property
    def total_current_a(self) -> float:
        """Σ currents [A]."""
        return float(self.currents_a.sum())


class Allocator:
    """Maps body wrench requests to thruster commands for one thruster configuration.

    Args:
        config: the thruster layout (body FRD).
        t200: the thruster curves (all thrusters are T200s).
        method: ``"pinv"`` (fast, the paper's f = T⁺m with direction-keeping scaling) or
            ``"lsq"`` (bounded least squares when T⁺m saturates; slower, scipy).
        current_limit_a: total current budget [A]; default ``config.current_budget_a``.
        slew_limit_n_per_s: per-thruster force rate limit [N/s], applied when ``allocate`` is
            given ``dt_s``; default ``config.slew_limit_n_per_s`` (``math.inf`` disables it).

    Raises:
        ValueError: unknown method or a non-positive limit.
    """

    def __init__(
        self,
        config: ThrusterConfig,
        t200: T200,
        *,
        method: AllocationMethod = "pinv",
        current_limit_a: float | None = None,
        slew_limit_n_per_s: float | None = None,
    ) -> None:
        if method not in ("pinv", "lsq"):
            raise ValueError(f"method must be 'pinv' or 'lsq', got {method!r}")
        self.config = config
        self.t200 = t200
        self.method: AllocationMethod = method
        self._n = config.n_thrusters
        self._names = config.names
        self._matrix = config.matrix
        n = self._n
        # the T200's (2, k) tables and one (3, n) row set per thruster: the kernels' layouts
        self._current_table = t200.current_table
        self._pwm_table = t200.inverse_table
        self._thrusters = np.zeros((3, n))
        ccw = config.ccw_mask
        self._thrusters[PWM_SIGN] = np.where(ccw, -1.0, 1.0)  # pwm = sign · pulse + offset
        self._thrusters[PWM_OFFSET] = np.where(ccw, 3000.0, 0.0)
        self._work = np.zeros((4, n))
        self._output = self._work[:3]
        self._output.setflags(write=False)  # a read-only view; the kernels write the base
        self._f_lo, self._f_hi = t200.force_limits_n
        self._current_limit_a = _positive(
            config.current_budget_a if current_limit_a is None else current_limit_a,
            "current_limit_a",
        )
        self._slew = _positive(
            config.slew_limit_n_per_s if slew_limit_n_per_s is None else slew_limit_n_per_s,
            "slew_limit_n_per_s",
        )
        self._failures: dict[int, ThrusterFault] = {}
        self._axis_maxima: np.ndarray | None = None
        # allocate_rows' limits: f_lo, f_hi, the slew step (set per call), cap, tolerance
        self._limits = np.array(
            [self._f_lo, self._f_hi, -1.0, 0.0, CURRENT_TOLERANCE_A], dtype=np.float64
        )
        self._rebuild()
        # Compile (or load from numba's cache) step's kernel now, on a scratch copy of the work
        # rows, not inside a timed run (the frame's own, allocate_rows, is bound at import).
        allocate_pinv(
            np.zeros(6),
            self._layout.stuck_wrench,
            self._layout.pinv,
            self._f_lo,
            self._f_hi,
            -1.0,
            self._cap_active,
            CURRENT_TOLERANCE_A,
            self._work.copy(),
            self._thrusters,
            self._current_table,
            self._pwm_table,
        )

    # ----------------------------------------------------------------- properties

    @property
    def n_thrusters(self) -> int:
        """Number of thrusters n (failed ones included)."""
        return self._n

    @property
    def current_limit_a(self) -> float:
        """Total current budget [A]."""
        return self._current_limit_a

    @property
    def slew_limit_n_per_s(self) -> float:
        """Per-thruster force rate limit [N/s]."""
        return self._slew

    @property
    def matrix(self) -> np.ndarray:
        """(6, n) effective T [N, N·m per N]: dead columns zero, degraded ones scaled (a copy)."""
        return self._layout.matrix.copy()

    @property
    def pinv(self) -> np.ndarray:
        """(n, 6) T⁺ of the thrusters the allocator can command (a copy)."""
        return self._layout.pinv.copy()

    @property
    def rank(self) -> int:
        """Numerical rank of the commandable part of T (6 = every axis independent)."""
        return self._layout.rank

    @property
    def failures(self) -> dict[int, ThrusterFault]:
        """Known failures by thruster index (a copy)."""
        return dict(self._failures)

    # ----------------------------------------------------------------- configuration

    def set_current_limit(self, current_limit_a: float) -> None:
        """Change the total current budget [A]; the axis maxima follow."""
        self._current_limit_a = _positive(current_limit_a, "current_limit_a")
        self._rebuild()

    def set_failure(self, thruster: int | str, mode: FaultMode, value: float = 0.0) -> None:
        """Tell the allocator a thruster has failed; T⁺ and the axis maxima are recomputed.

        Args:
            thruster: column index or name.
            mode: ``"dead"`` (removed from T), ``"stuck"`` (removed from T; its force ``value``
                [N] is subtracted from every request and its current from the budget) or
                ``"degraded"`` (its column scaled by the factor ``value`` in [0, 1]).
            value: the stuck force [N] or the degraded factor; ignored when dead.

        Raises:
            IndexError / KeyError: unknown thruster. ValueError: bad mode or value.
        """
        index = self._index(thruster)
        fault = ThrusterFault(mode, 0.0 if mode == "dead" else float(value))
        if mode == "stuck" and not self._f_lo <= fault.value <= self._f_hi:
            raise ValueError(
                f"stuck force must be within [{self._f_lo}, {self._f_hi}] N, got {fault.value}"
            )
        self._failures[index] = fault
        self._rebuild()

    def clear_failure(self, thruster: int | str | None = None) -> None:
        """Return a thruster (every thruster when None) to service; T⁺ is recomputed."""
        if thruster is None:
            self._failures.clear()
        else:
            self._failures.pop(self._index(thruster), None)
        self._rebuild()

    def reset(self) -> None:
        """Forget the previous command (the slew limit starts again from 0 N)."""
        self._work[PREVIOUS] = 0.0

    # ----------------------------------------------------------------- allocation

    def allocate(
        self, wrench: Sequence[float] | np.ndarray, dt_s: float | None = None
    ) -> ThrusterCommand:
        """Thruster commands for a requested body wrench (:meth:`step`, packaged).

        Args:
            wrench: (6,) requested body wrench [N, N·m], FRD, rows X Y Z K M N.
            dt_s: time since the previous command [s]; when given, the slew limit applies.

        Returns:
            The commands and the wrench they are expected to achieve.

        Raises:
            ValueError: wrench not 6 finite numbers, or dt_s not > 0.
        """
        scale = self.step(wrench, dt_s)
        rows = self._work[:3].copy()
        rows.setflags(write=False)  # and so are the row views below
        forces, pwm, currents = rows
        achieved = self._layout.matrix @ forces
        achieved.setflags(write=False)
        return ThrusterCommand(forces, pwm, currents, achieved, scale)

    def step(self, wrench: Sequence[float] | np.ndarray, dt_s: float | None = None) -> float:
        """Allocate a requested body wrench; the commands are left in :attr:`output`.

        The allocation itself (the per-frame path; :meth:`allocate` packages its result): f =
        T⁺(m − m_stuck) (:func:`~testbed.vehicle.thrust_kernels.pinv_forces`), the bounded
        least-squares solution instead when ``method="lsq"`` and T⁺m saturates, then
        saturation, current and slew limits, stuck forces, PWM and currents
        (:func:`~testbed.vehicle.thrust_kernels.limit_forces`); for ``"pinv"`` the two in one
        compiled call (:func:`~testbed.vehicle.thrust_kernels.allocate_pinv`).

        Args:
            wrench: (6,) requested body wrench [N, N·m], FRD, rows X Y Z K M N.
            dt_s: time since the previous command [s]; when given, the slew limit applies.

        Returns:
            The common factor applied for saturation × current limit (see
            :attr:`ThrusterCommand.scale`).

        Raises:
            ValueError: wrench not 6 finite numbers, or dt_s not > 0.
        """
        m = np.asarray(wrench, dtype=np.float64)
        if m.shape != (6,):
            raise ValueError(f"wrench must have shape (6,), got {m.shape}")
        if dt_s is None:
            slew_step = -1.0
        elif dt_s > 0.0:
            slew_step = self._slew * dt_s
        else:
            raise ValueError(f"dt_s must be > 0, got {dt_s}")
        work = self._work
        layout = self._layout
        if self.method == "pinv":  # the common case, one compiled call
            scale = allocate_pinv(
                m,
                layout.stuck_wrench,
                layout.pinv,
                self._f_lo,
                self._f_hi,
                slew_step,
                self._cap_active,
                CURRENT_TOLERANCE_A,
                work,
                self._thrusters,
                self._current_table,
                self._pwm_table,
            )
            if scale != scale:
                raise ValueError(f"wrench must be finite, got {m.tolist()}")
            return scale
        worst = pinv_forces(
            m, layout.stuck_wrench, layout.pinv, self._f_lo, self._f_hi, work[FORCES]
        )
        if worst != worst:
            raise ValueError(f"wrench must be finite, got {m.tolist()}")
        if worst > 1.0:
            work[FORCES] = solve_bounded(layout, m - layout.stuck_wrench, (self._f_lo, self._f_hi))
            worst = 1.0
        return limit_forces(
            work,
            worst,
            slew_step,
            self._cap_active,
            CURRENT_TOLERANCE_A,
            self._thrusters,
            self._current_table,
            self._pwm_table,
        )

    def step_rows(
        self,
        intents: Table,
        dt_s: float,
        requested: np.ndarray,
        output: RowView,
        tick: int,
        commanded: np.ndarray,
    ) -> float:
        """:meth:`step` of the sum of a force-intent table's live rows, written into a
        ThrusterOutput row (the frame's path, :func:`~testbed.vehicle.systems.allocate_thrust`).

        Args:
            intents: the table of the frame's force intents: (rows, 6) wrenches [N, N·m], FRD,
                summed in row order (:func:`~testbed.vehicle.thrust_kernels.sum_rows`).
            dt_s: time since the previous command [s] (> 0; the slew limit applies).
            requested: (6,) receives the sum.
            output: the ThrusterOutput row (forces, PWM, currents, scale), marked at ``tick``
                when a value changed (:mod:`testbed.ecs.store`'s write rule).
            tick: the running system's world tick.
            commanded: (n,) receives the commanded forces [N].

        Returns:
            The scale, as :meth:`step`.

        Raises:
            ValueError: a sum that is not finite, or dt_s not > 0.
        """
        if not dt_s > 0.0:
            raise ValueError(f"dt_s must be > 0, got {dt_s}")
        if self.method == "pinv":  # the common case, one compiled call
            limits = self._limits
            limits[2] = self._slew * dt_s
            scale = _ALLOCATE_ROWS(
                intents.values,
                intents.marks,
                requested,
                self._layout.stuck_wrench,
                self._layout.pinv,
                limits,
                self._work,
                self._thrusters,
                self._current_table,
                self._pwm_table,
                output.values,
                output.mark,
                tick,
                commanded,
            )
            if scale != scale:
                raise ValueError(f"wrench must be finite, got {requested.tolist()}")
            return scale
        sum_rows(intents.values, intents.marks, requested)
        scale = self.step(requested, dt_s)
        put_output(self._work, scale, output.values, output.mark, tick, commanded)
        return scale

    @property
    def output(self) -> np.ndarray:
        """(3, n) the last :meth:`step`'s commands: forces [N], PWM [µs], currents [A] (a
        read-only view, overwritten by the next step)."""
        return self._output

    def axis_maxima_signed(self) -> np.ndarray:
        """(2, 6) largest pure wrench along +e_k (row 0) and -e_k (row 1) [N, N·m], FRD.

        mate-rov's probe (:func:`~testbed.vehicle.allocation_geometry.probe_axis_maxima`) of
        the layout under the known failures, up to the first thruster limit or the current
        budget (less the stuck thrusters' current); an axis T⁺ cannot deliver reports 0.
        Computed once per configuration (read-only).
        """
        if self._axis_maxima is None:
            self._axis_maxima = probe_axis_maxima(
                self._layout,
                (self._f_lo, self._f_hi),
                self._current_table,
                self._cap_active,
                CURRENT_TOLERANCE_A,
            )
        return self._axis_maxima

    def axis_maxima(self) -> np.ndarray:
        """(6,) largest pure wrench [N, N·m] available in *both* directions of each axis.

        The smaller of :meth:`axis_maxima_signed`'s two rows: what a symmetric stick can be
        scaled to. An uncontrollable axis (pitch on the standard BlueROV2) reports 0.
        """
        both: np.ndarray = np.min(self.axis_maxima_signed(), axis=0)
        return both

    # ----------------------------------------------------------------- internals

    def _index(self, thruster: int | str) -> int:
        if isinstance(thruster, str):
            return self.config.index_of(thruster)
        if not 0 <= thruster < self._n:
            raise IndexError(f"thruster index {thruster} out of range 0..{self._n - 1}")
        return int(thruster)

    def _rebuild(self) -> None:
        """Recompute the effective layout (T_eff, T⁺, the stuck offsets) and the current budget
        left for the commandable thrusters after a change."""
        layout = self._layout = effective_layout(self._matrix, self._failures)
        self._thrusters[STUCK] = layout.stuck_forces
        stuck_current = total_current(layout.stuck_forces, 1.0, self._current_table)  # 0 A at 0 N
        self._cap_active = self._current_limit_a - stuck_current
        self._limits[3] = self._cap_active
        self._work[PREVIOUS] *= layout.commandable
        self._axis_maxima = None


def _positive(value: float, name: str) -> float:
    value = float(value)
    if not value > 0.0:
        raise ValueError(f"{name} must be > 0, got {value}")
    return value
