"""Depth and attitude holds of the user's own (``Controllers.depth_law``/``attitude_law``):
they fly instead of the packaged PIDs, see only the sensors' readings, and what they return is
checked. Truths: the closed-form equilibria of a P law against the net buoyancy and of a
constant torque against the model's yaw damping."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pytest

from testbed.common.components import ControlTargets, DepthReading, ImuReading
from testbed.vehicle.components import ControlMode
from testbed.vehicle.control_laws import ControlLawError
from testbed.vehicle.hydrodynamics import load_model
from testbed.vehicle.vehicle import Vehicle
from testbed.vehicle.vehicle_config import VehicleConfig

MODEL = load_model("bluerov2")
NET_BUOYANCY_N = MODEL.buoyancy_n - MODEL.weight_n  # 2 N up: the hold must push down by it


class ProportionalDepth:
    """A P depth hold, world-down force kp·(target − depth), rotated into the body by the
    IMU's attitude; it keeps what it was handed."""

    def __init__(self, kp_n_per_m: float) -> None:
        self.kp = kp_n_per_m
        self.seen: list[tuple[ControlTargets, DepthReading, ImuReading]] = []
        self.resets = 0

    def reset(self) -> None:
        self.resets += 1

    def update(
        self, target: ControlTargets, depth: DepthReading, imu: ImuReading, dt_s: float
    ) -> Sequence[float]:
        self.seen.append((target, depth, imu))
        down = self.kp * (target.depth_m - depth.depth_m)
        w, x, y, z = imu.quaternion_wxyz  # NED down (0, 0, 1) in the body: R^T e_z
        return (
            down * 2.0 * (x * z - w * y),
            down * 2.0 * (y * z + w * x),
            down * (w * w - x * x - y * y + z * z),
        )


class ConstantTorque:
    """An attitude 'hold' that asks for one fixed body torque."""

    def __init__(self, torque: tuple[float, float, float]) -> None:
        self.torque = torque

    def reset(self) -> None:
        pass

    def update(
        self,
        target: ControlTargets,
        imu: ImuReading,
        dt_s: float,
        axes: tuple[bool, bool, bool],
    ) -> Sequence[float]:
        return self.torque


def _vehicle(seed: int = 0) -> Vehicle:
    return Vehicle(VehicleConfig(start_position_ned_m=(0.0, 0.0, 1.0)), np.random.default_rng(seed))


def _fly(vehicle: Vehicle, until_s: float, every_s: float = 0.1) -> None:
    """Centred sticks every ``every_s`` until ``until_s`` (fresh commands: no failsafe)."""
    while vehicle.time_s < until_s - 1e-9:
        vehicle.command((0.0,) * 6)
        vehicle.advance(min(until_s, vehicle.time_s + every_s))


def test_a_p_depth_law_flies_and_settles_where_its_gain_meets_the_net_buoyancy() -> None:
    kp = 40.0
    law = ProportionalDepth(kp)
    with _vehicle() as vehicle:
        vehicle.controllers.depth_law = law
        vehicle.arm()
        vehicle.set_mode(ControlMode.DEPTH_HOLD)
        vehicle.set_depth(1.0)
        _fly(vehicle, 20.0)
        depths = []
        while vehicle.time_s < 25.0:
            _fly(vehicle, vehicle.time_s + 0.1)
            depths.append(vehicle.truth.position_ned_m[2])
        assert law.resets == 0
        vehicle.disarm()
        _fly(vehicle, 25.1)
        assert law.resets > 0  # the hold stood down: a law that integrates starts clean
    # the packaged PID integrates the offset away (depth 1.000); a P law stops short by B/kp
    assert np.mean(depths) == pytest.approx(1.0 - NET_BUOYANCY_N / kp, abs=3e-3)
    # what it saw were the sensors' readings: noisy (20 Pa, ≈ 2 mm), never the truth's depth
    readings = [d.depth_m for _, d, _ in law.seen]
    assert all(type(d) is DepthReading for _, d, _ in law.seen)
    assert np.std(np.diff(readings[-500:])) > 1e-3


def test_an_attitude_law_turns_at_the_damping_balance_and_loses_axes_it_cannot() -> None:
    torque = 1.0  # N·m of yaw: 1 = 0.07·r + 1.55·r² at the steady turn rate r
    d_l, d_q = -MODEL.linear_damping[5], -MODEL.quadratic_damping[5]
    rate = (-d_l + math.sqrt(d_l * d_l + 4.0 * d_q * torque)) / (2.0 * d_q)
    with _vehicle() as vehicle:
        vehicle.controllers.attitude_law = ConstantTorque((0.0, 3.0, torque))
        vehicle.arm()
        vehicle.set_mode(ControlMode.STABILIZE)
        _fly(vehicle, 15.0)
        requested = vehicle.actuation.requested.copy()
        rates = []
        while vehicle.time_s < 20.0:
            _fly(vehicle, vehicle.time_s + 0.1)
            rates.append(vehicle.truth.rates_rad_s[2])
    assert not vehicle.controllers.attitude_axes[1]  # the standard frame cannot pitch
    assert requested[4] == 0.0  # so the law's 3 N·m of pitch was dropped
    assert np.mean(rates) == pytest.approx(rate, rel=0.02)


@pytest.mark.parametrize("value", [(math.nan, 0.0, 0.0), (1.0, 2.0), "abc", None])
def test_a_law_returning_no_three_finite_numbers_is_one_line_naming_its_class(
    value: object,
) -> None:
    class Broken(ProportionalDepth):
        def update(self, *args: object) -> Sequence[float]:  # type: ignore[override]  # bad law
            return value  # type: ignore[return-value]  # what is tested

    with _vehicle() as vehicle:
        vehicle.controllers.depth_law = Broken(1.0)
        vehicle.arm()
        vehicle.set_mode(ControlMode.DEPTH_HOLD)
        with pytest.raises(ControlLawError, match=r"^test_.*Broken \(.*test_control_laws\.py\)"):
            _fly(vehicle, 1.0)


def test_a_law_of_a_class_without_a_source_file_is_named_by_its_class(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A law defined in a REPL or ``python -c`` (its module has no file): the broken answer's
    message names the class; building it raised OSError from ``inspect.getsourcefile`` before
    the law and link-model messages shared one describer (config.described_class)."""
    import sys
    import types

    from testbed.vehicle.control_laws import ControlLawError, checked_vector

    monkeypatch.setitem(sys.modules, "__main__", types.ModuleType("__main__"))
    law = type("Typed", (), {"__module__": "__main__"})()
    with pytest.raises(ControlLawError, match=r"^Typed: update returned \[1.0\]: expected"):
        checked_vector(law, [1.0], "force")
