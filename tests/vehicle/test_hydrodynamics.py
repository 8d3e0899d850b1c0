"""Fossen model terms against first principles, published figures and Fossen's matrices (no
pybullet): the compiled right-hand side against tests/vehicle/fossen_matrices.py."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from testbed.config import ConfigError, build
from testbed.vehicle.hydrodynamics import (
    HydroModel,
    body_acceleration,
    known_models,
    load_model,
    submerged_fraction,
)
from testbed.vehicle.water_current import CurrentProcess, WaterCurrent
from tests.vehicle import fossen_matrices
from tests.vehicle.fossen_matrices import (
    coriolis_added_mass,
    coriolis_rigid_body,
    damping_matrix,
    restoring_forces,
    wrench_about_origin,
)

OPTIONS = ("full", "isotropic", "off")


@pytest.fixture(scope="module")
def wu() -> HydroModel:
    return load_model("bluerov2")


def off_centre(model: HydroModel) -> HydroModel:
    """A model with every coupling switched on: r_g and r_b off every axis, unequal inertia."""
    return dataclasses.replace(
        model,
        cog_m=(0.01, -0.015, 0.03),
        cob_m=(-0.005, 0.01, -0.01),
        inertia_kg_m2=(0.14, 0.19, 0.23),
    )


def test_packaged_models_carry_the_published_figures(wu: HydroModel) -> None:
    assert known_models() == ["bluerov2", "bluerov2-heavy"]
    # Wu 2018 (REFERENCE §3.2).
    assert wu.mass_kg == 11.5
    assert (wu.weight_n, wu.buoyancy_n) == (112.8, 114.8)
    assert wu.net_buoyancy_n == pytest.approx(2.0)
    assert wu.cog_m == (0.0, 0.0, 0.02)
    assert wu.added_mass == (-5.5, -12.7, -14.57, -0.12, -0.12, -0.12)
    assert wu.linear_damping == (-4.03, -6.22, -5.18, -0.07, -0.07, -0.07)
    # Surge and sway quadratic drag from bluerov2_gz's box (−½ρC_dA, REFERENCE §3.2): Wu's
    # −18.18/−21.66 miss Blue Robotics' 1.5 m/s rating (docs/vehicle.md); the rest are Wu's.
    assert wu.quadratic_damping == (-33.8, -54.269, -36.99, -1.55, -1.55, -1.55)
    assert wu.added_mass_coriolis == "isotropic"
    # von Benzon 2022 Table A1: B = ρ g ∇ with ∇ = 0.0134 m³, g = 9.82; W = m g.
    heavy = load_model("bluerov2-heavy")
    assert heavy.buoyancy_n == pytest.approx(1000.0 * 9.82 * 0.0134, abs=0.05)
    assert heavy.weight_n == pytest.approx(13.5 * 9.82, abs=0.05)
    assert heavy.cob_m == (0.0, 0.0, -0.01)
    assert heavy.added_mass[2] == -18.68
    assert heavy.quadratic_damping[:3] == (-58.42, -55.137, -190.0)  # bluerov2_gz's box, Z_w|w|
    assert heavy.added_mass_coriolis == "isotropic"


def test_unknown_model_lists_the_known_ones() -> None:
    with pytest.raises(ConfigError, match=r"bluerov2, bluerov2-heavy"):
        load_model("nautilus")


def test_positive_derivative_is_rejected_with_its_key(wu: HydroModel) -> None:
    data = {f.name: getattr(wu, f.name) for f in dataclasses.fields(HydroModel)}
    data["added_mass"] = [5.5, -12.7, -14.57, -0.12, -0.12, -0.12]
    with pytest.raises(ConfigError, match=r"m\.toml: added_mass\[0\]: must be ≤ 0"):
        build(HydroModel, data, source="m.toml")


def test_mass_matrix_gives_the_rigid_body_kinetic_energy(wu: HydroModel) -> None:
    model = off_centre(wu)
    rng = np.random.default_rng(1)
    for _ in range(20):
        nu = rng.normal(size=6)
        v, omega = nu[:3], nu[3:]
        v_cog = v + np.cross(omega, model.cog_m)
        energy = 0.5 * model.mass_kg * v_cog @ v_cog
        energy += 0.5 * omega @ np.diag(model.inertia_kg_m2) @ omega
        assert 0.5 * nu @ model.rigid_body_mass_matrix @ nu == pytest.approx(energy, rel=1e-12)
    assert np.allclose(model.mass_matrix, model.mass_matrix.T)
    assert np.all(np.linalg.eigvalsh(model.mass_matrix) > 0.0)


def test_coriolis_does_no_work_and_damping_dissipates(wu: HydroModel) -> None:
    model = off_centre(wu)
    rng = np.random.default_rng(2)
    for _ in range(20):
        nu = rng.normal(size=6)
        c_rb = coriolis_rigid_body(model, nu)
        c_a = coriolis_added_mass(model, nu)
        assert np.allclose(c_rb, -c_rb.T)
        assert np.allclose(c_a, -c_a.T)
        assert nu @ (c_rb + c_a) @ nu == pytest.approx(0.0, abs=1e-12)
        assert nu @ damping_matrix(model, nu) @ nu > 0.0


def test_rigid_body_coriolis_is_newton_euler_about_the_cog(wu: HydroModel) -> None:
    """M_RB ν̇ + C_RB(ν)ν must equal the wrench about CO that Newton–Euler at the CoG needs."""
    model = off_centre(wu)
    rng = np.random.default_rng(3)
    inertia = np.diag(model.inertia_kg_m2)
    r_g = np.asarray(model.cog_m)
    for _ in range(20):
        nu, nu_dot = rng.normal(size=6), rng.normal(size=6)
        v, omega, v_dot, omega_dot = nu[:3], nu[3:], nu_dot[:3], nu_dot[3:]
        a_cog = v_dot + np.cross(omega_dot, r_g) + np.cross(omega, v + np.cross(omega, r_g))
        force = model.mass_kg * a_cog
        moment_cog = inertia @ omega_dot + np.cross(omega, inertia @ omega)
        expected = np.concatenate([force, moment_cog + np.cross(r_g, force)])
        got = model.rigid_body_mass_matrix @ nu_dot + coriolis_rigid_body(model, nu) @ nu
        assert np.allclose(got, expected, rtol=1e-12, atol=1e-12)


def test_munk_moment_turns_the_body_broadside(wu: HydroModel) -> None:
    """Moving forward and down, a body with Z_ẇ more negative than X_u̇ pitches nose up
    (Fossen's full C_A)."""
    full = dataclasses.replace(wu, added_mass_coriolis="full")
    nu = np.array([1.0, 0.0, 0.5, 0.0, 0.0, 0.0])
    moment = -(coriolis_added_mass(full, nu) @ nu)[4]
    assert moment == pytest.approx((wu.added_mass[0] - wu.added_mass[2]) * 0.5, rel=1e-12)
    assert moment > 0.0


@pytest.mark.parametrize("roll_rad", [0.1, -0.4, 1.0])
def test_restoring_moment_rights_a_rolled_vehicle(wu: HydroModel, roll_rad: float) -> None:
    rolled = Rotation.from_euler("x", roll_rad).as_matrix()  # body FRD → NED
    g = restoring_forces(wu, rolled)
    # Weight at r_g = (0, 0, z_g): K = −W·z_g·sin φ on the body, and g(η) is its negative.
    assert -g[3] == pytest.approx(-wu.weight_n * wu.cog_m[2] * math.sin(roll_rad), rel=1e-12)
    # The net force is B − W upwards, in the body frame.
    down_body = rolled.T @ [0.0, 0.0, 1.0]
    assert np.allclose(-g[:3], -wu.net_buoyancy_n * down_body)


def test_wrench_about_origin_keeps_the_moment_about_any_point(wu: HydroModel) -> None:
    model = off_centre(wu)
    wrench_cog = np.array([3.0, -2.0, 5.0, 0.1, -0.2, 0.3])
    tau = wrench_about_origin(model, wrench_cog)
    point = np.array([0.3, -0.1, 0.2])
    about_point_from_cog = wrench_cog[3:] + np.cross(np.asarray(model.cog_m) - point, tau[:3])
    about_point_from_origin = tau[3:] + np.cross(-point, tau[:3])
    assert np.allclose(about_point_from_cog, about_point_from_origin)


def test_at_rest_the_vehicle_accelerates_up_with_added_mass(wu: HydroModel) -> None:
    nu_dot = body_acceleration(wu, np.zeros(6), np.eye(3), np.zeros(6))
    expected = -wu.net_buoyancy_n / (wu.mass_kg - wu.added_mass[2])
    assert nu_dot == pytest.approx([0.0, 0.0, expected, 0.0, 0.0, 0.0], abs=1e-15)


@pytest.mark.parametrize("option", OPTIONS)
@pytest.mark.parametrize("name", ["bluerov2", "bluerov2-heavy", "off-centre"])
def test_compiled_equation_matches_fossens_matrices(name: str, option: str) -> None:
    model = off_centre(load_model("bluerov2")) if name == "off-centre" else load_model(name)
    model = dataclasses.replace(model, added_mass_coriolis=option)
    rng = np.random.default_rng(4)
    for _ in range(100):
        nu = rng.normal(scale=0.5, size=6)
        rot = Rotation.from_quat(rng.normal(size=4)).as_matrix()
        wrench = rng.normal(scale=10.0, size=6)
        current_ned = rng.normal(scale=0.3, size=3)
        scale = float(rng.uniform(0.0, 1.0))
        expected = fossen_matrices.body_acceleration(model, nu, rot, wrench, current_ned, scale)
        got = body_acceleration(model, nu, rot, wrench, current_ned, scale)
        assert np.allclose(got, expected, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("option", OPTIONS)
def test_munk_moment_is_there_only_with_the_full_added_mass_coriolis(
    wu: HydroModel, option: str
) -> None:
    """Forward and down at (u, w) = (1, 0.5) m/s, level, no rotation: the pitch moment on the
    body is the Munk moment (X_u̇ − Z_ẇ)·u·w (Fossen's −C_A·ν_r) with ``"full"``, and nothing
    otherwise. The
    moment is M·ν̇ from the compiled equation, less the weight's and buoyancy's (zero level)
    and the damping's (none in pitch at q = 0)."""
    model = dataclasses.replace(wu, added_mass_coriolis=option)
    nu = np.array([1.0, 0.0, 0.5, 0.0, 0.0, 0.0])
    nu_dot = body_acceleration(model, nu, np.eye(3), np.zeros(6))
    moment = (model.mass_matrix @ nu_dot)[4]
    munk = (wu.added_mass[0] - wu.added_mass[2]) * nu[0] * nu[2]
    expected = {"full": munk, "isotropic": 0.0, "off": 0.0}[option]
    assert moment == pytest.approx(expected, abs=1e-12)
    assert (moment > 0.0) == (option == "full")  # full: nose up, broadside to the flow


def test_submerged_fraction_fades_across_the_surface() -> None:
    assert submerged_fraction(1.0, 0.25) == 1.0
    assert submerged_fraction(-1.0, 0.25) == 0.0
    assert submerged_fraction(0.0, 0.25) == 0.5
    assert submerged_fraction(0.0625, 0.25) == pytest.approx(0.75)


def test_constant_current_needs_no_generator() -> None:
    process = CurrentProcess(WaterCurrent(velocity_ned_mps=(0.2, -0.1, 0.0)))
    assert process.advance(10.0) == (0.2, -0.1, 0.0)


def test_varying_current_without_generator_is_refused() -> None:
    with pytest.raises(ValueError, match="Generator"):
        CurrentProcess(WaterCurrent(variation_std_mps=(0.1, 0.1, 0.0)))


def test_gauss_markov_variation_has_its_stationary_statistics() -> None:
    """Standard deviation σ and lag correlation exp(−Δt/T) of the first-order process."""
    current = WaterCurrent(
        velocity_ned_mps=(0.3, 0.0, 0.0),
        variation_std_mps=(0.1, 0.05, 0.0),
        time_constant_s=10.0,
    )
    process = CurrentProcess(current, np.random.default_rng(6))
    samples = np.array([process.advance(5.0) for _ in range(20000)])
    deviation = samples - np.array(current.velocity_ned_mps)
    assert deviation[:, 0].std() == pytest.approx(0.1, rel=0.05)
    assert deviation[:, 1].std() == pytest.approx(0.05, rel=0.05)
    assert np.all(deviation[:, 2] == 0.0)
    lag = np.corrcoef(deviation[:-1, 0], deviation[1:, 0])[0, 1]
    assert lag == pytest.approx(math.exp(-0.5), abs=0.03)


def test_gauss_markov_variation_is_reproducible_from_the_seed() -> None:
    current = WaterCurrent(variation_std_mps=(0.1, 0.1, 0.02))
    runs = []
    for _ in range(2):
        process = CurrentProcess(current, np.random.default_rng(7))
        runs.append([process.advance(0.5) for _ in range(100)])
    assert runs[0] == runs[1]
