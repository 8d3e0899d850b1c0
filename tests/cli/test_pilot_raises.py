"""A pilot of the user's that raises, or samples what a run cannot fly, driven through the
command line: :func:`testbed.cli.main.main` in this process, and for one case of each mode
family through the real command line (a subprocess, as a user runs it): a stateful pilot
raising in ``testbed run``, and ``testbed hil``. The subject here is the error line and what is
kept, which ``main`` returns and writes the same in or out of a child; the children check that
nothing between the console script and ``main`` changes them, and spare the others a child's
start-up (≈ 1 s each).

Before, a pilot whose ``sample`` (or ``see``) raised, or whose sample was malformed in a way the
station's stick check did not catch (sticks that are no sequence, a NaN attitude or goal),
ended ``testbed run`` (and trials, a sweep point, ``testbed hil``) with a Python traceback and
exit 1. The pilot is the user's input, as a link model or a control law of theirs is: now each
is one line on stderr naming the pilot (its class and file), the call and its time, and the
error, exit 2, no traceback, and what ran before is kept, marked incomplete (``metrics.json``
``"complete": false`` with the ``failure`` and, for an exception, the user's line;
``events.csv`` ending in ``testbed,failed``). ``testbed live`` flies the browser's pilot and
``testbed mavlink`` the ground station's, so a scenario's pilot never runs there.

Truths: the user's own file (its class, its raising line, counted from the text below), the
time the pilot is written to break at, and the operator's sample times (the s100 link's
0.3-s frames: the first sample at or after the break).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from tests.processes import Runner, in_process, one_error_line, run_testbed

PILOTS = '''
import math

from testbed.operator.pilots import GoalOrder, PilotSample

STILL = PilotSample((0.0,) * 6)


class Bad:
    """Centred sticks, then from ``at_s`` [s] on what ``kind`` says."""

    def __init__(self, kind="raise", at_s=5.0):
        self.kind, self.at_s = kind, at_s

    def sample(self, t_s):
        if t_s < self.at_s:
            return STILL
        if self.kind == "raise":
            raise ValueError(f"sample broke at {t_s:.2f}")
        if self.kind == "nan":
            return PilotSample((0.0, math.nan, 0.0, 0.0, 0.0, 0.0))
        if self.kind == "tuple":
            return (0.0,) * 6
        if self.kind == "no_sticks":
            return PilotSample(None)
        if self.kind == "attitude":
            return PilotSample((0.0,) * 6, (math.nan, 0.0, 0.0))
        if self.kind == "goal":
            return PilotSample((0.0,) * 6, None, GoalOrder(0, (math.inf, 0.0, 1.0)))
        return STILL


class Pure(Bad):
    """The same, sampled again by the recorder at the vehicle's instants."""

    pure_function_of_time = True


class Watching(Bad):
    """Centred sticks; its ``see`` raises once it is shown a state from ``at_s`` on."""

    def see(self, odometry):
        if odometry.sampled_s >= self.at_s:
            raise KeyError("saw too much")
'''


def line_of(text: str) -> int:
    """The 1-based line of pilots.py that is ``text``."""
    return PILOTS.split("\n").index(text) + 1


RAISING_LINE = line_of('            raise ValueError(f"sample broke at {t_s:.2f}")')

SCENARIO = """\
schema = 1
id = "pilot-v1"
description = "a pilot of the user's over S100"
duration_s = 10.0
{trials}
[link]
preset = "s100"
[pilot]
kind = "python"
factory = "pilots.py:Bad"
[metrics]
settle_s = 2.0
"""

BREAK_S = 5.0
FRAME_S = 0.3
"""The s100 operator's frame period [s]: the failing sample is the first at or after the
break, at most one frame later."""


@pytest.fixture
def testbed(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> Runner:
    """``testbed ARGS`` run in this process (:func:`tests.processes.run_main`)."""
    return in_process(monkeypatch, capsys)


@pytest.fixture
def study(tmp_path: Path) -> Path:
    folder = tmp_path / "study"
    folder.mkdir()
    (folder / "pilots.py").write_text(PILOTS)
    (folder / "pilot.toml").write_text(SCENARIO.format(trials=""))
    (folder / "trials.toml").write_text(SCENARIO.format(trials="trials = 2"))
    return folder


def pilot(kind: str, name: str = "Bad") -> list[str]:
    return ["--set", f"pilot.factory=pilots.py:{name}", "--set", f'pilot.args={{kind="{kind}"}}']


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(encoding="utf-8") as handle:
        return list(csv.DictReader(handle))


def _check_kept(out: Path, failure_head: str) -> dict[str, object]:
    """What ran before the error is written and marked: metrics.json incomplete with the
    failure, events.csv ending in testbed,failed, the series up to the break and no later."""
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["complete"] is False
    assert metrics["failure"].startswith(failure_head), metrics["failure"]
    assert BREAK_S <= metrics["sim_s"] < BREAK_S + FRAME_S + 1e-9
    events = _rows(out / "events.csv")
    assert (events[-1]["source"], events[-1]["kind"]) == ("testbed", "failed")
    series_t = [float(row["t_s"]) for row in _rows(out / "series.csv")]
    assert series_t and max(series_t) <= metrics["sim_s"]
    return metrics


def _sample_time(line: str, name: str, study: Path) -> float:
    """The time in ``pilot NAME (FILE): sample(T)`` of ``line``."""
    head = f"testbed: error: pilot {name} ({study / 'pilots.py'}): sample("
    assert line.startswith(head), line
    return float(line[len(head) :].split(")", 1)[0])


@pytest.mark.parametrize("name", ["Bad", "Pure"])
def test_a_pilot_that_raises_part_way_is_one_line_exit_2_keeping_what_ran(
    study: Path, testbed: Runner, name: str
) -> None:
    """A stateful pilot (sampled by the operator alone) and a pure one (sampled by the
    recorder too): the same line, the time the first sample at or after the break."""
    argv = ["run", "pilot.toml", "--out", "out", "--no-plots", *pilot("raise", name)]
    run = run_testbed if name == "Bad" else testbed  # one through a child, as a user runs it
    line = one_error_line(run(argv, study))
    t_s = _sample_time(line, name, study)
    assert BREAK_S <= t_s < BREAK_S + FRAME_S + 1e-9
    assert f"): sample({t_s!r}) raised ValueError: sample broke at {t_s:.2f} (what ran" in line
    assert line.endswith("s of 10 s, is in out)")
    metrics = _check_kept(study / "out", f"PilotError: pilot {name} ({study / 'pilots.py'})")
    assert str(metrics["failure"]).endswith(f" (at {study / 'pilots.py'}:{RAISING_LINE})")


@pytest.mark.parametrize(
    ("kind", "problem"),
    [
        ("nan", "sway stick must be a finite number in [-1, 1], got nan"),
        ("tuple", "got a tuple, not a PilotSample (testbed.operator.pilots)"),
        ("no_sticks", "sticks must be six numbers, got None"),
        ("attitude", "attitude_deg must be None or three finite angles [deg], got (nan, 0.0, 0.0)"),
        ("goal", "goal's position_ned_m must be None or three finite numbers [m], got (inf, 0.0"),
    ],
)
def test_a_malformed_sample_part_way_is_one_line_naming_the_pilot_call_and_problem(
    study: Path, testbed: Runner, kind: str, problem: str
) -> None:
    argv = ["run", "pilot.toml", "--out", "out", "--no-plots", *pilot(kind)]
    line = one_error_line(testbed(argv, study))
    t_s = _sample_time(line, "Bad", study)
    assert BREAK_S <= t_s < BREAK_S + FRAME_S + 1e-9
    assert f"): sample({t_s!r}): {problem}" in line, line
    _check_kept(study / "out", f"PilotError: pilot Bad ({study / 'pilots.py'}): sample(")


def test_a_pilots_see_that_raises_is_one_line_naming_see(study: Path, testbed: Runner) -> None:
    argv = ["run", "pilot.toml", "--out", "out", "--no-plots", *pilot("none", "Watching")]
    line = one_error_line(testbed(argv, study))
    head = f"testbed: error: pilot Watching ({study / 'pilots.py'}): see(odometry of "
    assert line.startswith(head), line
    shown_s = float(line[len(head) :].split(" s)", 1)[0])
    assert BREAK_S <= shown_s < BREAK_S + 1.0  # a vehicle state from the break on
    assert " s) raised KeyError: 'saw too much' (what ran to t = " in line
    metrics = json.loads((study / "out" / "metrics.json").read_text())
    assert metrics["complete"] is False and metrics["failure"].startswith("PilotError: ")


def test_trials_keep_the_failed_trials_part_and_name_it(study: Path, testbed: Runner) -> None:
    argv = ["run", "trials.toml", "--out", "out", "--no-plots", *pilot("raise")]
    line = one_error_line(testbed(argv, study))
    assert "raised ValueError: sample broke at " in line
    assert line.endswith(f"is in {Path('out', 'trial-1')})")
    assert "(what ran in trial 1 of 2, to t = " in line
    document = json.loads((study / "out" / "trials.json").read_text())
    assert (document["failed_trial"], document["trials_finished"], document["complete"]) == (
        1,
        0,
        False,
    )
    _check_kept(study / "out" / "trial-1", "PilotError: pilot Bad (")


def test_a_sweep_records_the_failing_point_with_the_line_and_runs_the_rest(
    study: Path, testbed: Runner
) -> None:
    (study / "broken-v1.toml").write_text(
        """\
schema = 1
id = "broken-v1"
description = "a pilot that breaks part way at one point"
scenario = "pilot.toml"
seeds = [0]
metrics = ["depth_error_m.mean"]
[grid]
"pilot.args" = [{ at_s = 5.0 }, { at_s = 100.0 }]
"""
    )
    done = testbed(["sweep", "broken-v1.toml", "--out", "sweep", "--workers", "2"], study)
    assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr  # "some failed"
    runs = [json.loads(row) for row in (study / "sweep" / "runs.jsonl").read_text().splitlines()]
    status = {run["pilot.args"]["at_s"]: (run["status"], run["error"]) for run in runs}
    assert status[100.0] == ("ok", "")
    assert status[5.0][0] == "failed"
    error = status[5.0][1]
    head = f"PilotError: pilot Bad ({study / 'pilots.py'}): sample("
    assert error.startswith(head), error
    t_s = float(error[len(head) :].split(")", 1)[0])
    assert error == (
        f"{head}{t_s!r}) raised ValueError: sample broke at {t_s:.2f} "
        f"(at {study / 'pilots.py'}:{RAISING_LINE})"
    )


def test_testbed_hil_says_the_same_line_and_keeps_what_ran(study: Path) -> None:
    """``testbed hil`` over emulated EvoLogics modems (real time, the break 2 s in)."""
    from testbed.channel import load_link_config
    from testbed.emulator.ptys import ModemEmulator

    config = load_link_config("s2c", ["intrinsic_delay_s=0.05"])
    with ModemEmulator(config, seed=0, modem="evologics") as emulator:
        a, b = emulator.paths
        argv = ["hil", "pilot.toml", "--operator-port", a, "--vehicle-port", b]
        argv += ["--modem", "evologics", "--duration", "4", "--out", "out", "--no-plots"]
        argv += ["--set", "metrics.settle_s=1", "--set", "link.ipg=fixed"]
        argv += ["--set", "link.ipg_s=0.3", "--set", 'pilot.args={kind="raise", at_s=2.0}']
        done = run_testbed(argv, study)
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr
    line = done.stderr.splitlines()[-1]
    t_s = _sample_time(line, "Bad", study)
    assert 2.0 <= t_s < 4.0
    assert f"): sample({t_s!r}) raised ValueError: sample broke at {t_s:.2f} (what ran" in line
    metrics = json.loads((study / "out" / "metrics.json").read_text())
    assert metrics["complete"] is False and 2.0 <= metrics["sim_s"] < 4.0
    assert metrics["failure"].startswith(f"PilotError: pilot Bad ({study / 'pilots.py'}): ")
    assert metrics["failure"].endswith(f" (at {study / 'pilots.py'}:{RAISING_LINE})")
