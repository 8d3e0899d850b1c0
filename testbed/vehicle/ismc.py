"""Angler's integral sliding-mode velocity controller (ISMC): body twist setpoint → body wrench.

The law (Angler, Palmer et al.; REFERENCE §3.7; Utkin & Shi 1996), per body axis of
ν = (u v w p q r) with the desired acceleration 0::

    v_e = v_cmd − ν                                    velocity error [m/s, rad/s]
    s   = v_e − v_e(0) + Kp·∫₀ᵗ v_e dt                  sliding variable, s(0) = 0
    τ   = M·(Kp·v_e) + C(ν)ν + D(ν)ν + g(η) + ρ·tanh(s/λ)

``v_e(0)`` is stored by the first :meth:`IsmcController.update` after :meth:`~IsmcController.
reset` (arming), where the integral is empty, so ``s = 0`` there exactly. REFERENCE §3.7 and
the paper's eq. 13 print ``− Kp·v_e(0)``; integrating the paper's own eqs. 11–12
(σ = C·v_e, ż = v̇_e + Kp·v_e − C·v̇_e, z(0) = −C·v_e(0)) gives ``− v_e(0)``, and only that
meets its assumption s(0) = 0 unless Kp = I. Both have ṡ = v̇_e + Kp·v_e (eq. 14). The
integral is stepped by forward Euler (the previous update's v_e times dt): with the wrench
held over each period that keeps s on the surface of a perfectly modelled plant
(:meth:`IsmcController.update`).

Closed loop on a plant M ν̇ + C(ν)ν + D(ν)ν + g(η) = τ + d (d: an unmodelled generalised
force about CO) whose model the controller otherwise knows:
M ṡ = −d − ρ·tanh(s/λ). With ``|d| < ρ`` per axis (M diagonal) s settles at −λ·atanh(d/ρ),
ṡ → 0 and so v̇_e + Kp·v_e → 0: no steady velocity error. With ρ = 0 (the nominal
computed-torque law alone) the error settles at v_e = −(M·Kp)⁻¹·d. For |s| ≪ λ the robust
term is the linear ρ/λ·s: a PI law whose integral time constant M·λ/ρ is ≈ 100–200 s with
the packaged gains (λ = 100–200).

The model terms are **not** a second copy of Fossen's law: n(ν, η) = C(ν)ν + D(ν)ν + g(η) is
−M·ν̇_free, with ν̇_free from :func:`~testbed.vehicle.plant_kernels.fossen_acceleration` at
zero wrench and zero current on the controller's own :class:`~.hydrodynamics.HydroModel`
(fully submerged), so τ = M·(Kp·v_e − ν̇_free) + ρ·tanh(s/λ) is one matrix product. Model
mismatch is a different HydroModel (:func:`mismatched_model`).

Frames: world NED, body FRD throughout; ν at the body origin CO. τ above is the generalised
force about CO; the returned wrench has its moment about the CoG (what the allocator and
``fossen_acceleration`` take): moment_CoG = moment_CO − r_g × F. Angler (ROS) works in FLU
and converts its wrench to FRD before the thruster allocation; here every input and output is
FRD already, so nothing is converted, and the gains, per-axis magnitudes, are the same in
either frame.

The gains per vehicle model are package data (``data/ismc.toml``, :func:`load_ismc_gains`).
Pure: no ECS, no randomness, no pybullet. The law itself runs compiled on the controller's state
array (:mod:`testbed.vehicle.ismc_kernels`), called once a control period.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from importlib import resources

import numpy as np

from testbed.common import jit
from testbed.common.jit import CONST_VECTOR, F64, TABLE, VECTOR, floats
from testbed.config import build, check, check_range, check_ranges, load_toml, named_table
from testbed.vehicle.hydrodynamics import HydroModel, coefficients
from testbed.vehicle.ismc_kernels import (
    ARMED,
    INTEGRAL,
    ROBUST,
    SLIDING,
    STATE_SIZE,
    ismc_step,
)

__all__ = [
    "IsmcController",
    "IsmcGains",
    "known_ismc_models",
    "load_ismc_gains",
    "mismatched_model",
]

Vec3 = tuple[float, float, float]
Vec6 = tuple[float, float, float, float, float, float]

MAX_KP_1_S = 1000.0
"""Largest accepted Kp [1/s]: 100× the packaged gains."""


@functools.cache
def _ismc_step() -> Callable[..., Vec6]:
    """:func:`~.ismc_kernels.ismc_step`'s entry, compiled (or loaded from numba's disk cache)
    when the first controller is built, not when this module is imported: only vehicles with
    an ISMC need it."""
    return jit.entry(
        ismc_step,
        CONST_VECTOR,
        TABLE,
        floats(3),
        floats(6),
        F64,
        F64,
        VECTOR,
        floats(6),
        floats(6),
        floats(3),
        F64,
    )


"""The law without numba's dispatcher (the model's read-only coefficients, its mass matrix
and the controller's state are its own contiguous float64 arrays)."""


@dataclass(frozen=True, slots=True)
class IsmcGains:
    """Gains of the ISMC (module docstring), one vehicle model's row of REFERENCE §3.7.

    Attributes:
        kp: (6,) Kp per body axis (u v w p q r) [1/s], in (0, 1000]: the error's decay rate on
            the sliding surface, e(t) = e(0)·exp(−Kp·t).
        rho: switching gain ρ [N on the forces, N·m on the torques], in [0, 1e4]; it must
            exceed the unmodelled wrench per axis for the error to vanish (0 = the nominal
            computed-torque law alone).
        lambda_: boundary-layer width λ of tanh(s/λ) [m/s, rad/s: the unit of s], in
            (0, 1e4].
        rate_hz: the rate the controller runs at [Hz], in (0, 1000]; it is the scheduler's to
            honour (``update`` takes its own ``dt_s``).
        source: where the figures come from.
    """

    kp: Vec6
    rho: float
    lambda_: float
    rate_hz: float
    source: str = ""

    def __post_init__(self) -> None:
        check_ranges(self.kp, "kp", 0.0, MAX_KP_1_S, "1/s", low_open=True)
        check_range(self.rho, "rho", 0.0, 1e4, "N")
        check_range(self.lambda_, "lambda_", 0.0, 1e4, low_open=True)
        check_range(self.rate_hz, "rate_hz", 0.0, 1000.0, "Hz", low_open=True)

    @property
    def period_s(self) -> float:
        """1 / rate_hz [s]."""
        return 1.0 / self.rate_hz


def _gains_file() -> resources.abc.Traversable:
    return resources.files("testbed.vehicle").joinpath("data", "ismc.toml")


def _gains_tables() -> tuple[str, dict[str, object]]:
    with resources.as_file(_gains_file()) as path:
        return str(path), load_toml(path)


def known_ismc_models() -> list[str]:
    """Vehicle model names with a gains table in ``testbed/vehicle/data/ismc.toml``."""
    return sorted(_gains_tables()[1])


def load_ismc_gains(model_name: str) -> IsmcGains:
    """The packaged ISMC gains of one vehicle model (``data/ismc.toml``, table ``model_name``).

    Args:
        model_name: a vehicle model name, as :func:`~.hydrodynamics.load_model` takes.

    Raises:
        ConfigError: no table of that name (the message names the file and the known ones),
            or a bad table (unknown key, out-of-range value; file and dotted key named).
    """
    path, tables = _gains_tables()
    table = named_table(tables, model_name, path, "ISMC gains")
    return build(IsmcGains, table, source=path, prefix=f"{model_name}.")


def mismatched_model(
    model: HydroModel,
    *,
    mass_scale: float = 1.0,
    damping_scale: float = 1.0,
    added_mass_scale: float = 1.0,
    buoyancy_offset_n: float = 0.0,
) -> HydroModel:
    """A copy of ``model`` with its parameters off by the given factors: a controller's belief.

    ``mass_scale`` scales the mass, the weight and the inertia together (the same body,
    uniformly denser); ``damping_scale`` the linear and quadratic damping; ``added_mass_scale``
    the added masses; ``buoyancy_offset_n`` adds to the buoyancy. Geometry is unchanged.

    Args:
        model: the true model.
        mass_scale: factor on m, W and the inertia, in (0, 10].
        damping_scale: factor on every damping derivative, in [0, 10].
        added_mass_scale: factor on every added mass, in [0, 10].
        buoyancy_offset_n: added to B [N], in [−1000, 1000]; B must stay ≥ 0.

    Raises:
        FieldError: a factor or the offset out of range (a ValueError).
    """
    check_range(mass_scale, "mass_scale", 0.0, 10.0, low_open=True)
    check_range(damping_scale, "damping_scale", 0.0, 10.0)
    check_range(added_mass_scale, "added_mass_scale", 0.0, 10.0)
    check_range(buoyancy_offset_n, "buoyancy_offset_n", -1000.0, 1000.0, "N")
    buoyancy = model.buoyancy_n + buoyancy_offset_n
    check(buoyancy >= 0.0, "buoyancy_offset_n", f"leaves buoyancy < 0 ({buoyancy} N)")

    note = (
        f"mismatched: mass x{mass_scale:g}, damping x{damping_scale:g}, "
        f"added mass x{added_mass_scale:g}, buoyancy {buoyancy_offset_n:+g} N"
    )
    return dataclasses.replace(
        model,
        source=f"{model.source}; {note}",
        mass_kg=model.mass_kg * mass_scale,
        weight_n=model.weight_n * mass_scale,
        buoyancy_n=buoyancy,
        inertia_kg_m2=_scaled3(model.inertia_kg_m2, mass_scale),
        added_mass=_scaled6(model.added_mass, added_mass_scale),
        linear_damping=_scaled6(model.linear_damping, damping_scale),
        quadratic_damping=_scaled6(model.quadratic_damping, damping_scale),
    )


def _scaled3(values: Sequence[float], factor: float) -> Vec3:
    x, y, z = values
    return (factor * x, factor * y, factor * z)


def _vec6(values: Sequence[float]) -> Vec6:
    a, b, c, d, e, f = values
    return (float(a), float(b), float(c), float(d), float(e), float(f))


def _scaled6(values: Sequence[float], factor: float) -> Vec6:
    return _vec6([factor * x for x in values])


class IsmcController:
    """The ISMC's state: v_e(0) at arming and ∫v_e (module docstring for the law and frames).

    The law runs compiled (:func:`~testbed.vehicle.ismc_kernels.ismc_step`) on the state array
    :attr:`state`; this class holds the model, the gains and the checks of the inputs.

    Attributes:
        model: the controller's model of the vehicle (its belief, not the plant's truth).
        gains: the gains.
        state: (:data:`~.ismc_kernels.STATE_SIZE`,) the kernel's state: v_e(0), the last v_e,
            ∫v_e, s, ρ·tanh(s/λ) and whether armed (:mod:`~testbed.vehicle.ismc_kernels`).
    """

    __slots__ = ("_coefficients", "_cog", "_kp", "_mass", "_step", "gains", "model", "state")

    def __init__(self, model: HydroModel, gains: IsmcGains) -> None:
        self.model = model
        self.gains = gains
        self._step = _ismc_step()
        self._coefficients = coefficients(model)
        self._mass = np.ascontiguousarray(model.mass_matrix, dtype=np.float64)
        x, y, z = model.cog_m
        self._cog = (float(x), float(y), float(z))
        self._kp = _vec6(gains.kp)
        self.state = np.zeros(STATE_SIZE)

    @property
    def armed(self) -> bool:
        """True once an update has stored v_e(0) since the last :meth:`reset`."""
        return bool(self.state[ARMED] != 0.0)

    @property
    def sliding(self) -> Vec6:
        """(6,) s of the last update [m/s, rad/s] (zeros before the first)."""
        return _vec6(self.state[SLIDING : SLIDING + 6].tolist())

    @property
    def integral(self) -> Vec6:
        """(6,) ∫v_e dt since arming [m, rad]."""
        return _vec6(self.state[INTEGRAL : INTEGRAL + 6].tolist())

    @property
    def robust(self) -> Vec6:
        """(6,) the last ρ·tanh(s/λ) [N, N·m], about CO."""
        return _vec6(self.state[ROBUST : ROBUST + 6].tolist())

    def reset(self) -> None:
        """Disarm: forget v_e(0) and the integral; the next update arms (s = 0 there)."""
        self.state[:] = 0.0

    def update(
        self,
        v_cmd: Sequence[float],
        v: Sequence[float],
        down_body: Sequence[float],
        dt_s: float,
    ) -> Vec6:
        """One control step: the body wrench that drives ν towards ``v_cmd``.

        The first update after :meth:`reset` arms: it stores v_e(0), leaves the integral at 0
        (so s = 0 exactly) and ignores ``dt_s``. Later ones first add the previous update's
        v_e times ``dt_s`` to the integral (forward Euler: the error the held wrench was
        computed from). With the wrench held over the period, the sampled sliding dynamics are
        then the forward-Euler step of M ṡ = −d − ρ·tanh(s/λ), and s stays 0 on a perfect
        model; adding the new v_e instead would drift s by Kp·dt·(v_e − v_e(0)) (−0.02 m/s
        after a 0.2 m/s step at Kp·dt = 0.1), a bias the robust term would then fight.

        Args:
            v_cmd: (6,) commanded body twist (u v w p q r) [m/s, rad/s], FRD, at CO.
            v: (6,) measured body twist, same frame.
            down_body: (3,) the world's down unit vector in the body, Rᵀ·(0, 0, 1), FRD, from
                the attitude estimate (what ``fossen_acceleration`` takes).
            dt_s: time since the previous update [s], > 0.

        Returns:
            (6,) body wrench (X Y Z K M N) [N, N·m], FRD, moments about the CoG.

        Raises:
            ValueError: ``dt_s`` is not a positive finite number (after arming), or a vector
                has the wrong length.
        """
        state = self.state
        if state[ARMED] != 0.0 and not (dt_s > 0.0 and math.isfinite(dt_s)):
            raise ValueError(f"dt_s must be > 0 and finite, got {dt_s}")
        gx, gy, gz = down_body
        gains = self.gains
        return self._step(
            self._coefficients,
            self._mass,
            self._cog,
            self._kp,
            gains.rho,
            gains.lambda_,
            state,
            _vec6(v_cmd),
            _vec6(v),
            (float(gx), float(gy), float(gz)),
            float(dt_s),
        )
