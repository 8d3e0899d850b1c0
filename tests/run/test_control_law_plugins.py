"""Depth and attitude holds of the user's own named in scenario files (``[vehicle.control]``,
:func:`testbed.run.plugin_calls.scenario_control_laws`): they reach sweeps and trials, which take no
``vehicle_setup`` hook. Truths: a P depth law's closed-form offset −B/kp at each sweep point,
the same run with the law put in through ``vehicle_setup`` (a second method), one seed making
one result; and one line, exit 2, for every way the name, its arguments or its object can be
wrong."""

from __future__ import annotations

import csv
import hashlib
import textwrap
from pathlib import Path

import numpy as np
import pytest

from testbed.cli.main import main
from testbed.run.plugins import load_factory
from testbed.run.runner import run_scenario
from testbed.run.scenario import load_scenario
from testbed.run.trials import run_trials
from testbed.sweep import load_sweep, run_sweep
from testbed.vehicle.hydrodynamics import load_model
from testbed.vehicle.vehicle import Vehicle
from tests.vehicle.test_control_laws import ProportionalDepth

NET_BUOYANCY_N = load_model("bluerov2").buoyancy_n - load_model("bluerov2").weight_n

LAWS = '''
class PDepth:
    """A P depth hold: world-down force kp·(target − depth), into the body by the IMU's
    attitude; counts the laws made."""

    made = 0

    def __init__(self, kp=40.0):
        PDepth.made += 1
        self.kp = kp

    def reset(self):
        pass

    def update(self, target, depth, imu, dt_s):
        down = self.kp * (target.depth_m - depth.depth_m)
        w, x, y, z = imu.quaternion_wxyz
        return (
            down * 2.0 * (x * z - w * y),
            down * 2.0 * (y * z + w * x),
            down * (w * w - x * x - y * y + z * z),
        )


class UpdateOnly:
    def update(self, target, imu, dt_s, axes):
        return (0.0, 0.0, 0.0)


def no_law():
    return 42


def failing(kp):
    raise RuntimeError(f"no law at {kp}")
'''

SCENARIO = """\
schema = 1
id = "still-v1"
description = "centred sticks in depth hold"
duration_s = 60.0
[link]
preset = "s100"
[pilot]
kind = "scripted"
[metrics]
settle_s = 40.0
"""


@pytest.fixture
def study(tmp_path: Path) -> Path:
    """A folder with the user's laws and a still scenario, and one naming the P law."""
    folder = tmp_path / "study"
    folder.mkdir()
    (folder / "laws.py").write_text(LAWS)
    (folder / "still.toml").write_text(SCENARIO)
    law = '[vehicle.control]\ndepth = "laws.py:PDepth"\ndepth_args = { kp = 40.0 }\n'
    (folder / "p.toml").write_text(SCENARIO.replace("[pilot]", law + "[pilot]"))
    return folder


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as file:
        return list(csv.DictReader(file))


def test_a_sweep_of_a_p_laws_gain_settles_at_its_closed_form_and_as_a_direct_run(
    study: Path, tmp_path: Path
) -> None:
    """A sweep file in another folder names the law by a path of its own folder and sweeps
    kp; at each point ``depth_error_m.mean`` is −B/kp (truth − target: held B/kp shallow), and
    equals a direct run of the scenario with the same P law put in by ``vehicle_setup``."""
    elsewhere = tmp_path / "sweeps"
    (elsewhere / "lib").mkdir(parents=True)
    (elsewhere / "lib" / "laws.py").write_text(LAWS)
    sweep_file = elsewhere / "gain.toml"
    sweep_file.write_text(
        textwrap.dedent(
            f"""\
            schema = 1
            id = "gain-v1"
            description = "a P depth law's gain"
            scenario = "{study / "still.toml"}"
            seeds = 1
            metrics = ["depth_error_m.mean"]
            [set]
            "vehicle.control.depth" = "lib/laws.py:PDepth"
            [grid]
            "vehicle.control.depth_args.kp" = [40.0, 80.0]
            """
        )
    )
    out = tmp_path / "out"
    summary = run_sweep(load_sweep(str(sweep_file)), out, workers=2)
    assert summary.failed == () and summary.ran == 2
    errors = [float(row["depth_error_m.mean"]) for row in _rows(out / "results.csv")]
    scenario = load_scenario(str(study / "still.toml"))
    for kp, error in zip((40.0, 80.0), errors, strict=True):
        assert error == pytest.approx(-NET_BUOYANCY_N / kp, abs=3e-3)

        def with_law(vehicle: Vehicle, kp: float = kp) -> None:
            vehicle.controllers.depth_law = ProportionalDepth(kp)

        direct = run_scenario(scenario, seed=0, vehicle_setup=with_law).metrics
        assert error == direct["depth_error_m"]["mean"]
        assert direct["inputs"]["depth_law"] == {
            "object": f"{ProportionalDepth.__module__}.ProportionalDepth"
        }
    assert errors[0] == pytest.approx(2.0 * errors[1], abs=3e-3)


def test_trials_with_a_law_make_one_law_each_and_one_seed_one_result(
    study: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Two trials at BER 1e-3 (the link's draws matter) from another working directory: the
    factory is called once a trial, the seeds' runs differ, the same seed writes the same
    bytes; metrics.json records the law and its file's SHA-256."""
    monkeypatch.chdir(tmp_path)
    scenario = load_scenario(
        str(study / "p.toml"), ["duration_s=20", "metrics.settle_s=5", "link.ber=1e-3", "trials=2"]
    )
    made = load_factory(f"{study / 'laws.py'}:PDepth", "test", "law")
    before = made.made
    first, again = tmp_path / "first", tmp_path / "again"
    for out in (first, again):
        out.mkdir()
        assert run_trials(scenario, out, seed=7).stopped is None
    assert made.made - before == 4
    one = (first / "trial-1" / "series.csv").read_bytes()
    assert one != (first / "trial-2" / "series.csv").read_bytes()
    for trial in ("trial-1", "trial-2"):
        for name in ("series.csv", "events.csv"):
            assert (first / trial / name).read_bytes() == (again / trial / name).read_bytes()
    result = run_scenario(scenario, seed=7)
    inputs = result.metrics["inputs"]
    assert inputs["depth_law"] == {"factory": f"{study / 'laws.py'}:PDepth", "args": {"kp": 40.0}}
    assert "attitude_law" not in inputs
    law_file = str(study / "laws.py")
    assert inputs["files"][law_file] == hashlib.sha256(LAWS.encode()).hexdigest()


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ("vehicle.control.depth=nofile.py:PDepth", "vehicle.control.depth: no such file: /"),
        (
            "vehicle.control.depth=laws.py:Missing",
            "vehicle.control.depth: laws.py has no 'Missing'",
        ),
        ("vehicle.control.attitude=laws", "vehicle.control.attitude: expected 'FILE.py:NAME'"),
        (
            "vehicle.control.depth_args={kp=1.0, ki=2.0}",
            "vehicle.control.depth_args: laws.py:PDepth: got an unexpected keyword argument 'ki'",
        ),
        (
            "vehicle.control.attitude=laws.py:failing",
            "vehicle.control.attitude_args: laws.py:failing: missing a required argument: 'kp'",
        ),
        (
            "vehicle.control.attitude_args={kp=1.0}",
            "vehicle.control.attitude_args: only used with vehicle.control.attitude",
        ),
        (
            "vehicle.control.depht=laws.py:PDepth",
            "vehicle.control.depht: unknown key (known: attitude, attitude_args, depth, "
            "depth_args)",
        ),
        ("vehicle.controls.depth=laws.py:PDepth", "vehicle.controls: unknown key (known: "),
        ("vehicle.control=3", "vehicle.control: expected a table"),
    ],
)
def test_a_wrong_law_name_or_argument_is_one_line_naming_the_key_and_exit_2(
    study: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    override: str,
    message: str,
) -> None:
    monkeypatch.chdir(study)
    out = study / "out"
    code = main(["run", "p.toml", "--set", override, "--out", str(out), "--no-plots"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("testbed: error: --set: "), err
    assert message in err, err
    assert not out.exists()


def test_the_unknown_vehicle_key_lists_control(
    study: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(study)
    assert main(["run", "p.toml", "--set", "vehicle.controls.depth=laws.py:PDepth"]) == 2
    assert "camera, control, control_rate_hz, current" in capsys.readouterr().err


def test_what_the_law_factory_makes_is_checked_before_the_run_one_line_exit_2(
    study: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A factory that raises, or makes no law (no ``reset``/``update``), stops the run before
    its first frame with one line naming where the law came from (here ``--set``) and the
    keys."""
    monkeypatch.chdir(study)
    cases = [
        (
            ["vehicle.control.depth=laws.py:failing", "vehicle.control.depth_args={kp=5.0}"],
            "--set: vehicle.control.depth, vehicle.control.depth_args (called with "
            "vehicle.control.depth_args = {'kp': 5.0}): RuntimeError: no law at 5.0",
        ),
        (
            ["vehicle.control.depth=laws.py:no_law", "vehicle.control.depth_args={}"],
            "--set: vehicle.control.depth: laws.py:no_law made a int without reset and update "
            "(expected a DepthLaw: reset() and update(target, depth, imu, dt_s)",
        ),
        (
            ["vehicle.control.attitude=laws.py:UpdateOnly"],
            "--set: vehicle.control.attitude: laws.py:UpdateOnly made a UpdateOnly without "
            "reset (expected an AttitudeLaw",
        ),
    ]
    for overrides, message in cases:
        args = [item for o in overrides for item in ("--set", o)]
        out = study / "out"
        code = main(["run", "p.toml", *args, "--out", str(out), "--no-plots"])
        err = capsys.readouterr().err
        assert code == 2, err
        assert err.count("\n") == 1 and message in err, err
        assert not out.exists()


def test_the_docs_law_and_scenario_table_run_as_written(tmp_path: Path) -> None:
    """docs/vehicle.md's ``MyDepth`` (its example up to the ``run_scenario`` line) named by the
    docs' ``[vehicle.control]`` table: with the net buoyancy fed forward it holds the target;
    without (``buoyancy_n = 0``) a PD settles where a P law does, −B/kp."""
    root = Path(__file__).resolve().parents[2]
    docs = (root / "docs" / "vehicle.md").read_text(encoding="utf-8")
    section = docs.split("## A depth or attitude hold of your own", 1)[1]
    example = section.split("```python\n", 1)[1].split("\nrun_scenario(", 1)[0]
    table = section.split("```toml\n", 1)[1].split("```", 1)[0]
    (tmp_path / "my_laws.py").write_text(example)
    (tmp_path / "docs.toml").write_text(SCENARIO.replace("[pilot]", table + "[pilot]"))
    kp = load_scenario(str(tmp_path / "docs.toml")).control_laws.depth_args["kp"]
    fed = run_scenario(load_scenario(str(tmp_path / "docs.toml"))).metrics["depth_error_m"]
    assert abs(fed["mean"]) < 3e-3
    unfed = ["vehicle.control.depth_args={kp=60.0, kd=40.0, buoyancy_n=0.0}"]
    pd = run_scenario(load_scenario(str(tmp_path / "docs.toml"), unfed)).metrics["depth_error_m"]
    assert kp == 60.0 and pd["mean"] == pytest.approx(-NET_BUOYANCY_N / kp, abs=3e-3)


def test_the_live_and_mavlink_vehicles_fly_the_scenarios_law(study: Path) -> None:
    """``testbed live`` and ``testbed mavlink`` build their vehicles from the scenario too: each
    holds a law the file's factory made for it, with the scenario's kp."""
    import simpy

    from testbed.channel import Trace
    from testbed.live.hub import Hub
    from testbed.live.session import LiveSession
    from testbed.run.mavlink_run import MavlinkVehicleNode
    from testbed.run.recorder import Recorder

    scenario = load_scenario(str(study / "p.toml"))
    session = LiveSession(scenario, Hub(), pilot=None)
    node = MavlinkVehicleNode(
        simpy.Environment(), scenario, np.random.default_rng(0), [], Recorder(trace=Trace())
    )
    try:
        for vehicle in (session.vehicle, node.vehicle):
            law = vehicle.controllers.depth_law
            assert type(law).__name__ == "PDepth" and getattr(law, "kp", None) == 40.0
            assert vehicle.controllers.attitude_law is None
    finally:
        session.vehicle.close()
        node.vehicle.close()
