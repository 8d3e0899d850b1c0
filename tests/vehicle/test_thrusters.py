"""testbed.vehicle.thrusters: the T200 lookup tables and the plant-side thruster dynamics."""

from __future__ import annotations

import csv
import io
import math
from importlib import resources

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import signal

from testbed.vehicle.thrusters import (
    SPIN_UP_TIME_CONSTANT_S,
    T200,
    ZERO_FORCE_N,
    Handedness,
    ThrusterDynamics,
    ThrusterFault,
)

T = T200.from_table()


def packaged_rows() -> list[dict[str, float]]:
    """The packaged CSV, read here with the csv module independently of T200's own reader."""
    text = resources.files("testbed.vehicle").joinpath("data", "t200_12v.csv").read_text()
    body = "\n".join(line for line in text.splitlines() if not line.startswith("#"))
    return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(io.StringIO(body))]


ROWS = packaged_rows()


# ----------------------------------------------------------------------------- the table


def test_packaged_table_is_the_blue_robotics_sheet() -> None:
    assert len(ROWS) == 183
    assert ROWS[0]["pwm"] == 1100 and ROWS[-1]["pwm"] == 1900
    assert {row["voltage"] for row in ROWS} == {12.0}
    text = resources.files("testbed.vehicle").joinpath("data", "t200_12v.csv").read_text()
    assert "Blue Robotics" in text.split("pwm,rpm")[0]  # attribution header


def test_every_table_row_is_reproduced_pwm_to_force() -> None:
    for row in ROWS:
        assert T.force_for_pwm(row["pwm"]) == pytest.approx(row["force"], abs=1e-12)


def test_published_end_figures() -> None:
    assert T.force_for_pwm(1100.0) == pytest.approx(-28.449)
    assert T.force_for_pwm(1900.0) == pytest.approx(36.3951)
    assert T.max_forward_n == pytest.approx(36.40, abs=0.005)
    assert T.max_reverse_n == pytest.approx(28.65, abs=0.005)
    assert T.force_limits_n == (-T.max_reverse_n, T.max_forward_n)
    assert T.max_current_a == pytest.approx(17.08)


def test_reference_derived_figures() -> None:
    # REFERENCE §3.5: +10 N ≈ 2.25 A at ≈ 1674 µs (CW); -10 N ≈ 3.30 A (≈ 1300 CW, 1700 CCW).
    assert T.pwm_for_force(10.0, "cw") == pytest.approx(1674.0, abs=0.5)
    assert T.current_for_force(10.0) == pytest.approx(2.25, abs=0.005)
    assert T.current_for_force(-10.0) == pytest.approx(3.30, abs=0.005)
    assert T.pwm_for_force(-10.0, "cw") == pytest.approx(1300.0, abs=0.5)
    assert T.pwm_for_force(-10.0, "ccw") == pytest.approx(1700.0, abs=0.5)
    # Linear interpolation between the two bracketing rows (1672 µs 9.81 N, 1676 µs 10.2024 N).
    t = (10.0 - 9.81) / (10.2024 - 9.81)
    assert T.pwm_for_force(10.0) == pytest.approx(1672.0 + 4.0 * t, rel=1e-12)
    assert T.current_for_force(10.0) == pytest.approx(2.2 + 0.1 * t, rel=1e-12)


@pytest.mark.parametrize("handedness", ["cw", "ccw"])
def test_dead_band_gives_zero_force(handedness: Handedness) -> None:
    for pwm in np.arange(1464.0, 1536.0 + 0.25, 0.25):
        assert T.force_for_pwm(float(pwm), handedness) == 0.0
    assert T.force_for_pwm(1460.0, "cw") == pytest.approx(-0.3924)
    assert T.force_for_pwm(1540.0, "cw") == pytest.approx(0.3924)
    assert T.pwm_for_force(0.0, handedness) == 1500.0
    assert T.current_for_force(0.0) == 0.0


def test_any_real_force_is_commanded_outside_the_dead_band() -> None:
    assert T.pwm_for_force(1e-6) > 1536.0
    assert T.pwm_for_force(-1e-6) < 1464.0
    assert 1536.0 > T.pwm_for_force(1e-15) > 1500.0  # round-off stays inside, near neutral


@given(st.floats(1000.0, 2000.0))
def test_ccw_mirrors_the_pulse(pwm: float) -> None:
    assert T.force_for_pwm(pwm, "ccw") == T.force_for_pwm(3000.0 - pwm, "cw")


@given(st.floats(-40.0, 40.0))
def test_ccw_mirrors_the_inverse(force: float) -> None:
    assert T.pwm_for_force(force, "ccw") == pytest.approx(3000.0 - T.pwm_for_force(force, "cw"))


def test_saturation_of_the_inverse() -> None:
    assert T.pwm_for_force(100.0) == 1892.0  # first row reaching the forward maximum
    assert T.pwm_for_force(-100.0) == 1104.0  # the reverse maximum (1100 µs gives less)
    assert T.current_for_force(100.0) == pytest.approx(16.74)
    assert T.current_for_force(-100.0) == pytest.approx(17.08)


def test_inverse_is_strictly_monotone_and_continuous() -> None:
    forces = np.linspace(-T.max_reverse_n, T.max_forward_n, 20001)
    pwm = T.pwms_for_forces(forces, np.zeros(forces.size, dtype=bool))
    steps = np.diff(pwm)
    assert np.all(steps > 0)
    # No jumps on the grid (3.3 mN apart) except the dead band crossed next to 0 N.
    crossing = (forces[:-1] < 0) & (forces[1:] > 0)
    assert np.max(steps[~crossing]) < 5.0
    assert steps[crossing].sum() > 1536.0 - 1464.0


def test_inverse_hits_every_envelope_row_exactly() -> None:
    # Envelope rows, derived here from the raw rows: outward from neutral, strictly beyond all
    # rows nearer 1500 µs.
    forward = [r for r in ROWS if r["pwm"] > 1500]
    reverse = [r for r in reversed(ROWS) if r["pwm"] < 1500]
    kept = []
    for side, sign in ((forward, 1.0), (reverse, -1.0)):
        best = 0.0
        for row in side:
            if sign * row["force"] > best:
                kept.append(row)
                best = sign * row["force"]
    assert {r["pwm"] for r in ROWS} - {r["pwm"] for r in kept} == {1100.0, 1500.0, 1896.0, 1900.0}
    for row in kept:
        assert T.pwm_for_force(row["force"]) == pytest.approx(row["pwm"], abs=1e-9)
        assert T.current_for_force(row["force"]) == pytest.approx(row["current"], abs=1e-12)


@given(st.floats(-28.6452, 36.3951), st.sampled_from(["cw", "ccw"]))
def test_round_trip_force_pwm_force(force: float, handedness: Handedness) -> None:
    pwm = T.pwm_for_force(force, handedness)
    # Exact but for the ±1e-9 N gap in which the inverse crosses the dead band.
    assert T.force_for_pwm(pwm, handedness) == pytest.approx(force, abs=2 * ZERO_FORCE_N)


def test_current_grows_with_thrust_magnitude() -> None:
    forward = np.linspace(0.0, 40.0, 2001)
    reverse = np.linspace(0.0, -30.0, 2001)
    assert np.all(np.diff(T.currents_for_forces(forward)) >= 0)
    assert np.all(np.diff(T.currents_for_forces(reverse)) >= 0)
    # Reverse thrust costs more current than the same forward thrust (asymmetric propeller).
    assert T.current_for_force(-20.0) > T.current_for_force(20.0)


@settings(max_examples=50)
@given(st.lists(st.tuples(st.floats(-40.0, 40.0), st.booleans()), min_size=1, max_size=10))
def test_vectorised_variants_match_scalar(pairs: list[tuple[float, bool]]) -> None:
    forces = [f for f, _ in pairs]
    hands: list[Handedness] = ["ccw" if c else "cw" for _, c in pairs]
    f = np.array(forces)
    ccw = np.array([c for _, c in pairs])
    pwm = T.pwms_for_forces(f, ccw)
    scalar = [T.pwm_for_force(x, h) for x, h in zip(forces, hands, strict=True)]
    assert pwm.tolist() == pytest.approx(scalar)
    currents = T.currents_for_forces(f)
    assert currents.tolist() == pytest.approx([T.current_for_force(x) for x in forces])
    back = T.forces_for_pwms(pwm, ccw)
    scalar = [T.force_for_pwm(p, h) for p, h in zip(pwm.tolist(), hands, strict=True)]
    assert back.tolist() == pytest.approx(scalar)


# ----------------------------------------------------------------------------- voltage


def test_twelve_volts_is_the_table_itself() -> None:
    assert T.voltage_v == 12.0
    for pwm in (1100.0, 1300.0, 1700.0, 1900.0):
        assert T200.from_table(12.0).force_for_pwm(pwm) == T.force_for_pwm(pwm)


@pytest.mark.parametrize(
    ("voltage", "forward", "reverse"),
    [(14.0, 44.4, 34.5), (16.0, 51.4, 39.9), (18.0, 59.0, 45.0), (20.0, 65.9, 49.4)],
)
def test_other_voltages_scale_to_the_published_maxima(
    voltage: float, forward: float, reverse: float
) -> None:
    t = T200.from_table(voltage)
    # The table's own maxima (36.3951 / 28.6452 N) versus the published 36.4 / 28.6 N.
    assert t.max_forward_n == pytest.approx(forward * 36.3951 / 36.4, rel=1e-12)
    assert t.max_reverse_n == pytest.approx(reverse * 28.6452 / 28.6, rel=1e-12)
    k_fwd, k_rev = forward / 36.4, reverse / 28.6
    assert t.force_for_pwm(1700.0) == pytest.approx(k_fwd * T.force_for_pwm(1700.0))
    assert t.force_for_pwm(1300.0) == pytest.approx(k_rev * T.force_for_pwm(1300.0))
    # Current at the same PWM scales with the same factor.
    assert t.current_for_force(t.force_for_pwm(1700.0)) == pytest.approx(
        k_fwd * T.current_for_force(T.force_for_pwm(1700.0))
    )
    assert t.force_for_pwm(1500.0) == 0.0


def test_voltage_between_rows_interpolates_and_outside_is_rejected() -> None:
    t13 = T200.from_table(13.0)
    assert t13.max_forward_n == pytest.approx(0.5 * (36.4 + 44.4) * 36.3951 / 36.4)
    # The BlueROV2's 4S battery, 14.8 V nominal: 40 % of the way from the published 14 V
    # maxima (44.4 / 34.5 N) to the 16 V ones (51.4 / 39.9 N): 47.2 / 36.66 N published-scale.
    battery = T200.from_table(14.8)
    assert battery.max_forward_n == pytest.approx(47.2 * 36.3951 / 36.4, rel=1e-12)
    assert battery.max_reverse_n == pytest.approx(36.66 * 28.6452 / 28.6, rel=1e-12)
    t14, t16 = T200.from_table(14.0), T200.from_table(16.0)
    assert t14.max_forward_n < battery.max_forward_n < t16.max_forward_n
    assert t14.max_current_a < battery.max_current_a < t16.max_current_a
    with pytest.raises(ValueError, match="voltage"):
        T200.from_table(11.0)
    with pytest.raises(ValueError, match="voltage"):
        T200.from_table(24.0)


def test_malformed_tables_are_rejected() -> None:
    with pytest.raises(ValueError, match="strictly increasing"):
        T200(np.array([1500.0, 1400.0, 1600.0]), np.zeros(3), np.zeros(3), voltage_v=12)
    no_neutral = np.array([1400.0, 1450.0, 1600.0])
    with pytest.raises(ValueError, match="1500"):
        T200(no_neutral, np.array([-1.0, -0.5, 1.0]), np.zeros(3), voltage_v=12)
    pwm = np.array([1400.0, 1500.0, 1600.0])
    with pytest.raises(ValueError, match="force"):
        T200(pwm, np.array([1.0, 0.0, 1.0]), np.zeros(3), voltage_v=12)


# ----------------------------------------------------------------------------- dynamics


def test_spin_up_follows_the_first_order_closed_form() -> None:
    tau = 0.05
    dyn = ThrusterDynamics(2, time_constant_s=tau)
    command = np.array([10.0, -5.0])
    dt = 0.001
    for step in range(1, 201):
        actual = dyn.step(command, dt)
        expected = command * (1.0 - math.exp(-step * dt / tau))
        assert actual == pytest.approx(expected, rel=1e-9)
    # Exact discretisation: one long step equals many short ones.
    one = ThrusterDynamics(2, time_constant_s=tau)
    assert one.step(command, 0.2) == pytest.approx(dyn.forces_n, rel=1e-9)


def test_zero_time_constant_follows_at_once() -> None:
    dyn = ThrusterDynamics(3, time_constant_s=0.0)
    assert dyn.step(np.array([1.0, 2.0, -3.0]), 0.01).tolist() == [1.0, 2.0, -3.0]


def test_default_time_constant_fits_von_benzon_dynamics() -> None:
    t = np.linspace(0.0, 0.5, 50001)
    _, y = signal.step(([6136.0, 108700.0], [1.0, 89.0, 9258.0, 108700.0]), T=t)
    rise_63 = t[np.argmax(y >= 1.0 - math.exp(-1.0))]
    assert rise_63 == pytest.approx(SPIN_UP_TIME_CONSTANT_S, abs=0.001)


def test_dead_stuck_and_degraded_faults() -> None:
    dyn = ThrusterDynamics(3, time_constant_s=0.0)
    command = np.array([10.0, 10.0, 10.0])
    dyn.step(command, 0.01)
    dyn.set_fault(0, "dead")
    dyn.set_fault(1, "stuck")  # holds the force it had: 10 N
    dyn.set_fault(2, "degraded", 0.4)
    for new_command in (np.array([-20.0, -20.0, -20.0]), np.array([5.0, 5.0, 5.0])):
        out = dyn.step(new_command, 0.01)
        assert out[0] == 0.0
        assert out[1] == 10.0
        assert out[2] == pytest.approx(0.4 * new_command[2])
    assert dyn.faults == {
        0: ThrusterFault("dead"),
        1: ThrusterFault("stuck", 10.0),
        2: ThrusterFault("degraded", 0.4),
    }
    dyn.set_fault(1, "stuck", -7.5)
    assert dyn.forces_n[1] == -7.5
    dyn.clear_fault()
    assert dyn.step(command, 0.01).tolist() == [10.0, 10.0, 10.0]


def test_cleared_fault_resumes_the_lag_from_where_it_was() -> None:
    tau = 0.02
    dyn = ThrusterDynamics(1, time_constant_s=tau)
    dyn.set_fault(0, "stuck", 4.0)
    dyn.step(np.array([10.0]), 1.0)
    dyn.clear_fault(0)
    out = dyn.step(np.array([10.0]), tau)
    assert out[0] == pytest.approx(10.0 + (4.0 - 10.0) * math.exp(-1.0))


def test_dynamics_rejects_misuse() -> None:
    dyn = ThrusterDynamics(2)
    with pytest.raises(ValueError, match="shape"):
        dyn.step(np.zeros(3), 0.01)
    with pytest.raises(ValueError, match="dt_s"):
        dyn.step(np.zeros(2), -0.01)
    with pytest.raises(IndexError):
        dyn.set_fault(2, "dead")
    with pytest.raises(ValueError, match="factor"):
        dyn.set_fault(0, "degraded")
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        dyn.set_fault(0, "degraded", 1.5)
    with pytest.raises(ValueError, match="mode"):
        dyn.set_fault(0, "exploded")  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        ThrusterDynamics(0)
    with pytest.raises(ValueError):
        ThrusterDynamics(2, time_constant_s=-1.0)


# ----------------------------------------------------------------------------- total current


def test_total_current_is_the_sum_of_the_table_currents() -> None:
    # Forward rows 1700 and 1704 µs and reverse rows 1300 and 1296 µs, read here from the CSV:
    # each row's own force draws its own current, and a force a third of the way between two
    # rows draws the current a third of the way between theirs (linear interpolation).
    by_pwm = {row["pwm"]: row for row in ROWS}
    forces, expected = [], 0.0
    for a, b in ((1700.0, 1704.0), (1300.0, 1296.0)):
        ra, rb = by_pwm[a], by_pwm[b]
        forces += [ra["force"], ra["force"] + (rb["force"] - ra["force"]) / 3.0]
        expected += ra["current"] + ra["current"] + (rb["current"] - ra["current"]) / 3.0
    forces += [0.0, 100.0]  # 0 A at rest; beyond the table the forward maximum's 16.74 A
    expected += 0.0 + 16.74
    assert T.total_current_a(np.array(forces)) == pytest.approx(expected, rel=1e-12)
