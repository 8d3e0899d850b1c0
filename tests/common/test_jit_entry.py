"""Kernels called at their machine code's entry (:func:`testbed.common.jit.entry`).

Truth: numba's own dispatcher, which checks every argument's type and compiles what it is given
(an independent route to the same machine code), and the arrays' own dtype, dimension and
layout (what the checked mode must refuse). The frame's call sites are held to their
declarations by running scenarios in a fresh process with ``TESTBED_CHECK_KERNELS=1``: a call
that passes an array of another type than declared raises there, and the results must be the
same bits as this process's unchecked run.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numba
import numpy as np
import pytest

from testbed.common import jit


@numba.njit
def _weighted(
    values: np.ndarray, weights: np.ndarray, scale: float, offset: tuple[float, float]
) -> float:
    total = offset[0] + offset[1]
    for i in range(values.size):
        total += scale * values[i] * weights[i]
    return total


def test_an_entry_gives_what_the_dispatcher_gives() -> None:
    rng = np.random.default_rng(7)
    values, weights = rng.normal(size=9), rng.normal(size=9)
    code = jit.entry(_weighted, jit.VECTOR, jit.VECTOR, jit.F64, jit.floats(2))
    assert code(values, weights, 0.5, (1.0, -2.0)) == _weighted(values, weights, 0.5, (1.0, -2.0))
    # numbers convert (an int where a float is declared), tuples are checked by the entry
    assert code(values, weights, 1, (0.0, 0.0)) == _weighted(values, weights, 1.0, (0.0, 0.0))
    with pytest.raises((TypeError, ValueError)):
        code(values, weights, 0.5, (1.0, 2.0, 3.0))


_CHECKED_MISUSE = """
import numpy as np
from testbed.common import jit
from testbed.vehicle.thrust_kernels import put_wrench
code = jit.entry(put_wrench, jit.VECTOR, jit.MARK, jit.I64, *(jit.F64,) * 6)
row, mark = np.zeros(6), np.zeros(2, dtype=np.int64)
code(row, mark, 3, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0)
assert row.tolist() == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0] and mark.tolist() == [3, 1]
for bad in (np.zeros(12)[::2], np.zeros(6, dtype=np.float32), np.zeros((1, 6))):
    try:
        code(bad, mark, 4, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    except TypeError as err:
        print("refused:", err)
    else:
        print("accepted", bad.dtype, bad.shape)
"""


def test_the_checked_mode_refuses_arrays_of_another_type() -> None:
    env = {**os.environ, "TESTBED_CHECK_KERNELS": "1"}
    done = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(_CHECKED_MISUSE)],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    declared = "declared array(float64, 1d, C)"
    assert done.stdout.splitlines() == [
        f"refused: put_wrench: argument 0 is array(float64, 1d, A), {declared}",
        f"refused: put_wrench: argument 0 is array(float32, 1d, C), {declared}",
        f"refused: put_wrench: argument 0 is array(float64, 2d, C), {declared}",
    ]


_SCENARIOS = (
    ("s100-teleop-v1", ["duration_s=15"]),  # the pilot, depth and attitude loops, the link
    ("s100-thruster-failure-v1", []),  # a thruster fault: the allocator rebuilt mid-run
    ("heavy-station-keeping-v1", ["trials=1", "duration_s=12"]),  # localization, the ISMC
    ("uvms-waypoint-v1", ["trials=1", "duration_s=12"]),  # the arm's coupled step
)
_RUN = """
import json, sys
from pathlib import Path
from testbed.run.runner import run_scenario
from testbed.run.scenario import load_scenario
out = Path(sys.argv[1])
for name, overrides in json.loads(sys.argv[2]):
    recorder = run_scenario(load_scenario(name, overrides)).recorder
    recorder.write_series_csv(out / f"{name}-series.csv")
    recorder.write_events_csv(out / f"{name}-events.csv")
"""


def _run(out: Path, checked: bool) -> None:
    env = {k: v for k, v in os.environ.items() if k != "TESTBED_CHECK_KERNELS"}
    if checked:
        env["TESTBED_CHECK_KERNELS"] = "1"
    out.mkdir()
    args = [sys.executable, "-c", _RUN, str(out), json.dumps(_SCENARIOS)]
    subprocess.run(args, env=env, capture_output=True, text=True, timeout=600, check=True)


def test_the_frames_kernels_get_the_arrays_they_declare(tmp_path: Path) -> None:
    """Every entry the scenarios call gets arrays of its declared type (checked mode raises
    otherwise), and the unchecked entries give the same bits."""
    _run(tmp_path / "checked", checked=True)
    _run(tmp_path / "plain", checked=False)
    files = sorted(p.name for p in (tmp_path / "checked").iterdir())
    assert len(files) == 2 * len(_SCENARIOS)
    for name in files:
        checked = (tmp_path / "checked" / name).read_bytes()
        assert checked == (tmp_path / "plain" / name).read_bytes(), name
        assert checked.count(b"\n") > 10, name  # the runs recorded something


def test_whole_numbers_in_configs_reach_the_kernels_as_floats() -> None:
    """A config written with whole numbers (TOML integers) gives the kernels the same float64
    arrays as one written with decimals (an int64 array at a float64 entry would be misread,
    its bits taken for tiny floats)."""
    from testbed.vehicle.control import PID, PidGains
    from testbed.vehicle.estimation import KalmanNavigator
    from testbed.vehicle.filter_values import FilterConfig
    from testbed.vehicle.nav_sensors import Measurement
    from testbed.vehicle.sensors import DepthSensor, DepthSensorConfig

    def depth_readings(config: DepthSensorConfig) -> list[float]:
        sensor = DepthSensor(config, np.random.default_rng(4))
        return [sensor.sample(0.01 * k, 2.0).depth_m for k in range(1, 20)]

    whole = DepthSensorConfig(
        rate_hz=100, noise_pa=20, water_density_kg_m3=1000, spec_grav=1, surface_pressure_pa=101325
    )
    decimal = DepthSensorConfig(
        rate_hz=100.0,
        noise_pa=20.0,
        water_density_kg_m3=1000.0,
        spec_grav=1.0,
        surface_pressure_pa=101325.0,
    )
    assert depth_readings(whole) == depth_readings(decimal)
    assert depth_readings(whole)[0] == pytest.approx(2.0, abs=0.02)

    def estimate(config: FilterConfig) -> tuple[float, ...]:
        nav = KalmanNavigator(config)
        nav.predict(0.5)
        nav.update(Measurement("fix", "position_ned", 0.5, (1.0, 2.0, 3.0), (0.1, 0.1, 0.1)))
        return nav.estimate().position_ned_m

    whole_filter = FilterConfig(initial_position_sigma_m=10, initial_velocity_sigma_m_s=1)
    assert estimate(whole_filter) == estimate(FilterConfig())
    assert estimate(whole_filter)[0] == pytest.approx(1.0, abs=0.01)

    whole_pid, decimal_pid = PID(PidGains(kp=2, ki=1)), PID(PidGains(kp=2.0, ki=1.0))
    assert whole_pid.update(0.5, 0.01) == decimal_pid.update(0.5, 0.01) == pytest.approx(1.005)


_KERNEL_MODULE = """
import numba


@numba.njit(cache=True)
def twice(x):
    return 2.0 * x
"""

_ENTER_KERNEL = """
import sys
sys.path.insert(0, sys.argv[1])
import kernel_module
from testbed.common import jit
code = jit.entry(kernel_module.twice, jit.F64)
print(code(2.5))
"""


def test_a_cold_cache_is_announced_once_before_compiling(tmp_path: Path) -> None:
    """A fresh checkout's first run compiles for many seconds: the user is told why, once, on
    stderr; a run that loads the saved kernels says nothing."""
    (tmp_path / "kernel_module.py").write_text(_KERNEL_MODULE)

    def run() -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, "-c", _ENTER_KERNEL, str(tmp_path)],
            capture_output=True,
            text=True,
            timeout=120,
            check=True,
        )

    cold = run()
    assert cold.stdout.strip() == "5.0"
    assert cold.stderr.splitlines() == [jit.COLD_CACHE_NOTICE]
    assert list((tmp_path / "__pycache__").glob("kernel_module.twice-*.nbi"))  # saved
    warm = run()
    assert warm.stdout.strip() == "5.0"
    assert warm.stderr == ""


def test_loading_a_scenario_compiles_no_autonomy_kernels() -> None:
    """The navigation filter's and the ISMC's kernels (most of a cold cache's compile time)
    are compiled when a vehicle that uses them is built, not when the run's modules load: a
    teleoperation run, or a bad scenario's one-line error, does not wait for them."""
    script = textwrap.dedent(
        """
        from testbed.run.scenario import load_scenario
        from testbed.vehicle import filter_replay, ismc_kernels
        load_scenario("s100-teleop-v1")
        print(len(filter_replay.apply_measurement.overloads), len(ismc_kernels.ismc_step.overloads))
        """
    )
    result = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=120, check=True
    )
    assert result.stdout.split() == ["0", "0"]
