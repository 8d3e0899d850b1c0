"""The pybullet plant against closed forms, a 1-DOF integration and a full 6-DOF integration.

Unless a test says otherwise the vehicle is the default BlueROV2 (Wu 2018) and tolerances are
2 %. Where a test wants one axis alone, the force goes through the body origin CO (moment about
the CoG −r_g×F), so damping at CO leaves no steady moment, and the 2 N net buoyancy is cancelled
by a body force while the vehicle stays level.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pybullet
import pytest
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation

from testbed.common.geometry import quat_from_euler
from testbed.vehicle.hydrodynamics import HydroModel, load_model, submerged_fraction
from testbed.vehicle.open_loop import simulate_open_loop
from testbed.vehicle.physics import Physics
from testbed.vehicle.pool_scene import PoolScene
from testbed.vehicle.pybullet_frames import (
    ned_to_pybullet,
    pybullet_to_ned,
    quaternion_ned_to_pybullet,
    quaternion_pybullet_to_ned,
)
from testbed.vehicle.water_current import WaterCurrent
from tests.vehicle.fossen_matrices import body_acceleration

DT_S = 1.0 / 240.0


@pytest.fixture(scope="module")
def wu() -> HydroModel:
    return load_model("bluerov2")


def terminal_speed(quadratic: float, linear: float, force: float) -> float:
    """Positive root of |d_q|·v² + |d_l|·v = F."""
    dq, dl = abs(quadratic), abs(linear)
    return (-dl + math.sqrt(dl * dl + 4.0 * dq * force)) / (2.0 * dq)


def through_origin(model: HydroModel, force: tuple[float, float, float]) -> list[float]:
    """A body wrench about the CoG equal to ``force`` applied at CO, net buoyancy cancelled."""
    f = np.array([force[0], force[1], force[2] + model.net_buoyancy_n])
    return [*f.tolist(), *(-np.cross(model.cog_m, f)).tolist()]


def run(sim: Physics, wrench: list[float], duration_s: float) -> None:
    for _ in range(round(duration_s / sim.dt_s)):
        sim.step(wrench)


# --- frames ---------------------------------------------------------------------------------


def test_vector_and_quaternion_conversions_round_trip() -> None:
    v = (1.0, -2.0, 3.5)
    assert pybullet_to_ned(ned_to_pybullet(v)) == v
    q = quat_from_euler(0.3, -0.2, 2.0)
    assert np.allclose(quaternion_pybullet_to_ned(quaternion_ned_to_pybullet(q)), q)


def test_pose_round_trips_through_pybullet(wu: HydroModel) -> None:
    position, euler = (4.0, -3.0, 7.5), (0.2, -0.3, 2.5)
    with Physics(wu, start_position_ned=position, start_euler_rad=euler) as sim:
        state = sim.state()
        assert np.allclose(state.position_ned, position, atol=1e-12)
        assert np.allclose(state.euler_rad, euler, atol=1e-12)
        assert np.allclose(state.nu, 0.0)
        # pybullet's own view: z up, base at the CoG, body FLU.
        base, orn = pybullet.getBasePositionAndOrientation(sim.body_id, sim.client_id)
        rot = Rotation.from_euler("ZYX", euler[::-1]).as_matrix()  # body FRD → NED
        cog_ned = np.array(position) + rot @ wu.cog_m
        assert np.allclose(base, [cog_ned[0], -cog_ned[1], -cog_ned[2]])
        forward_pb = np.array(pybullet.getMatrixFromQuaternion(orn)).reshape(3, 3)[:, 0]
        forward_ned = rot[:, 0]
        assert np.allclose(forward_pb, [forward_ned[0], -forward_ned[1], -forward_ned[2]])


def test_level_vehicle_heading_east_sits_z_up_in_pybullet(wu: HydroModel) -> None:
    with Physics(
        wu, start_position_ned=(1.0, 2.0, 3.0), start_euler_rad=(0, 0, math.pi / 2)
    ) as sim:
        base, orn = pybullet.getBasePositionAndOrientation(sim.body_id, sim.client_id)
        axes = np.array(pybullet.getMatrixFromQuaternion(orn)).reshape(3, 3)
    assert np.allclose(base, (1.0, -2.0, -3.0 - wu.cog_m[2]))  # CoG 2 cm below CO
    assert np.allclose(axes[:, 0], (0.0, -1.0, 0.0))  # forward = east = pybullet −y
    assert np.allclose(axes[:, 2], (0.0, 0.0, 1.0))  # body up (FLU z) = world up


def test_velocity_round_trips_and_forces_push_the_right_way(wu: HydroModel) -> None:
    nu = (0.3, -0.2, 0.1, 0.05, -0.04, 0.2)
    with Physics(wu, start_euler_rad=(0.1, 0.2, -1.0)) as sim:
        sim.reset(nu=nu)
        assert np.allclose(sim.state().nu, nu)
        sim.reset(euler_rad=(0.0, 0.0, 0.0))
        run(sim, [10.0, 0.0, 30.0, 0.0, 0.0, 1.0], 0.5)
        state = sim.state()
    assert state.position_ned[0] > 0.0  # forward is north
    assert state.position_ned[2] > 10.0  # +z body force pushes down
    assert state.euler_rad[2] > 0.0  # +N turns clockwise seen from above


# --- terminal speeds ------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("axis", "force"),
    [
        # 5 N surge keeps u ≈ 0.43 m/s below the Munk-moment pitch instability of this model,
        # (Z_ẇ − X_u̇)·u² > W·z_g, i.e. u > 0.50 m/s; sway is stable to ≈ 1.1 m/s.
        (0, 5.0),
        (1, 20.0),
        (2, 20.0),
        (2, -20.0),
    ],
)
def test_terminal_speed_matches_the_damping_balance(
    wu: HydroModel, axis: int, force: float
) -> None:
    f = [0.0, 0.0, 0.0]
    f[axis] = force
    with Physics(wu) as sim:
        run(sim, through_origin(wu, (f[0], f[1], f[2])), 8.0)
        speed = sim.state().nu[axis]
    expected = math.copysign(
        terminal_speed(wu.quadratic_damping[axis], wu.linear_damping[axis], abs(force)), force
    )
    assert speed == pytest.approx(expected, rel=0.02)


def test_terminal_yaw_rate_matches_the_damping_balance(wu: HydroModel) -> None:
    with Physics(wu) as sim:
        run(sim, [0.0, 0.0, wu.net_buoyancy_n, 0.0, 0.0, 1.0], 6.0)
        rate = sim.state().nu[5]
    assert rate == pytest.approx(
        terminal_speed(wu.quadratic_damping[5], wu.linear_damping[5], 1.0), rel=0.02
    )


def test_passive_ascent_from_net_buoyancy(wu: HydroModel) -> None:
    result = simulate_open_loop("bluerov2", [0.0] * 6, duration_s=10.0)
    expected = terminal_speed(wu.quadratic_damping[2], wu.linear_damping[2], wu.net_buoyancy_n)
    assert result.nu[-1, 2] == pytest.approx(-expected, rel=0.02)
    assert result.position_ned[-1, 2] < 10.0
    assert result.t[0] == 0.0 and result.t[-1] == pytest.approx(10.0)
    assert result.position_ned.shape == (2401, 3) and result.nu.shape == (2401, 6)


# --- added mass -----------------------------------------------------------------------------


def one_dof_surge(model: HydroModel, force: float, t_s: np.ndarray) -> np.ndarray:
    """(m − X_u̇)·u̇ = F + X_u·u + X_u|u|·u|u| by scipy, from rest."""
    mass = model.mass_kg - model.added_mass[0]
    x_u, x_uu = model.linear_damping[0], model.quadratic_damping[0]

    def rhs(_t: float, u: np.ndarray) -> list[float]:
        return [(force + x_u * u[0] + x_uu * u[0] * abs(u[0])) / mass]

    sol = solve_ivp(rhs, (0.0, float(t_s[-1])), [0.0], t_eval=t_s, rtol=1e-10, atol=1e-12)
    return np.asarray(sol.y[0])


def test_surge_step_follows_the_added_mass_integration(wu: HydroModel) -> None:
    """Force at the CoG: added mass at CO couples a little pitch (≈ 0.5 %), within 2 %."""
    with Physics(wu) as sim:
        samples = []
        for _ in range(480):
            sim.step([5.0, 0.0, wu.net_buoyancy_n, 0.0, 0.0, 0.0])
            samples.append((sim.time_s, sim.state().nu[0]))
    t, u = np.array(samples).T
    assert u == pytest.approx(one_dof_surge(wu, 5.0, t), rel=0.02)
    # Without added mass the vehicle would have been 48 % faster off the mark.
    assert u[23] < 0.75 * 5.0 / wu.mass_kg * t[23]


def test_surge_step_is_exact_when_nothing_couples(wu: HydroModel) -> None:
    """r_g = 0 decouples surge: pybullet must then follow the 1-DOF ODE to the step error."""
    model = dataclasses.replace(wu, cog_m=(0.0, 0.0, 0.0))
    with Physics(model) as sim:
        samples = []
        for _ in range(720):
            sim.step([20.0, 0.0, model.net_buoyancy_n, 0.0, 0.0, 0.0])
            samples.append((sim.time_s, sim.state().nu[0]))
    t, u = np.array(samples).T
    assert u == pytest.approx(one_dof_surge(model, 20.0, t), rel=0.003)


def test_heave_step_is_stable_and_exact_at_240_hz(wu: HydroModel) -> None:
    """Heave added mass (14.57 kg) exceeds the 11.5 kg body: a lagged estimate would diverge."""
    force = 40.0
    mass = wu.mass_kg - wu.added_mass[2]
    z_w, z_ww = wu.linear_damping[2], wu.quadratic_damping[2]
    with Physics(wu) as sim:
        w = []
        for _ in range(720):
            sim.step([0.0, 0.0, force, 0.0, 0.0, 0.0])
            w.append(sim.state().nu[2])
    w_arr = np.array(w)
    assert np.all(np.diff(w_arr) > 0.0)  # monotone rise, no ringing
    first = (force - wu.net_buoyancy_n) / mass * DT_S
    assert w_arr[0] == pytest.approx(first, rel=1e-9)

    def rhs(_t: float, y: np.ndarray) -> list[float]:
        return [(force - wu.net_buoyancy_n + z_w * y[0] + z_ww * y[0] * abs(y[0])) / mass]

    t = DT_S * np.arange(1, 721)
    ref = solve_ivp(rhs, (0.0, t[-1]), [0.0], t_eval=t, rtol=1e-10, atol=1e-12).y[0]
    assert w_arr == pytest.approx(ref, rel=0.003)


# --- restoring ------------------------------------------------------------------------------


def linearised_mode(model: HydroModel, axis: str) -> tuple[float, float]:
    """(decay rate σ [1/s], damped frequency ω_d [rad/s]) of small roll or pitch motion.

    Sway–roll (or surge–pitch) about CO, from the kinetic energy ½m|v + ω×r_g|² + ½I_g ω² +
    ½ added mass, restoring W·z_g·angle and linear damping.
    """
    m, z_g = model.mass_kg, model.cog_m[2]
    lin, ang = (1, 3) if axis == "roll" else (0, 4)
    coupling = -m * z_g if axis == "roll" else m * z_g
    mass = np.array(
        [
            [m - model.added_mass[lin], coupling],
            [coupling, model.inertia_kg_m2[ang - 3] + m * z_g**2 - model.added_mass[ang]],
        ]
    )
    stiffness = np.diag([0.0, model.weight_n * z_g])
    damping = np.diag([-model.linear_damping[lin], -model.linear_damping[ang]])
    inverse = np.linalg.inv(mass)
    a = np.block([[np.zeros((2, 2)), np.eye(2)], [-inverse @ stiffness, -inverse @ damping]])
    eigenvalues = np.linalg.eigvals(a)
    oscillatory = eigenvalues[np.abs(eigenvalues.imag) > 1e-9][0]
    return -oscillatory.real, abs(oscillatory.imag)


@pytest.mark.parametrize(("axis", "index"), [("roll", 0), ("pitch", 1)])
def test_small_angle_oscillation_matches_the_linearised_equation(
    wu: HydroModel, axis: str, index: int
) -> None:
    """Neutral buoyancy (B = W) so the vehicle stays put; 1e-4 rad so quadratic damping is nil."""
    model = dataclasses.replace(wu, buoyancy_n=wu.weight_n)
    euler = [0.0, 0.0, 0.0]
    euler[index] = 1e-4
    with Physics(model, start_euler_rad=euler) as sim:
        angle = [sim.state().euler_rad[index]]
        for _ in range(240 * 9):
            sim.step([0.0] * 6)
            angle.append(sim.state().euler_rad[index])
    a = np.array(angle)
    t = DT_S * np.arange(len(a))
    crossings = [
        t[i] - a[i] * DT_S / (a[i + 1] - a[i]) for i in range(len(a) - 1) if a[i] * a[i + 1] < 0
    ]
    period = 2.0 * float(np.mean(np.diff(crossings)))
    peaks = [a[i] for i in range(1, len(a) - 1) if a[i - 1] < a[i] >= a[i + 1]]
    decay = math.log(peaks[0] / peaks[-1]) / ((len(peaks) - 1) * period)
    sigma, omega_d = linearised_mode(model, axis)
    assert period == pytest.approx(2.0 * math.pi / omega_d, rel=0.02)
    assert decay == pytest.approx(sigma, rel=0.02)


@pytest.mark.parametrize(
    "euler", [(0.5, 0.0, 0.0), (-0.5, 0.0, 0.0), (0.0, 0.4, 0.0), (0.0, -0.4, 1.0)]
)
def test_tilted_vehicle_rights_itself(wu: HydroModel, euler: tuple[float, float, float]) -> None:
    index = 0 if euler[0] else 1
    with Physics(wu, start_euler_rad=euler) as sim:
        sim.step([0.0] * 6)
        first = sim.state()
        run(sim, [0.0] * 6, 20.0)
        last = sim.state()
    # The restoring moment opposes the tilt from the first step...
    assert math.copysign(1.0, first.nu_dot[3 + index]) == -math.copysign(1.0, euler[index])
    # ...and damping brings it back near level.
    assert abs(last.euler_rad[index]) < 0.05 * abs(euler[index])


# --- full model -----------------------------------------------------------------------------


def integrate_reference(
    model: HydroModel,
    wrench: list[float],
    duration_s: float,
    nu0: tuple[float, ...],
    euler0: tuple[float, float, float],
    current_ned: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> np.ndarray:
    """(13,) [position NED, quaternion, ν] at ``duration_s`` by scipy on Fossen's matrices."""

    def rhs(_t: float, y: np.ndarray) -> np.ndarray:
        q = y[3:7] / np.linalg.norm(y[3:7])
        nu = y[7:]
        rot = Rotation.from_quat(q, scalar_first=True).as_matrix()
        depth_cob = y[2] + (rot @ model.cob_m)[2]
        scale = submerged_fraction(depth_cob, model.hull_size_m[2])
        nu_dot = body_acceleration(model, nu, rot, wrench, current_ned, scale)
        w, x, yy, z = q
        p, qq, r = nu[3:]
        q_dot = 0.5 * np.array(
            [
                -x * p - yy * qq - z * r,
                w * p + yy * r - z * qq,
                w * qq + z * p - x * r,
                w * r + x * qq - yy * p,
            ]
        )
        return np.concatenate([rot @ nu[:3], q_dot, nu_dot])

    q0 = Rotation.from_euler("ZYX", euler0[::-1]).as_quat(scalar_first=True)
    y0 = np.concatenate([[0.0, 0.0, 10.0], q0, nu0])
    sol = solve_ivp(rhs, (0.0, duration_s), y0, rtol=1e-10, atol=1e-12)
    return np.asarray(sol.y[:, -1])


@pytest.mark.parametrize(
    ("name", "option"),
    [
        ("bluerov2", "full"),
        ("bluerov2-heavy", "full"),
        ("bluerov2", "isotropic"),
        ("bluerov2", "off"),
    ],
)
def test_tumbling_manoeuvre_matches_a_6dof_integration(name: str, option: str) -> None:
    """Every coupling at once (spin, r_g, unequal inertia, current): pybullet vs scipy on
    Fossen's matrices, for each added-mass Coriolis option."""
    model = load_model(name, added_mass_coriolis=option)  # type: ignore[arg-type]
    wrench = [8.0, -6.0, 10.0, 0.6, -0.5, 0.8]
    nu0 = (0.2, -0.1, 0.1, 1.5, -1.0, 2.0)
    euler0 = (0.3, -0.2, 0.5)
    current = (0.2, -0.3, 0.05)
    with Physics(model, start_euler_rad=euler0, current=WaterCurrent(current)) as sim:
        sim.reset(nu=nu0)
        run(sim, wrench, 2.0)
        state = sim.state()
    ref = integrate_reference(model, wrench, 2.0, nu0, euler0, current)
    assert state.position_ned == pytest.approx(ref[:3], abs=0.01)
    assert abs(np.dot(state.quaternion_wxyz, ref[3:7])) == pytest.approx(1.0, abs=1e-4)
    assert state.nu == pytest.approx(ref[7:], abs=0.02 * np.abs(ref[7:]).max())


def test_constant_current_carries_the_vehicle_at_its_speed(wu: HydroModel) -> None:
    current = (0.3, 0.2, 0.0)
    with Physics(wu, current=WaterCurrent(velocity_ned_mps=current)) as sim:
        run(sim, [0.0] * 6, 20.0)
        state = sim.state()
    attitude = Rotation.from_quat(state.quaternion_wxyz, scalar_first=True)
    velocity_ned = attitude.as_matrix() @ state.nu[:3]
    assert velocity_ned[:2] == pytest.approx(current[:2], rel=0.02)


def test_varying_current_is_reproducible_and_needs_a_generator(wu: HydroModel) -> None:
    current = WaterCurrent(variation_std_mps=(0.1, 0.1, 0.0), update_period_s=0.1)
    with pytest.raises(ValueError, match="Generator"):
        Physics(wu, current=current)
    finals = []
    for _ in range(2):
        with Physics(wu, current=current, rng=np.random.default_rng(11)) as sim:
            run(sim, [0.0] * 6, 2.0)
            finals.append(sim.state().position_ned.copy())
    assert np.array_equal(finals[0], finals[1])
    assert np.linalg.norm(finals[0][:2]) > 0.0


def test_stepping_to_a_time_is_stepping_one_at_a_time(wu: HydroModel) -> None:
    """``step_until`` (the vehicle's path: the held wrench, many steps a call) ends at the first
    step at or after its time and leaves the plant exactly where single steps do, with the
    current's variation drawn at the same steps."""
    current = WaterCurrent(variation_std_mps=(0.1, 0.1, 0.0), update_period_s=0.05)
    wrench = (12.0, -3.0, 5.0, 0.4, -0.2, 1.0)
    with (
        Physics(wu, current=current, rng=np.random.default_rng(3)) as one,
        Physics(wu, current=current, rng=np.random.default_rng(3)) as many,
    ):
        for _ in range(100):
            one.step(wrench)
        many.held_wrench[:] = wrench
        reached = 0.0
        for until_s in (0.1, 0.1, 0.25, 100 * many.dt_s - 1e-9):
            before = many.time_s
            reached = many.step_until(until_s)
            if before >= until_s:  # already there: one step
                assert reached == pytest.approx(before + many.dt_s, abs=1e-12)
            else:  # the first step at or after it
                assert until_s <= reached < until_s + many.dt_s
        assert reached == one.time_s == many.time_s
        assert one.state_floats() == many.state_floats()
        assert np.array_equal(one.state().nu_dot, many.state().nu_dot)
        assert one.current_ned == many.current_ned != current.velocity_ned_mps
        assert many.held_wrench.tolist() == list(wrench)  # held, not consumed


# --- scene ----------------------------------------------------------------------------------


def test_vehicle_stops_at_the_pool_floor(wu: HydroModel) -> None:
    pool = PoolScene(length_m=10.0, width_m=6.0, depth_m=3.0)
    with Physics(wu, pool=pool, start_position_ned=(0.0, 0.0, 2.0)) as sim:
        run(sim, [0.0, 0.0, 20.0, 0.0, 0.0, 0.0], 4.0)
        state = sim.state()
    resting = pool.depth_m - wu.hull_size_m[2] / 2  # hull box centred on CO
    assert state.position_ned[2] == pytest.approx(resting, abs=0.01)
    assert abs(state.nu[2]) < 1e-3


def test_vehicle_floats_at_the_surface(wu: HydroModel) -> None:
    """Buoyancy fades as the hull leaves the water: the vehicle floats where B·fraction = W."""
    with Physics(wu, start_position_ned=(0.0, 0.0, 0.5)) as sim:
        run(sim, [0.0] * 6, 40.0)
        depth = sim.state().position_ned[2]
    expected = (wu.weight_n / wu.buoyancy_n - 0.5) * wu.hull_size_m[2]
    assert depth == pytest.approx(expected, abs=0.005)


# --- lifecycle ------------------------------------------------------------------------------


def test_state_is_cached_read_only_and_time_counts_steps(wu: HydroModel) -> None:
    with Physics(wu, dt_s=0.01) as sim:
        first = sim.state()
        assert sim.state() is first
        for _ in range(7):
            sim.step(np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0]))
        state = sim.state()
        assert state is not first
        assert state.time_s == pytest.approx(0.07)
        assert state.nu_dot[0] > 0.0
        with pytest.raises(ValueError):
            state.nu[0] = 1.0
        sim.reset(position_ned=(1.0, 1.0, 1.0))
        assert sim.time_s == 0.0
        assert np.allclose(sim.state().position_ned, (1.0, 1.0, 1.0))


def test_close_disconnects_its_own_client(wu: HydroModel) -> None:
    with Physics(wu) as sim, Physics(wu) as other:
        assert sim.client_id != other.client_id
        client = sim.client_id
        sim.close()
        assert not pybullet.isConnected(client)
        assert pybullet.isConnected(other.client_id)
        sim.close()  # idempotent
        with pytest.raises(RuntimeError):
            sim.state()


def test_the_steps_rotation_matrix_is_pybullets_to_the_bit() -> None:
    # The step computes pybullet's getMatrixFromQuaternion itself (one pybullet call a step
    # fewer): the same bits as pybullet's, for unit and non-unit quaternions and near the axes.
    from testbed.vehicle.plant_kernels import matrix_from_quaternion

    rng = np.random.default_rng(7)
    for i in range(20000):
        q = rng.normal(size=4)
        if i % 3 == 0:
            q *= (1.0, 1e-4, 1e-7, 1.0)
        if i % 2 == 0:
            q /= np.linalg.norm(q)
        orientation = (float(q[0]), float(q[1]), float(q[2]), float(q[3]))
        assert matrix_from_quaternion(orientation) == pybullet.getMatrixFromQuaternion(orientation)
