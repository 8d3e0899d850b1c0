"""The recorded pilot (``[pilot] kind = "recorded"``): a run's sticks replayed open loop.

Truth: (1) a scripted run's own ``series.csv`` — replayed over the same scenario, the replay's
``cmd_*`` columns equal the recording's, text for text, at every row; the sticks the vehicle
applied differ by at most the int8 codes the hold's lag can move them, a bound from the scripted
pilot's sine terms in closed form; the track departs by no more than twice what a pilot one
full row late (the hold's largest lag) makes it depart. (2) Hand-written files for the hold's
semantics and each load error, through the CLI: :func:`testbed.cli.main.main` in this process
(the line and exit code it returns are the command's), and a missing recording through the real
command line (a subprocess, as a user runs it). (3) A sweep over ``link.ber``, in this process.
"""

from __future__ import annotations

import csv
import json
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from testbed.cli.main import main
from testbed.config import ConfigError
from testbed.operator.pilots import PURE_PILOTS, is_pure
from testbed.operator.recorded_pilot import RecordedPilot, load_recorded_pilot
from testbed.protocol.orders import AXIS_SCALE
from testbed.run.scenario import load_scenario
from testbed.run.scenario_files import scenario_dir
from tests.processes import Runner, in_process, one_error_line, run_testbed

HEADER = "t_s,cmd_x,cmd_y,cmd_z,cmd_yaw,rx_x\n"


@pytest.fixture
def testbed(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> Runner:
    """``testbed ARGS`` run in this process (:func:`tests.processes.run_main`)."""
    return in_process(monkeypatch, capsys)


def _write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def _replay_scenario(folder: Path, file: str, extra: str = "", duration_s: float = 120.0) -> Path:
    """s100-teleop-v1 with its pilot replaced by ``kind = "recorded"`` of ``file``."""
    text = scenario_dir().joinpath("s100-teleop-v1.toml").read_text(encoding="utf-8")
    head, _, rest = text.partition("[pilot]")
    _, _, tail = rest.partition("[metrics]")
    head = head.replace('id = "s100-teleop-v1"', 'id = "s100-replay-v1"')
    head = re.sub(r"duration_s = [0-9.]+", f"duration_s = {duration_s}", head)
    pilot = f'[pilot]\nkind = "recorded"\nfile = "{file}"\n{extra}\n'
    return _write(folder / "replay.toml", f"{head}{pilot}[metrics]{tail}")


def _series(path: Path) -> tuple[list[str], list[list[str]]]:
    with path.open(encoding="utf-8") as handle:
        rows = list(csv.reader(handle))
    return rows[0], rows[1:]


# --- the hold -------------------------------------------------------------------------------


def test_the_hold_gives_the_last_row_at_or_before_t_and_centred_sticks_outside(
    tmp_path: Path,
) -> None:
    rows = "1,0.1,0.2,0.3,0.4,9\n\n2,-1,1,-0.5,0.25,9\n3,0.5,0,0,-1,nan\n"  # a blank line
    pilot = load_recorded_pilot(_write(tmp_path / "s.csv", HEADER + rows))
    assert pilot.sample(0.999).sticks == (0.0,) * 6  # before the first row
    assert pilot.sample(1.0).sticks == (0.1, 0.2, 0.3, 0.0, 0.0, 0.4)
    assert pilot.sample(1.999).sticks == (0.1, 0.2, 0.3, 0.0, 0.0, 0.4)
    assert pilot.sample(2.0).sticks == (-1.0, 1.0, -0.5, 0.0, 0.0, 0.25)
    assert pilot.sample(3.0).sticks == (0.5, 0.0, 0.0, 0.0, 0.0, -1.0)
    assert pilot.sample(3.001).sticks == (0.0,) * 6  # after the last row
    assert pilot.sample(1e6).sticks == (0.0,) * 6
    later = pilot.shifted(10.0)  # shift_s: the same rows 10 s later
    assert later.sample(11.5).sticks == pilot.sample(1.5).sticks
    assert later.sample(10.5).sticks == (0.0,) * 6
    assert is_pure(pilot) and type(pilot) in PURE_PILOTS  # the recorder samples it again


def test_a_row_is_in_force_from_the_instant_its_six_digit_time_was_rounded_from(
    tmp_path: Path,
) -> None:
    """series.csv writes 6 significant digits: 7/240 s (a physics instant at 240 Hz) is written
    0.0291667, later than itself; the row must be in force at 7/240 all the same."""
    t = 7.0 / 240.0
    assert float(f"{t:.6g}") > t
    rows = f"0,0,0,0,0,0\n{t:.6g},0.5,0,0,0,0\n{2 * t:.6g},0.25,0,0,0,0\n"
    pilot = load_recorded_pilot(_write(tmp_path / "s.csv", HEADER + rows))
    assert pilot.sample(t).sticks[0] == 0.5
    assert pilot.sample(2 * t).sticks[0] == 0.25  # the last row, until its rounding ends
    assert pilot.sample(2 * t + 1e-6).sticks[0] == 0.0
    assert pilot.sample(t - 1e-6).sticks[0] == 0.0  # not earlier than the rounding allows


# --- load errors ----------------------------------------------------------------------------

BAD_FILES = [
    ("t_s,cmd_x,cmd_z,cmd_yaw\n0,0,0,0\n", r"line 1: missing column cmd_y"),
    ("t_s,cmd_x,cmd_y\n0,0,0\n", r"line 1: missing columns cmd_z, cmd_yaw"),
    (HEADER + "0,0,0,0,0,0\n1,0,zero,0,0,0\n", r"line 3: cmd_y: expected a number, got 'zero'"),
    (HEADER + "0,0,0,nan,0,0\n", r"line 2: cmd_z: must be finite, got nan"),
    (HEADER + "inf,0,0,0,0,0\n", r"line 2: t_s: must be finite, got inf"),
    (HEADER + "0,0,0,0,0,0\n\n1,0,0,0,0,0\n-inf,0,0,0,0,0\n", r"line 5: t_s: must be finite"),
    (HEADER + "0,0,0,0,1.5,0\n", r"line 2: cmd_yaw: a stick must be in \[-1, 1\], got 1.5"),
    (HEADER + "0,-1.01,0,0,0,0\n", r"line 2: cmd_x: a stick must be in \[-1, 1\], got -1.01"),
    (HEADER + "1,0,0,0,0,0\n1,0,0,0,0,0\n", r"line 3: t_s: times must increase, got 1 after 1"),
    (HEADER + "1,0,0,0,0,0\n0.5,0,0,0,0,0\n", r"line 3: t_s: times must increase"),
    (HEADER + "0,0,0,0,0\n", r"line 2: 5 fields, expected 6"),
    (HEADER, r"no data lines after the header"),
    ("", r"empty file"),
    (HEADER + "0," + "1" * 70000 + "\n", r"line 2: longer than 65536 characters"),
]


@pytest.mark.parametrize(("text", "problem"), BAD_FILES)
def test_a_bad_file_is_one_line_naming_the_file_line_and_column(
    tmp_path: Path, text: str, problem: str
) -> None:
    path = _write(tmp_path / "bad.csv", text)
    with pytest.raises(ConfigError) as info:
        load_recorded_pilot(path)
    message = str(info.value)
    assert "\n" not in message
    assert re.match(rf"^{re.escape(str(path))}: {problem}", message), message


def test_a_missing_file_and_a_folder_are_refused(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"nothing.csv: file not found$"):
        load_recorded_pilot(tmp_path / "nothing.csv")
    with pytest.raises(ConfigError, match=r": (not a file|cannot read)"):
        load_recorded_pilot(tmp_path)


def test_the_scenario_keys_belong_to_kind_recorded(tmp_path: Path) -> None:
    _write(tmp_path / "s.csv", HEADER + "0,0,0,0,0,0\n1,0.5,0,0,-0.5,0\n")
    scenario = _replay_scenario(tmp_path, "s.csv")
    loaded = load_scenario(str(scenario))  # the file is the scenario folder's
    assert isinstance(loaded.pilot.pilot(), RecordedPilot)
    assert str(tmp_path / "s.csv") in dict(loaded.files)  # its SHA-256 is recorded
    with pytest.raises(ConfigError, match=r"^--set: pilot.start_s: not used when kind = 'rec"):
        load_scenario(str(scenario), ["pilot.start_s=3"])
    with pytest.raises(ConfigError, match=r"^--set: pilot.file: required when kind = 'rec"):
        load_scenario(str(scenario), ["pilot.file=''"])
    with pytest.raises(ConfigError, match=r"^--set: pilot.file: only used when kind = 'rec"):
        load_scenario("s100-teleop-v1", ["pilot.file=x.csv"])
    with pytest.raises(ConfigError, match=r"^--set: pilot.shift_s: only used when kind = 'rec"):
        load_scenario("s100-teleop-v1", ["pilot.shift_s=2"])
    for bad in ("nan", "inf", "-1e308"):
        with pytest.raises(
            ConfigError, match=r"^--set: pilot.shift_s: (must be in|expected a number)"
        ):
            load_scenario(str(scenario), [f"pilot.shift_s={bad}"])
    early = load_scenario(str(scenario), ["pilot.shift_s=-1"]).pilot.pilot()
    assert early.sample(0.0).sticks == loaded.pilot.pilot().sample(1.0).sticks
    assert early.sample(0.0).sticks == (0.5, 0.0, 0.0, 0.0, 0.0, -0.5)


@pytest.mark.parametrize(
    "first", ["testbed.operator.recorded_pilot", "testbed.operator.pilots", "testbed.run.sections"]
)
def test_the_modules_import_in_any_order(first: str) -> None:
    """pilots lists the recorded pilot among its pure ones; the recorded pilot needs pilots'
    PilotSample only when it samples, so neither import order is a cycle."""
    code = f"import {first}; from testbed.operator.pilots import PURE_PILOTS; print(PURE_PILOTS)"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert done.returncode == 0 and "RecordedPilot" in done.stdout, done.stderr


@pytest.mark.parametrize(("text", "problem"), [BAD_FILES[2], BAD_FILES[5], BAD_FILES[7]])
def test_cli_refuses_a_bad_recording_in_one_line(
    tmp_path: Path, testbed: Runner, text: str, problem: str
) -> None:
    _write(tmp_path / "bad.csv", text)
    scenario = _replay_scenario(tmp_path, "bad.csv")
    line = one_error_line(testbed(["run", str(scenario), "--out", "out"], tmp_path))
    assert line.startswith(f"testbed: error: {scenario}: pilot.file: {tmp_path / 'bad.csv'}: ")
    assert re.search(problem, line), line
    assert not (tmp_path / "out").exists()


def test_cli_refuses_a_missing_recording_in_one_line(tmp_path: Path) -> None:
    scenario = _replay_scenario(tmp_path, "gone/series.csv")
    line = one_error_line(run_testbed(["run", str(scenario)], tmp_path))
    assert line == (
        f"testbed: error: {scenario}: pilot.file: {tmp_path / 'gone/series.csv'}: file not found"
    )


def test_a_replay_shorter_than_the_scripted_start_runs(tmp_path: Path) -> None:
    """pilot.start_s (5 s by default, refused with kind = "recorded") does not bound it."""
    _write(tmp_path / "s.csv", HEADER + "0,0.5,0,0,0,0\n3,0,0,0,0,0\n")
    scenario = _replay_scenario(tmp_path, "s.csv", duration_s=4.0)
    text = scenario.read_text(encoding="utf-8")
    _write(scenario, re.sub(r"settle_s = [0-9.]+", "settle_s = 0.0", text))
    loaded = load_scenario(str(scenario))
    assert loaded.duration_s == 4.0 and loaded.pilot.start_s == 5.0


def test_a_recording_that_never_ends_is_one_line(tmp_path: Path, testbed: Runner) -> None:
    """A scenario naming a .csv that is /dev/zero: no line ends, never read whole."""
    (tmp_path / "zero.csv").symlink_to("/dev/zero")
    scenario = _replay_scenario(tmp_path, "zero.csv")
    line = one_error_line(testbed(["run", str(scenario)], tmp_path))
    assert line.endswith("zero.csv: line 1: longer than 65536 characters (not a series.csv)")


def test_an_edited_recording_is_read_again(tmp_path: Path) -> None:
    """A scenario is built once per text of its files in a process; the recording's edit
    (same size, other sticks) is seen."""
    sticks = _write(tmp_path / "s.csv", HEADER + "0,0.5,0,0,0,0\n1,0,0,0,0,0\n")
    scenario = _replay_scenario(tmp_path, "s.csv")
    assert load_scenario(str(scenario)).pilot.pilot().sample(0.5).sticks[0] == 0.5
    _write(sticks, HEADER + "0,0.7,0,0,0,0\n1,0,0,0,0,0\n")
    assert load_scenario(str(scenario)).pilot.pilot().sample(0.5).sticks[0] == 0.7


# --- the replay -----------------------------------------------------------------------------

STICKS = ("cmd_x", "cmd_y", "cmd_z", "cmd_yaw")
APPLIED = ("rx_x", "rx_y", "rx_z", "rx_yaw")
TRACK = ("north_m", "east_m", "down_m", "yaw_deg")


def _max_slope(terms: tuple[object, ...]) -> float:
    """The largest |ds/dt| [1/s] of a stick Σ a·sin(2πτ/T + φ): Σ 2π|a|/T (clip keeps it)."""
    return math.fsum(2.0 * math.pi * abs(t.amplitude) / t.period_s for t in terms)  # type: ignore[attr-defined]


def test_a_scripted_run_replayed_gives_its_sticks_back(tmp_path: Path) -> None:
    for out, extra in (("A", []), ("late", ["--set", "pilot.start_s=5.05"])):
        assert (
            main(["run", "s100-teleop-v1", "--out", str(tmp_path / out), "--no-plots", *extra]) == 0
        )
    scenario = _replay_scenario(tmp_path, "A/series.csv")
    assert main(["run", str(scenario), "--out", str(tmp_path / "B"), "--no-plots"]) == 0
    header, recorded = _series(tmp_path / "A" / "series.csv")
    replay_header, replayed = _series(tmp_path / "B" / "series.csv")
    assert replay_header == header and len(replayed) == len(recorded) == 2400
    col = {name: header.index(name) for name in header}
    # 1. The recorder samples the replay at the recording's instants: each row's own sticks,
    # as written (6 significant digits round-trip), at every row.
    for name in ("t_s", *STICKS):
        assert [r[col[name]] for r in replayed] == [r[col[name]] for r in recorded], name
    # 2. What the vehicle flew: the operator samples the hold at its own slots, up to one row
    # (Δ = 0.05 s) after the row's instant, so its stick lags the continuous one by at most
    # slope·Δ (+ the 6-digit rounding); as int8 codes at most ⌊127·slope·Δ⌋ + 1 apart.
    pilot = load_scenario("s100-teleop-v1").pilot
    period_s = 1.0 / load_scenario("s100-teleop-v1").metrics.sample_rate_hz
    a, b = np.array(recorded, dtype=float), np.array(replayed, dtype=float)
    for name, terms in zip(APPLIED, (pilot.x, pilot.y, pilot.z, pilot.yaw), strict=True):
        lag = _max_slope(terms) * period_s + 1e-5
        codes = math.floor(AXIS_SCALE * lag) + 1
        moved = np.abs(a[:, col[name]] - b[:, col[name]]) * AXIS_SCALE
        assert moved.max() <= codes + 1e-3, (name, moved.max(), codes)
        assert moved.max() > 0  # the hold does lag: the check has teeth
    # 3. The track: within twice the departure of a pilot one full row late (start_s + Δ).
    _, late_rows = _series(tmp_path / "late" / "series.csv")
    late = np.array(late_rows, dtype=float)
    for name in TRACK:
        tolerance = 2.0 * np.abs(late[:, col[name]] - a[:, col[name]]).max()
        departure = np.abs(b[:, col[name]] - a[:, col[name]]).max()
        assert departure <= tolerance, (name, departure, tolerance)
    inputs = json.loads((tmp_path / "B" / "metrics.json").read_text())["inputs"]
    assert str(tmp_path / "A" / "series.csv") in inputs["files"]


def test_a_ber_sweep_over_a_recorded_pilot_runs(tmp_path: Path, testbed: Runner) -> None:
    rows = "".join(f"{k * 0.05:.6g},0.5,0,0,0.25,0\n" for k in range(200))  # 10 s
    _write(tmp_path / "sticks.csv", HEADER + rows)
    _replay_scenario(tmp_path, "sticks.csv", duration_s=12.0)
    _write(
        tmp_path / "sweep.toml",
        'schema = 1\nid = "replay-vs-ber-v1"\ndescription = "recorded sticks over BER"\n'
        'scenario = "replay.toml"\nseeds = 1\nmetrics = ["link.uplink.per", "energy_wh"]\n\n'
        '[grid]\n"link.ber" = [0.0, 1e-3]\n',
    )
    out = tmp_path / "sweep-out"
    sweep = ["sweep", str(tmp_path / "sweep.toml"), "--workers", "1", "--out", str(out)]
    done = testbed(sweep, tmp_path)
    assert done.returncode == 0, done.stderr
    with (out / "results.csv").open(encoding="utf-8") as handle:
        results = list(csv.DictReader(handle))
    assert [float(r["link.ber"]) for r in results] == [0.0, 1e-3]
    assert all(r["status"] == "ok" for r in results), results
    with (tmp_path / "sticks.csv").open("a", encoding="utf-8") as handle:
        handle.write("10,0,0,0,0,0\n")  # an edited recording is another input
    again = one_error_line(testbed([*sweep, "--resume"], tmp_path))
    assert f"input {tmp_path / 'sticks.csv'}: changed (SHA-256" in again
