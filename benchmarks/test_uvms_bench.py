"""Vehicle-manipulator kinematics and TPIK cost, in µs per call.

The manipulator's 30-Hz TPIK input (``manipulation._tpik_input``) needs the end effector's NED
pose and the UVMS Jacobian; the recorder and the autonomy ask the FK at 20 Hz, on a 100-Hz
vehicle that must run many times faster than real time.

1. Kinematics, measured interleaved in the same run so machine noise hits all alike:
   ``two calls`` (:func:`end_effector_ned` then :func:`uvms_jacobian`, as the TPIK input was
   built), ``uvms_kinematics`` (both from one chain walk) and ``end_effector_ned`` alone; the
   ratio two calls / one is the figure to compare between runs.
2. :func:`solve_uvms` per call on the Alpha 5 + Heavy at the packaged configuration: the usual
   case (no joint in its activation band: one mode) and with one and two joints in their bands
   (2 and 4 modes solved).

Run:

    .venv/bin/python -m pytest benchmarks/test_uvms_bench.py -m benchmark --benchmark-enable -s
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable

import numpy as np
import pytest
from pytest_benchmark.fixture import BenchmarkFixture

from testbed.common.geometry import quat_from_euler
from testbed.vehicle.arm import ArmModel, load_arm_model
from testbed.vehicle.arm_kinematics import end_effector_ned, uvms_jacobian, uvms_kinematics
from testbed.vehicle.tpik import TpikConfig, TpikInput, load_tpik_config, solve_uvms

pytestmark = pytest.mark.benchmark

CALLS = 500
ROUNDS = 15
POSITION = np.array([1.0, -2.0, 3.0])
QUATERNION = np.array(quat_from_euler(0.05, -0.03, 0.7))


def _per_call_us(fn: Callable[[], object]) -> float:
    start = time.perf_counter()
    for _ in range(CALLS):
        fn()
    return (time.perf_counter() - start) / CALLS * 1e6


def _interleaved(cases: dict[str, Callable[[], object]]) -> dict[str, list[float]]:
    """µs per call of each case, ROUNDS rounds, the cases taking turns within each round."""
    times: dict[str, list[float]] = {name: [] for name in cases}
    for fn in cases.values():
        fn()  # warm caches (the model's fixed chain) before timing
    for _ in range(ROUNDS):
        for name, fn in cases.items():
            times[name].append(_per_call_us(fn))
    return times


def test_uvms_kinematics_against_two_calls(benchmark: BenchmarkFixture) -> None:
    model = load_arm_model()
    q = np.array(model.initial_q_rad)

    def two_calls() -> object:
        end_effector_ned(model, q, POSITION, QUATERNION)
        return uvms_jacobian(model, q, QUATERNION)

    cases: dict[str, Callable[[], object]] = {
        "two calls": two_calls,
        "uvms_kinematics": lambda: uvms_kinematics(model, q, POSITION, QUATERNION),
        "end_effector_ned": lambda: end_effector_ned(model, q, POSITION, QUATERNION),
    }
    times = _interleaved(cases)
    for name, values in times.items():
        best, median = min(values), statistics.median(values)
        benchmark.extra_info[f"{name}_us_min"] = best
        benchmark.extra_info[f"{name}_us_median"] = median
        print(f"\n{name}: {best:.1f} µs/call (median {median:.1f})")
    ratio = min(times["two calls"]) / min(times["uvms_kinematics"])
    benchmark.extra_info["two_calls_over_uvms_kinematics"] = ratio
    print(f"two calls / uvms_kinematics: {ratio:.2f}×")
    benchmark.pedantic(cases["uvms_kinematics"], rounds=200, warmup_rounds=10)


def _tpik_input(model: ArmModel, config: TpikConfig, in_band: int) -> TpikInput:
    """A state near the packaged start with the first ``in_band`` limit tasks' joints just
    inside their low activation band, the target 0.15 m away."""
    q = np.array(model.initial_q_rad, dtype=float)
    for task in config.limit_tasks[:in_band]:
        q[task.joint] = task.low_threshold - 0.01
    ee_position, ee_rotation, jac = uvms_kinematics(model, q, POSITION, QUATERNION)
    return TpikInput(
        q=q,
        position_ned_m=POSITION,
        quaternion_wxyz=QUATERNION,
        ee_position_ned_m=ee_position,
        ee_rotation_ned=ee_rotation,
        uvms_jacobian=jac,
        target_position_ned_m=ee_position + np.array([0.1, 0.05, -0.1]),
        target_rotation_ned=None,
        target_yaw_rad=0.7,
        target_velocity_ned_m_s=np.zeros(3),
    )


def test_solve_uvms_per_call(benchmark: BenchmarkFixture) -> None:
    model, config = load_arm_model(), load_tpik_config()
    inputs = {k: _tpik_input(model, config, k) for k in (0, 1, 2)}
    cases: dict[str, Callable[[], object]] = {}
    for k, state in inputs.items():
        modes = solve_uvms(config, state).mode_count
        assert modes == 2**k
        cases[f"solve_uvms, {modes} mode{'s' if modes > 1 else ''}"] = lambda state=state: (
            solve_uvms(config, state)
        )
    times = _interleaved(cases)
    for name, values in times.items():
        best, median = min(values), statistics.median(values)
        benchmark.extra_info[f"{name}_us_min"] = best
        benchmark.extra_info[f"{name}_us_median"] = median
        print(f"\n{name}: {best:.1f} µs/call (median {median:.1f})")
    benchmark.pedantic(lambda: solve_uvms(config, inputs[0]), rounds=200, warmup_rounds=10)
