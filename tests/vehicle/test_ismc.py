"""The ISMC (testbed.vehicle.ismc) against independent truth: Fossen's matrices written out in
tests/vehicle/fossen_matrices.py for its model terms, and closed forms for its closed loop.

Closed loop: plant M ν̇ + C(ν)ν + D(ν)ν + g(η) = τ + d, controller τ = M·Kp·v_e + C v + D v + g
+ ρ·tanh(s/λ) on the same model, v_e = v_cmd − ν, s = v_e − v_e(0) + Kp∫v_e. Then
M ν̇ = M·Kp·v_e + ρ·tanh(s/λ) + d and ṡ = v̇_e + Kp·v_e = −ν̇ + Kp·v_e, so

    M ṡ = −d − ρ·tanh(s/λ)

(the sign: d pushes ν up, v_e = v_cmd − ν down). Per axis with M diagonal (the Heavy: CoG at
CO) and |d| < ρ it is separable: with a = d, b = ρ, x = s/λ,
∫dx/(a + b·tanh x) = (a·x − b·ln(a·cosh x + b·sinh x))/(a² − b²), so
t(s) = −M·λ·[F(s/λ) − F(0)], and s → −λ·atanh(d/ρ). There ṡ = 0, so ė + Kp·e = 0: e → 0.
Without the robust term (ρ = 0): M·Kp·e_ss + d = 0, e_ss = −d/(M₁₁·Kp_x).
Perfect model, d = 0: s ≡ 0, so e(t) = e(0)·exp(−Kp·t) on every axis, coupled M included.

The closed-loop runs hold the wrench over each control period (zero-order hold) and step the
plant by RK4. The long runs integrate ``fossen_acceleration`` (fast) for the plant — the same
kernel the controller reads its model from, which the term-by-term test below checks against
Fossen's matrices — and the perfect-model run integrates the matrices themselves.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.optimize import brentq

from testbed.common.geometry import quat_from_euler, quat_normalize, rotation_matrix
from testbed.config import ConfigError, FieldError
from testbed.vehicle.hydrodynamics import HydroModel, coefficients, load_model
from testbed.vehicle.ismc import (
    IsmcController,
    IsmcGains,
    known_ismc_models,
    load_ismc_gains,
    mismatched_model,
)
from testbed.vehicle.plant_kernels import fossen_acceleration
from tests.vehicle import fossen_matrices

FloatArray = NDArray[np.float64]
Vec6 = tuple[float, float, float, float, float, float]
Quat = tuple[float, float, float, float]
Plant = Callable[[Vec6, Quat, Vec6], Sequence[float]]
ZERO6: Vec6 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
SURGE_D_N = 10.0


def kernel_plant(model: HydroModel) -> Plant:
    """ν̇ from the package's compiled right-hand side (fast: the long runs)."""
    c = coefficients(model)

    def acceleration(nu: Vec6, q: Quat, wrench: Vec6) -> Sequence[float]:
        down = rotation_matrix(q)[2]
        result: Sequence[float] = fossen_acceleration(c, nu, down, (0.0, 0.0, 0.0), 1.0, wrench)
        return result

    return acceleration


def matrix_plant(model: HydroModel) -> Plant:
    """ν̇ from Fossen's matrices (tests/vehicle/fossen_matrices.py)."""

    def acceleration(nu: Vec6, q: Quat, wrench: Vec6) -> Sequence[float]:
        rot = np.array(rotation_matrix(q))
        result: list[float] = fossen_matrices.body_acceleration(model, nu, rot, wrench).tolist()
        return result

    return acceleration


def _vec6(values: Sequence[float]) -> Vec6:
    a, b, c, d, e, f = values
    return (a, b, c, d, e, f)


def _derivative(plant: Plant, state: Sequence[float], wrench: Vec6) -> list[float]:
    """(ν̇, q̇) of the state (ν, q): Fossen's ν̇ and q̇ = ½·q⊗(0, ω)."""
    nu = _vec6(state[:6])
    w, x, y, z = state[6:]
    p, q, r = nu[3:]
    return [
        *plant(nu, (w, x, y, z), wrench),
        0.5 * (-x * p - y * q - z * r),
        0.5 * (w * p + y * r - z * q),
        0.5 * (w * q + z * p - x * r),
        0.5 * (w * r + x * q - y * p),
    ]


def rk4_step(plant: Plant, state: list[float], wrench: Vec6, dt_s: float) -> list[float]:
    """One RK4 step of (ν, q) with the wrench held; q renormalised."""

    def shifted(k: list[float], h: float) -> list[float]:
        return [x + h * y for x, y in zip(state, k, strict=True)]

    k1 = _derivative(plant, state, wrench)
    k2 = _derivative(plant, shifted(k1, dt_s / 2), wrench)
    k3 = _derivative(plant, shifted(k2, dt_s / 2), wrench)
    k4 = _derivative(plant, shifted(k3, dt_s), wrench)
    out = [
        x + dt_s / 6 * (a + 2 * b + 2 * c + d)
        for x, a, b, c, d in zip(state, k1, k2, k3, k4, strict=True)
    ]
    return out[:6] + list(quat_normalize(out[6:]))


def simulate(
    plant: Plant,
    controller: IsmcController,
    v_cmd: Vec6,
    *,
    dt_s: float,
    duration_s: float,
    disturbance_cog: Vec6 = ZERO6,
    q0: Quat = (1.0, 0.0, 0.0, 0.0),
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Closed loop from rest: (t (n,), ν (n, 6), s (n, 6)) at each control update."""
    controller.reset()
    state = [0.0] * 6 + list(q0)
    steps = round(duration_s / dt_s)
    times, nus, slides = [], [], []
    for k in range(steps):
        nu = _vec6(state[:6])
        down = rotation_matrix((state[6], state[7], state[8], state[9]))[2]
        tau = controller.update(v_cmd, nu, down, dt_s)
        times.append(k * dt_s)
        nus.append(nu)
        slides.append(controller.sliding)
        wrench = _vec6([a + b for a, b in zip(tau, disturbance_cog, strict=True)])
        state = rk4_step(plant, state, wrench, dt_s)
    return np.array(times), np.array(nus), np.array(slides)


def sliding_closed_form(t_s: float, mass: float, d: float, rho: float, width: float) -> float:
    """s(t) of M ṡ = −d − ρ·tanh(s/λ), s(0) = 0, 0 < d < ρ: the separable integral, inverted."""

    def big_f(x: float) -> float:
        return (d * x - rho * math.log(d * math.cosh(x) + rho * math.sinh(x))) / (d * d - rho * rho)

    def time_at(s: float) -> float:
        return -mass * width * (big_f(s / width) - big_f(0.0))

    s_inf = -width * math.atanh(d / rho)
    if t_s == 0.0:
        return 0.0
    return float(brentq(lambda s: time_at(s) - t_s, s_inf * (1.0 - 1e-12), 0.0, xtol=1e-14))


@pytest.fixture(scope="module")
def heavy() -> HydroModel:
    return load_model("bluerov2-heavy")


# --- arming and the model terms ----------------------------------------------------------------


def test_sliding_variable_is_exactly_zero_at_arming_and_rearming() -> None:
    model = load_model("bluerov2")
    gains = load_ismc_gains("bluerov2")  # Kp ≠ 1: the printed "− Kp·v_e(0)" would not give 0
    ctl = IsmcController(model, gains)
    rng = np.random.default_rng(7)
    for _ in range(3):
        v_cmd, v = rng.normal(0.0, 0.4, 6).tolist(), rng.normal(0.0, 0.4, 6).tolist()
        assert not ctl.armed
        ctl.update(v_cmd, v, (0.0, 0.0, 1.0), 0.01)
        assert ctl.armed
        assert ctl.sliding == ZERO6
        assert ctl.integral == ZERO6
        # the next step: s = v_e − v_e(0) + Kp·v_e(0)·dt (forward Euler of the integral)
        v2 = rng.normal(0.0, 0.4, 6).tolist()
        ctl.update(v_cmd, v2, (0.0, 0.0, 1.0), 0.01)
        expected = [
            (c - b) - (c - a) + k * (c - a) * 0.01
            for a, b, c, k in zip(v, v2, v_cmd, gains.kp, strict=True)
        ]
        assert ctl.sliding == pytest.approx(expected, abs=1e-15)
        ctl.reset()


def test_wrench_is_m_kp_error_plus_fossen_terms_moved_to_the_cog() -> None:
    """τ = M·Kp·v_e + C(ν)ν + D(ν)ν + g(η) about CO (s = 0 at arming), moment moved to the CoG,
    against the textbook matrices on a model with every coupling on."""
    base = load_model("bluerov2")
    model = dataclasses.replace(
        base,
        cog_m=(0.01, -0.015, 0.02),
        cob_m=(-0.005, 0.01, -0.01),
        inertia_kg_m2=(0.16, 0.21, 0.27),
        added_mass_coriolis="full",
    )
    gains = load_ismc_gains("bluerov2")
    rng = np.random.default_rng(3)
    for _ in range(5):
        nu = rng.normal(0.0, 0.3, 6)
        v_cmd = nu + rng.normal(0.0, 0.2, 6)
        q = quat_normalize(rng.normal(0.0, 1.0, 4).tolist())
        rot = np.array(rotation_matrix(q))
        ctl = IsmcController(model, gains)
        wrench = ctl.update(v_cmd.tolist(), nu.tolist(), rot[2].tolist(), 0.01)
        bias = (
            fossen_matrices.coriolis_rigid_body(model, nu) @ nu
            + fossen_matrices.coriolis_added_mass(model, nu) @ nu
            + fossen_matrices.damping_matrix(model, nu) @ nu
            + fossen_matrices.restoring_forces(model, rot)
        )
        tau_co = model.mass_matrix @ (np.array(gains.kp) * (v_cmd - nu)) + bias
        expected = np.concatenate([tau_co[:3], tau_co[3:] - np.cross(model.cog_m, tau_co[:3])])
        np.testing.assert_allclose(wrench, expected, rtol=1e-12, atol=1e-12)
        # and the plant, fed that wrench, accelerates as M ν̇ = M·Kp·v_e exactly
        nu_dot = fossen_matrices.body_acceleration(model, nu, rot, wrench)
        np.testing.assert_allclose(nu_dot, np.array(gains.kp) * (v_cmd - nu), atol=1e-10)


def test_update_rejects_bad_dt_after_arming() -> None:
    ctl = IsmcController(load_model("bluerov2"), load_ismc_gains("bluerov2"))
    ctl.update(ZERO6, ZERO6, (0.0, 0.0, 1.0), 0.0)  # arming ignores dt
    for dt in (0.0, -0.01, math.nan, math.inf):
        with pytest.raises(ValueError, match="dt_s"):
            ctl.update(ZERO6, ZERO6, (0.0, 0.0, 1.0), dt)


# --- closed loop against closed forms ----------------------------------------------------------


def test_perfect_model_error_decays_as_exp_minus_kp_t_on_every_axis() -> None:
    model = load_model("bluerov2")  # coupled M (CoG 2 cm below CO)
    gains = load_ismc_gains("bluerov2")
    ctl = IsmcController(model, gains)
    v_cmd: Vec6 = (0.3, -0.2, 0.15, 0.1, -0.1, 0.2)
    dt = 1e-3
    t, nu, s = simulate(matrix_plant(model), ctl, v_cmd, dt_s=dt, duration_s=0.4)
    error = np.array(v_cmd) - nu
    expected = np.array(v_cmd) * np.exp(-np.outer(t, gains.kp))
    # the hold's lag: e₀·(1 − Kp·dt)^k vs e₀·exp(−Kp·t) differ by ≤ e₀·Kp·dt/(2e) = 0.2 % here
    np.testing.assert_allclose(error, expected, rtol=0.0, atol=0.005 * 0.3)
    # s stays on the surface (it started there) but for the drift of C(ν)ν + D(ν)ν + g within
    # each held period, ½·dt·e(0)·∂n/∂ν / M ≈ 2e-4 here
    assert np.abs(s).max() < 1e-3


@pytest.mark.parametrize(
    ("width", "duration_s", "converged"),
    [(2.0, 40.0, True), (None, 20.0, False)],
    ids=["lambda-2", "packaged-lambda-200"],
)
def test_surge_disturbance_follows_the_sliding_closed_form_and_is_rejected(
    heavy: HydroModel, width: float | None, duration_s: float, converged: bool
) -> None:
    packaged = load_ismc_gains("bluerov2-heavy")  # Kp_x 10, ρ 20, λ 200
    gains = packaged if width is None else dataclasses.replace(packaged, lambda_=width)
    ctl = IsmcController(heavy, gains)
    m11 = heavy.mass_matrix[0, 0]  # 13.5 + 6.36 kg, decoupled (CoG at CO)
    v_cmd: Vec6 = (0.2, 0.0, 0.0, 0.0, 0.0, 0.0)
    d: Vec6 = (SURGE_D_N, 0.0, 0.0, 0.0, 0.0, 0.0)
    _, _, s = simulate(kernel_plant(heavy), ctl, v_cmd, dt_s=gains.period_s, duration_s=duration_s)
    t_d, nu_d, s_d = simulate(
        kernel_plant(heavy),
        ctl,
        v_cmd,
        dt_s=gains.period_s,
        duration_s=duration_s,
        disturbance_cog=d,
    )
    # undisturbed, s stays on the surface but for the damping's drift within each held period:
    # Σ ½·dt²·Kp·e_k·D′/M = ½·dt·e(0)·D′/M, D′ = ∂(D(u)u)/∂u = −X_u − 2·X_u|u|·|u| at 0.2 m/s
    slope = -heavy.linear_damping[0] - 2.0 * heavy.quadratic_damping[0] * v_cmd[0]
    assert np.abs(s).max() < 0.5 * gains.period_s * v_cmd[0] * slope / m11  # 1.9e-3 m/s
    lam = gains.lambda_
    s_inf = -lam * math.atanh(SURGE_D_N / gains.rho)
    picks = range(0, len(t_d), len(t_d) // 40)
    predicted = np.array(
        [sliding_closed_form(t_d[i], m11, SURGE_D_N, gains.rho, lam) for i in picks]
    )
    measured = s_d[list(picks), 0]
    scale = abs(predicted).max()
    assert np.abs(measured - predicted).max() < 0.01 * scale
    assert np.abs(nu_d[:, 1:]).max() < 1e-9  # the other axes stay still
    error = v_cmd[0] - nu_d[-1, 0]
    if converged:
        assert s_d[-1, 0] == pytest.approx(s_inf, rel=1e-3)
        assert abs(error) < 1e-3
    else:  # λ = 200: the robust term is a slow integral (M·λ/ρ ≈ 200 s); s is far from −λ·atanh
        assert abs(s_d[-1, 0]) < 0.2 * abs(s_inf)


def test_nominal_law_leaves_the_closed_form_steady_error(heavy: HydroModel) -> None:
    gains = dataclasses.replace(load_ismc_gains("bluerov2-heavy"), rho=0.0)
    ctl = IsmcController(heavy, gains)
    v_cmd: Vec6 = (0.2, 0.0, 0.0, 0.0, 0.0, 0.0)
    d: Vec6 = (SURGE_D_N, 0.0, 0.0, 0.0, 0.0, 0.0)
    _, nu, _ = simulate(
        kernel_plant(heavy), ctl, v_cmd, dt_s=gains.period_s, duration_s=2.0, disturbance_cog=d
    )
    e_ss = -SURGE_D_N / (heavy.mass_matrix[0, 0] * gains.kp[0])  # −10 / (19.86 · 10) m/s
    assert v_cmd[0] - nu[-1, 0] == pytest.approx(e_ss, rel=0.01)


def test_ismc_rejects_model_mismatch_that_the_nominal_law_does_not(heavy: HydroModel) -> None:
    belief = mismatched_model(
        heavy, mass_scale=1.05, damping_scale=0.7, added_mass_scale=0.8, buoyancy_offset_n=1.0
    )
    fast = dataclasses.replace(load_ismc_gains("bluerov2-heavy"), lambda_=2.0)
    v_cmd: Vec6 = (0.2, -0.1, 0.05, 0.0, 0.0, 0.1)
    q0 = quat_from_euler(0.05, -0.03, 0.3)
    finals = {}
    for rho in (fast.rho, 0.0):
        ctl = IsmcController(belief, dataclasses.replace(fast, rho=rho))
        _, nu, _ = simulate(
            kernel_plant(heavy), ctl, v_cmd, dt_s=fast.period_s, duration_s=40.0, q0=q0
        )
        finals[rho] = np.abs(np.array(v_cmd) - nu[-1]).max()
    assert finals[fast.rho] < 1e-3
    assert finals[0.0] > 1e-2


# --- gains, loader, mismatch knobs ---------------------------------------------------------------


def test_packaged_gains_are_reference_rows() -> None:
    assert known_ismc_models() == ["bluerov2", "bluerov2-heavy"]
    blue = load_ismc_gains("bluerov2")
    assert (blue.kp, blue.rho, blue.lambda_, blue.rate_hz) == ((5, 5, 5, 5, 5, 10), 15, 100, 100)
    heavy = load_ismc_gains("bluerov2-heavy")
    assert (heavy.kp, heavy.rho, heavy.lambda_) == ((10, 10, 6, 3, 6, 10), 20, 200)
    assert heavy.period_s == pytest.approx(0.01)
    assert "Heavy" in heavy.source and "BlueROV2" in blue.source


def test_unknown_model_names_the_file_and_the_known_ones() -> None:
    with pytest.raises(ConfigError, match=r"ismc\.toml: nope: .*known: bluerov2, bluerov2-heavy"):
        load_ismc_gains("nope")


def test_gains_are_validated() -> None:
    ok = load_ismc_gains("bluerov2")
    for change, key in (
        ({"kp": (0.0, 5.0, 5.0, 5.0, 5.0, 5.0)}, "kp[0]"),
        ({"rho": -1.0}, "rho"),
        ({"lambda_": 0.0}, "lambda_"),
        ({"rate_hz": math.nan}, "rate_hz"),
    ):
        with pytest.raises(FieldError, match=key.replace("[", r"\[").replace("]", r"\]")):
            dataclasses.replace(ok, **change)
    assert isinstance(IsmcGains(ok.kp, 0.0, 1.0, 50.0), IsmcGains)


def test_mismatched_model_scales_the_knobs(heavy: HydroModel) -> None:
    off = mismatched_model(
        heavy, mass_scale=1.2, damping_scale=0.5, added_mass_scale=2.0, buoyancy_offset_n=-3.0
    )
    assert off.mass_kg == pytest.approx(1.2 * heavy.mass_kg)
    assert off.weight_n == pytest.approx(1.2 * heavy.weight_n)
    assert off.inertia_kg_m2 == pytest.approx([1.2 * x for x in heavy.inertia_kg_m2])
    assert off.linear_damping == pytest.approx([0.5 * x for x in heavy.linear_damping])
    assert off.quadratic_damping == pytest.approx([0.5 * x for x in heavy.quadratic_damping])
    assert off.added_mass == pytest.approx([2.0 * x for x in heavy.added_mass])
    assert off.buoyancy_n == pytest.approx(heavy.buoyancy_n - 3.0)
    assert (off.cog_m, off.cob_m, off.name) == (heavy.cog_m, heavy.cob_m, heavy.name)
    assert mismatched_model(heavy) == dataclasses.replace(
        heavy, source=mismatched_model(heavy).source
    )
    with pytest.raises(FieldError, match="mass_scale"):
        mismatched_model(heavy, mass_scale=0.0)
    with pytest.raises(FieldError, match="buoyancy_offset_n"):
        mismatched_model(heavy, buoyancy_offset_n=-200.0)
