"""A pilot, link model or control law of the user's that calls ``sys.exit``.

``SystemExit`` is not an ``Exception``, so it went past every handler of the user's errors:

- at import, or in the factory, the command ended with the module's exit code (3) and not a
  line (a module that runs a script's ``sys.exit`` when imported);
- during a run, ``testbed run`` lost everything that ran (nothing written, ``--out`` removed)
  where any other error of the pilot keeps it;
- in a sweep on the process pool, the worker handed the ``SystemExit`` back and the whole sweep
  exited with it: no failed run recorded, the runs still to come never run, no resume line
  (on Dask the worker died four times over and the run was a ``KilledWorker``).

Now it is the user's error like any other: one line, exit 2, when loading; during a run a
:class:`~testbed.run.failures.RunExit` naming the user's line, with what ran kept; a sweep
records the failed run and goes on.

The loading cases run :func:`~testbed.cli.main.main` in this process (its exit code and
stderr are the command's; a ``SystemExit`` it let out would end the test as a failure), and a
module's ``sys.exit(3)`` at import also through the real command line (a subprocess), where it
used to become the process's exit code.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from testbed.cli.main import main
from testbed.sweep import load_sweep, run_sweep
from tests.processes import in_process, run_testbed
from tests.run.test_plugins import write_study

PILOTS = """
import sys

from testbed.operator.pilots import PilotSample

STILL = PilotSample((0.0,) * 6)


class Idle:
    def sample(self, t_s):
        return STILL


class Quitter:
    def __init__(self, at_s=12.0):
        self.at_s = at_s

    def sample(self, t_s):
        if t_s > self.at_s:
            sys.exit("the pilot gave up")
        return STILL


def no_pilot_today():
    sys.exit("no pilot today")
"""

EXIT_LINE = PILOTS.split("\n").index('            sys.exit("the pilot gave up")') + 1


@pytest.fixture
def study(tmp_path: Path) -> Path:
    """test_plugins's study (a 30-s S100 scenario, step.toml), with these pilots beside, and a
    module that exits as it is imported."""
    folder = write_study(tmp_path / "study")
    (folder / "quitters.py").write_text(PILOTS)
    (folder / "script.py").write_text("import sys\n\nsys.exit(3)\n")
    return folder


@pytest.mark.parametrize(
    ("key", "target", "said"),
    [
        ("pilot.factory", "script.py:Pilot", "importing script.py failed: SystemExit: 3"),
        ("link.model", "script.py:model", "importing script.py failed: SystemExit: 3"),
        ("vehicle.control.depth", "script.py:Law", "importing script.py failed: SystemExit: 3"),
        ("pilot.factory", "quitters.py:no_pilot_today", "SystemExit: no pilot today"),
    ],
)
def test_sys_exit_while_a_plugin_loads_is_one_line_naming_the_key_exit_2(
    study: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    key: str,
    target: str,
    said: str,
) -> None:
    out = study / "out"
    sets = ["--set", f"{key}={target}"]
    if key == "pilot.factory":
        sets += ["--set", "pilot.args={}"]
    child = (key, target) == ("pilot.factory", "script.py:Pilot")  # as a user runs it
    run = run_testbed if child else in_process(monkeypatch, capsys)
    done = run(["run", "step.toml", *sets, "--out", str(out), "--no-plots"], study)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("testbed: error: ")
    assert f"{key}" in lines[0] and said in lines[0]
    assert not out.exists()


def _rows(path: Path) -> list[list[str]]:
    with path.open(newline="") as handle:
        return list(csv.reader(handle))


def _pilot(study: Path, name: str) -> list[str]:
    return ["--set", f"pilot.factory={study / 'quitters.py'}:{name}", "--set", "pilot.args={}"]


def test_sys_exit_in_a_pilot_part_way_keeps_what_ran(
    study: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Exit 1 with the traceback and the line naming the time and folder, as for any error of
    the pilot's; the series up to there is, row for row, the start of a run whose pilot
    commands the same and never exits."""
    run = ["run", str(study / "step.toml"), "--no-plots"]
    assert main([*run, "--out", str(study / "idle"), *_pilot(study, "Idle")]) == 0
    capsys.readouterr()
    out = study / "quitter"
    assert main([*run, "--out", str(out), *_pilot(study, "Quitter")]) == 1
    err = capsys.readouterr().err
    metrics = json.loads((out / "metrics.json").read_text())
    assert err.endswith(
        f"testbed: the run failed; what ran to t = {metrics['sim_s']:.1f} s of 30 s, is in {out}\n"
    )
    where = f"(at {study / 'quitters.py'}:{EXIT_LINE})"
    assert metrics["failure"] == (
        f"RunExit: sys.exit('the pilot gave up') called during the run {where}"
    )
    assert metrics["complete"] is False and 12.0 < metrics["sim_s"] < 12.6
    partial, whole = _rows(out / "series.csv"), _rows(study / "idle" / "series.csv")
    assert len(partial) > 200 and partial == whole[: len(partial)]
    assert _rows(out / "events.csv")[-1][1:3] == ["testbed", "failed"]


def test_a_sweep_on_the_pool_records_a_run_that_calls_sys_exit_and_goes_on(
    study: Path, tmp_path: Path
) -> None:
    """The point whose pilot exits at 5 s is a failed run with the user's line; the other
    point's runs finish and equal `testbed run` of that point (a second method)."""
    sweep_file = tmp_path / "quit.toml"
    sweep_file.write_text(
        f"""\
schema = 1
id = "quit-v1"
description = "a pilot that gives up at some point"
scenario = "{study / "step.toml"}"
seeds = 2
metrics = ["command_lag_s.mean"]
[set]
"pilot.factory" = "{study / "quitters.py"}:Quitter"  # the scenario's args: at_s = 15
duration_s = 20.0
[grid]
"pilot.args.at_s" = [100.0, 5.0]
"""
    )
    out = tmp_path / "out"
    summary = run_sweep(load_sweep(str(sweep_file)), out, workers=2)
    assert summary.ran == 4
    where = f"(at {study / 'quitters.py'}:{EXIT_LINE})"
    error = f"RunExit: sys.exit('the pilot gave up') called during the run {where}"
    assert [(point, seed, said) for point, seed, _, said in summary.failed] == [
        (1, 0, error),
        (1, 1, error),
    ]
    with (out / "results.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert [(row["point"], row["seed"], row["status"]) for row in rows] == [
        ("0", "0", "ok"),
        ("0", "1", "ok"),
        ("1", "0", "failed"),
        ("1", "1", "failed"),
    ]
    direct = study / "direct"
    overrides = [*_pilot(study, "Quitter"), "--set", "pilot.args={at_s=100.0}"]
    argv = ["run", str(study / "step.toml"), "--seed", "1", "--set", "duration_s=20.0"]
    assert main([*argv, *overrides, "--out", str(direct), "--no-plots"]) == 0
    lag = json.loads((direct / "metrics.json").read_text())["command_lag_s"]["mean"]
    assert float(rows[1]["command_lag_s.mean"]) == lag
