"""A depth hold of the user's own in a whole run over S100 (``vehicle_setup`` puts it in
``vehicle.controllers``): ``depth_error_m`` against the closed-form equilibrium of a P law,
and the same result for the same seed."""

from __future__ import annotations

import numpy as np
import pytest

from testbed.run import PilotSample, load_scenario, run_scenario
from testbed.vehicle.hydrodynamics import load_model
from testbed.vehicle.vehicle import Vehicle
from tests.vehicle.test_control_laws import ProportionalDepth

MODEL = load_model("bluerov2")
KP_N_PER_M = 40.0
OVERRIDES = ["duration_s=60", "metrics.settle_s=40"]


class StillPilot:
    """Centred sticks: the depth target stays the depth at arming."""

    pure_function_of_time = True

    def sample(self, t_s: float) -> PilotSample:
        return PilotSample((0.0, 0.0, 0.0, 0.0, 0.0, 0.0))


def _with_p_law(vehicle: Vehicle) -> None:
    vehicle.controllers.depth_law = ProportionalDepth(KP_N_PER_M)


def test_depth_error_is_the_p_laws_closed_form_offset_and_zero_for_the_packaged_pid() -> None:
    scenario = load_scenario("s100-teleop-v1", OVERRIDES)
    own = run_scenario(scenario, pilot=StillPilot(), vehicle_setup=_with_p_law).metrics
    packaged = run_scenario(scenario, pilot=StillPilot()).metrics
    offset = -(MODEL.buoyancy_n - MODEL.weight_n) / KP_N_PER_M  # truth − target: 5 cm high
    assert own["depth_error_m"]["mean"] == pytest.approx(offset, abs=3e-3)
    assert own["depth_error_m"]["p95"] == pytest.approx(-offset, abs=5e-3)
    assert abs(packaged["depth_error_m"]["mean"]) < 3e-3  # its integral takes the offset


def test_a_run_with_a_law_of_ones_own_is_the_same_for_the_same_seed() -> None:
    scenario = load_scenario("s100-teleop-v1", ["duration_s=20", "link.ber=1e-3"])
    runs = [run_scenario(scenario, seed=3, vehicle_setup=_with_p_law) for _ in range(2)]
    series = [run.recorder.series() for run in runs]
    for name in series[0]:
        np.testing.assert_array_equal(series[0][name], series[1][name], err_msg=name)


def test_the_link_failsafe_holds_the_depth_target_the_operator_held() -> None:
    """s100-outage-v1's 2-s outage at 60 s puts the vehicle in the failsafe's HOLD. In depth
    hold that keeps the operator's depth target (ArduSub's ``set_mode`` leaves a vehicle already
    in ALT_HOLD alone), so a P law riding B/kp above its target stays there through the HOLD;
    it climbed another B/kp at each HOLD while the HOLD re-based the target on the measured
    depth."""
    scenario = load_scenario("s100-outage-v1", ["duration_s=75", "metrics.settle_s=40"])
    series = run_scenario(scenario, pilot=StillPilot(), vehicle_setup=_with_p_law).recorder.series()
    t, target, failsafe = series["t_s"], series["depth_target_m"], series["failsafe"]
    assert np.any(failsafe[(t > 60.0) & (t < 64.0)] > 0)  # the outage did trigger the HOLD
    held = target[(t > 50.0) & (t < 60.0)]
    assert np.all(held == held[0]) and np.all(target[t >= 60.0] == held[0])
    offset = -(MODEL.buoyancy_n - MODEL.weight_n) / KP_N_PER_M
    error = series["down_m"] - target
    assert np.mean(error[t > 70.0]) == pytest.approx(offset, abs=3e-3)
