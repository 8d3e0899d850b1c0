"""Trials that a real Ctrl-C or SIGTERM ends while results are written, not while a trial runs.

A trial that ran to its end is written whole (data and ``metrics.json``) before its plots; an
interrupt while its plots are drawn, or while the trials figure is, ends no trial part way.
``trials.json`` must count that trial as finished, with its figures (they are its own
``metrics.json``'s), and the command must say in its one line where the results are. Before,
the trial was dropped from ``trials.json`` (``trials_finished`` one short, the trial named as
interrupted) though its directory held a complete run, and an interrupt while the trials
figure was drawn ended with a bare ``testbed: interrupted``.

Each command is a child process; the signal is real, sent by the child to itself from inside
the plot writer (a monkeypatched wrapper), so it lands exactly while that trial is written.
The calls of the wrapped writer before the signalled one draw nothing, nor (with
``quiet_runs``) do the trials' own run plots: those are finished trials' plots, not the
subject here (tests/report draws them); the signalled call is the real writer's.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from testbed.run.trials import headline
from tests.processes import check_set, default_sigint

WAIT_S = 300.0

TELEOP_TRIALS = [
    "--set",
    "trials=2",
    "--set",
    "duration_s=3",
    "--set",
    "pilot.start_s=1",
    "--set",
    "metrics.settle_s=1",
]

SIGNAL_IN_PLOTS = """
import os, signal, sys
import testbed.report.run_plots as run_plots
import testbed.report.{module} as plots

if {quiet_runs}:
    run_plots.write_run_plots = lambda result, out_dir: []
drawn = []
original = plots.{function}

def {function}(*args, **kwargs):  # the signal lands as the {nth} call begins to draw
    drawn.append(1)
    if len(drawn) < {nth}:
        return []  # an earlier finished trial's plots: not the subject
    if len(drawn) == {nth}:
        os.kill(os.getpid(), signal.SIG{name})
    return original(*args, **kwargs)

plots.{function} = {function}
from testbed.cli.main import main
sys.exit(main({argv!r}))
"""


def run_signalled(
    argv: list[str], module: str, function: str, nth: int, name: str, *, quiet_runs: bool = False
) -> subprocess.CompletedProcess[str]:
    script = SIGNAL_IN_PLOTS.format(
        module=module, function=function, nth=nth, name=name, argv=argv, quiet_runs=quiet_runs
    )
    return subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        timeout=WAIT_S,
        preexec_fn=default_sigint,
    )


@pytest.mark.parametrize(("name", "code"), [("INT", 130), ("TERM", 143)])
def test_an_interrupt_while_a_finished_trial_is_plotted_keeps_it_counted(
    tmp_path: Path, name: str, code: int
) -> None:
    out = tmp_path / "out"
    argv = ["run", *TELEOP_TRIALS, "--out", str(out)]
    done = run_signalled(argv, "run_plots", "write_run_plots", nth=2, name=name)
    assert done.returncode == code, done.stderr
    assert done.stderr.splitlines() == [
        f"testbed: interrupted while writing results, after trial 2 of 2; 2 finished, "
        f"results in {out}"
    ]
    second = check_set(out / "trial-2")  # its data and metrics.json, whole
    assert second["complete"] is True and second["sim_s"] == 3.0
    document = json.loads((out / "trials.json").read_text())
    assert document["trials_finished"] == 2 and document["complete"] is True
    assert document["interrupted_trial"] is None and document["failed_trial"] is None
    assert [row["seed"] for row in document["trials"]] == [0, 1]
    row = document["trials"][1]
    figures = headline(second)  # the trial's own metrics.json is the truth of its row
    for key in ("command_lag_mean_s", "energy_wh", "depth_error_mean_m"):
        assert row[key] == figures[key]
    assert "trial 2 seed 1:" in done.stdout  # its line, as for any finished trial


def test_an_interrupt_while_the_first_of_two_trials_is_plotted_stops_before_the_second(
    tmp_path: Path,
) -> None:
    out = tmp_path / "out"
    argv = ["run", *TELEOP_TRIALS, "--out", str(out)]
    done = run_signalled(argv, "run_plots", "write_run_plots", nth=1, name="INT")
    assert done.returncode == 130, done.stderr
    assert done.stderr.splitlines() == [
        f"testbed: interrupted while writing results, after trial 1 of 2; 1 finished, "
        f"results in {out}"
    ]
    assert check_set(out / "trial-1")["complete"] is True
    assert not (out / "trial-2").exists()
    document = json.loads((out / "trials.json").read_text())
    assert document["trials_finished"] == 1 and document["complete"] is False
    assert [row["seed"] for row in document["trials"]] == [0]


MISSION_TRIALS = """\
schema = 1
id = "station-trials-v1"
description = "station keeping on motion capture, past the mission's 10-s leg"
duration_s = 11.0
seed = 7
trials = 2

[link]
preset = "s100"
codec = "teleop"
mac = "token"
ipg = "telerobotics-2021"
operator_position_ned_m = [-0.5, 0.0, 1.0]

[vehicle]
model = "bluerov2"
thrusters = "bluerov2"
start_position_ned_m = [0.0, 0.0, 1.0]

[vehicle.navigation.motion_capture]

[vehicle.autonomy]
mission = "station_keeping"

[pilot]
start_s = 1.0

[metrics]
settle_s = 1.0
"""


def test_an_interrupt_while_the_trials_figure_is_drawn_says_where_the_trials_are(
    tmp_path: Path,
) -> None:
    scenario = tmp_path / "station-trials.toml"
    scenario.write_text(MISSION_TRIALS, encoding="utf-8")
    out = tmp_path / "out"
    argv = ["run", str(scenario), "--out", str(out)]
    done = run_signalled(argv, "mission_plots", "plot_trials", nth=1, name="INT", quiet_runs=True)
    assert done.returncode == 130, done.stderr
    assert done.stderr.splitlines() == [
        f"testbed: interrupted while writing results, after trial 2 of 2; 2 finished, "
        f"results in {out}"
    ]
    document = json.loads((out / "trials.json").read_text())
    assert document["trials_finished"] == 2 and document["complete"] is True
    assert not (out / "trials.png").exists()
    assert not [path.name for path in out.iterdir() if path.name.startswith(".tmp-")]
