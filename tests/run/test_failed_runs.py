"""A run that an error ends part way keeps what ran (testbed.run.failures): a pilot of the
user's that raises 12 s into a run used to lose the whole recording. The partial series is held
to a run of a pilot that commands the same and never raises (a second run, not the code's own
bookkeeping), and each entry point says where what ran went.

A pilot of the user's is the user's input, like a link model or a control law of theirs: what it
raises is a PilotError (a ConfigError: one line, exit 2, no traceback) naming the pilot's class
and file, the call and its time, and the error, caused by the pilot's own exception (it used to
be the pilot's traceback and exit 1)."""

from __future__ import annotations

import csv
import json
import threading
from pathlib import Path

import pytest

from testbed.cli.main import main
from testbed.config import ConfigError
from testbed.operator.pilots import PilotError
from testbed.run.failures import partial_run
from testbed.run.runner import run_scenario
from testbed.run.scenario import load_scenario
from tests.run.test_plugins import write_study

PILOTS = """
from testbed.operator.pilots import PilotSample

STILL = PilotSample((0.0,) * 6)
trials_made = [0]


class Idle:
    def sample(self, t_s):
        return STILL


class Sleepy:
    def __init__(self, at_s=12.0):
        self.at_s = at_s

    def sample(self, t_s):
        if t_s > self.at_s:
            raise ValueError(f"pilot fell asleep at {t_s:.1f}")
        return STILL


class Overdriven:
    def sample(self, t_s):
        return PilotSample((2.0 if t_s > 12.0 else 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))


def second_trial_sleeps():
    trials_made[0] += 1
    return Sleepy() if trials_made[0] == 2 else Idle()


def second_trial_never_starts():
    trials_made[0] += 1
    if trials_made[0] == 2:
        raise RuntimeError("no pilot for trial 2")
    return Idle()
"""

RAISE_LINE = PILOTS.split("\n").index(
    '            raise ValueError(f"pilot fell asleep at {t_s:.1f}")'
)


@pytest.fixture
def study(tmp_path: Path) -> Path:
    """test_plugins's study (a 30-s S100 scenario, step.toml), with these pilots beside."""
    folder = write_study(tmp_path / "study")
    (folder / "sleepy.py").write_text(PILOTS)
    return folder


def _pilot(study: Path, name: str) -> list[str]:
    return ["--set", f"pilot.factory={study / 'sleepy.py'}:{name}", "--set", "pilot.args={}"]


def _rows(path: Path) -> list[list[str]]:
    with path.open(newline="") as handle:
        return list(csv.reader(handle))


def _sleepy_line(study: Path, sim_s: float) -> str:
    """What a Sleepy pilot's error says, the run having reached ``sim_s`` (the time of the
    operator's sample that raised)."""
    return (
        f"pilot Sleepy ({study / 'sleepy.py'}): sample({round(sim_s, 6)!r}) raised ValueError: "
        "pilot fell asleep at 12.2"
    )


def test_a_pilot_that_raises_part_way_is_one_line_exit_2_and_keeps_what_ran(
    study: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Exit 2 and one line naming the pilot (class and file), the call and its time, the
    error, and where what ran went; no traceback. The series up to there is, row for row, the
    start of a run whose pilot commands the same and never raises; metrics.json is marked
    incomplete with the error and the user's line."""
    run = ["run", str(study / "step.toml"), "--no-plots"]
    assert main([*run, "--out", str(study / "idle"), *_pilot(study, "Idle")]) == 0
    capsys.readouterr()
    out = study / "sleepy"
    assert main([*run, "--out", str(out), *_pilot(study, "Sleepy")]) == 2
    err = capsys.readouterr().err
    metrics = json.loads((out / "metrics.json").read_text())
    assert "Traceback" not in err
    assert err == (
        f"testbed: error: {_sleepy_line(study, metrics['sim_s'])} (what ran to t = "
        f"{metrics['sim_s']:.1f} s of 30 s, is in {out})\n"
    )
    assert metrics["complete"] is False
    where = f"(at {study / 'sleepy.py'}:{RAISE_LINE + 1})"
    assert metrics["failure"] == f"PilotError: {_sleepy_line(study, metrics['sim_s'])} {where}"
    assert 12.0 < metrics["sim_s"] < 12.6  # the operator's sample after 12 s (0.3-s frames)
    partial, whole = _rows(out / "series.csv"), _rows(study / "idle" / "series.csv")
    assert len(partial) > 200 and partial == whole[: len(partial)]
    assert float(partial[-1][0]) <= metrics["sim_s"] < float(whole[len(partial)][0])
    last_event = _rows(out / "events.csv")[-1]
    assert last_event[1:3] == ["testbed", "failed"] and last_event[-1] == metrics["failure"]
    assert set(metrics["files"]) == {"events.csv", "series.csv"}


def test_the_python_api_raises_a_pilot_error_caused_by_the_pilots_own_carrying_what_ran(
    study: Path,
) -> None:
    """run_scenario raises a PilotError caused by the pilot's own exception (its traceback);
    partial_run gives what ran."""
    scenario = load_scenario(str(study / "step.toml"), _pilot(study, "Idle")[1::2])
    sleepy = load_scenario(str(study / "step.toml"), _pilot(study, "Sleepy")[1::2])
    with pytest.raises(
        PilotError, match=r"raised ValueError: pilot fell asleep at 12\.2"
    ) as caught:
        run_scenario(sleepy)
    assert isinstance(caught.value, ConfigError)
    cause = caught.value.__cause__
    assert isinstance(cause, ValueError) and str(cause) == "pilot fell asleep at 12.2"
    partial = partial_run(caught.value)
    assert partial is not None and partial.stopped is None
    assert partial.failure is not None and partial.failure.startswith("PilotError: pilot Sleepy")
    assert 12.0 < partial.metrics["sim_s"] < 12.6
    assert partial_run(ValueError("not from a run")) is None
    assert run_scenario(scenario).failure is None


def test_a_bad_sample_part_way_is_one_line_exit_2_and_keeps_what_ran(
    study: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A sample out of [-1, 1] is bad input (one line, exit 2), and what ran is kept."""
    out = study / "overdriven"
    argv = ["run", str(study / "step.toml"), "--no-plots", "--out", str(out)]
    assert main([*argv, *_pilot(study, "Overdriven")]) == 2
    err = capsys.readouterr().err
    metrics = json.loads((out / "metrics.json").read_text())
    assert err == (
        f"testbed: error: pilot Overdriven ({study / 'sleepy.py'}): "
        f"sample({round(metrics['sim_s'], 6)!r}): surge stick must be a finite number in "
        f"[-1, 1], got 2.0 (what ran to t = {metrics['sim_s']:.1f} s of 30 s, is in {out})\n"
    )
    assert metrics["complete"] is False and metrics["failure"].startswith("PilotError: ")


def test_a_trial_that_fails_keeps_the_trials_before_it_and_its_own_start(
    study: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Trial 2 of 3 fails at 12.2 s: trial 1 whole, trial 2 partial, no trial 3, and
    trials.json names the failed trial."""
    out = study / "trials"
    argv = ["run", str(study / "step.toml"), "--no-plots", "--out", str(out), "--set", "trials=3"]
    assert main([*argv, *_pilot(study, "second_trial_sleeps")]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.count("\n") == 1
    document = json.loads((out / "trials.json").read_text())
    assert (document["complete"], document["failed_trial"], document["trials_finished"]) == (
        False,
        2,
        1,
    )
    first = json.loads((out / "trial-1" / "metrics.json").read_text())
    second = json.loads((out / "trial-2" / "metrics.json").read_text())
    assert first["complete"] is True and first["sim_s"] == 30.0
    assert second["complete"] is False
    assert second["failure"].startswith("PilotError: pilot Sleepy (")
    assert not (out / "trial-3").exists()
    assert err.endswith(
        f"(what ran in trial 2 of 3, to t = {second['sim_s']:.1f} s of 30 s, "
        f"is in {out / 'trial-2'})\n"
    )


def test_a_hil_run_whose_pilot_raises_keeps_what_ran_and_closes_the_ports(study: Path) -> None:
    """run_hil over emulated EvoLogics modems: the pilot raising 2 s in ends the session with
    a PilotError caused by its own, what ran (to ≈ 2 s of real time) kept on it, both ports
    closed."""
    from testbed.channel import load_link_config
    from testbed.emulator.ptys import ModemEmulator
    from testbed.hil import PortSettings, open_endpoint
    from testbed.run.realtime import run_hil

    config = load_link_config("s2c", ["intrinsic_delay_s=0.05"])
    short = ["metrics.settle_s=1", "link.ipg=fixed", "link.ipg_s=0.3"]
    sleepy = [f"pilot.factory={study / 'sleepy.py'}:Sleepy", "pilot.args={at_s=2.0}"]
    with ModemEmulator(config, seed=0, modem="evologics") as emulator:
        path_a, path_b = emulator.paths
        endpoints = {
            "operator": open_endpoint(PortSettings(path_a, "evologics", "operator")),
            "vehicle": open_endpoint(PortSettings(path_b, "evologics", "vehicle")),
        }
        scenario = load_scenario(str(study / "step.toml"), [*short, *sleepy])
        with pytest.raises(PilotError, match="raised ValueError: pilot fell asleep") as caught:
            run_hil(scenario, endpoints, duration_s=4.0, modem="evologics")
        assert isinstance(caught.value.__cause__, ValueError)
        partial = partial_run(caught.value)
        assert partial is not None and partial.failure is not None
        assert 2.0 < partial.metrics["sim_s"] < 4.0
        assert len(partial.recorder.series()["t_s"]) > 10
    alive = [t.name for t in threading.enumerate() if t.name.startswith("serial:")]
    assert alive == []


def test_a_trial_that_fails_as_it_begins_keeps_the_trials_before_it(
    study: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A pilot factory that raises for trial 2 (bad input: one line, exit 2): nothing of trial
    2 ran, but trial 1 and a trials.json naming the failed trial are kept, and the line says
    which trial (it was the error alone, no trials.json)."""
    out = study / "trials"
    argv = ["run", str(study / "step.toml"), "--no-plots", "--out", str(out), "--set", "trials=3"]
    assert main([*argv, *_pilot(study, "second_trial_never_starts")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "RuntimeError: no pilot for trial 2" in err
    assert err.endswith(f"(trial 2 of 3 failed as it began; the trials before it are in {out})\n")
    document = json.loads((out / "trials.json").read_text())
    assert (document["failed_trial"], document["trials_finished"]) == (2, 1)
    assert (out / "trial-1" / "metrics.json").exists() and not (out / "trial-2").exists()


def test_testbed_hil_writes_what_ran_when_the_pilot_raises(
    study: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The CLI over emulated EvoLogics modems (a code review drove it by hand): exit 2 and one
    error line, the partial session with its ports.csv and the ports it used, the failure
    naming the pilot and the line."""
    from testbed.channel import load_link_config
    from testbed.emulator.ptys import ModemEmulator

    config = load_link_config("s2c", ["intrinsic_delay_s=0.05"])
    out = study / "hil"
    with ModemEmulator(config, seed=0, modem="evologics") as emulator:
        a, b = emulator.paths
        ports = ["--operator-port", a, "--vehicle-port", b, "--modem", "evologics"]
        short = ["--set", "metrics.settle_s=1", "--set", "link.ipg=fixed"]
        short += ["--set", "link.ipg_s=0.3", "--set", f"pilot.factory={study / 'sleepy.py'}:Sleepy"]
        argv = ["hil", str(study / "step.toml"), *ports, "--duration", "4", "--log-bytes"]
        argv += ["--out", str(out), "--no-plots", *short, "--set", "pilot.args={at_s=2.0}"]
        assert main(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert f"testbed: error: pilot Sleepy ({study / 'sleepy.py'}): sample(2." in err
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["complete"] is False and 2.0 < metrics["sim_s"] < 4.0
    assert metrics["failure"].startswith(f"PilotError: pilot Sleepy ({study / 'sleepy.py'}")
    assert "raised ValueError: pilot fell asleep at 2." in metrics["failure"]
    assert f"(at {study / 'sleepy.py'}:{RAISE_LINE + 1})" in metrics["failure"]
    assert {"ports.csv", "series.csv", "events.csv"} <= set(metrics["files"])
    assert metrics["hil"]["ports"]["duration_s"] == 4.0


def test_a_pilot_that_raises_at_its_first_sample_is_one_line_and_writes_nothing(
    study: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A pilot that raises at its first sample (t = 0): nothing ran, so nothing is written
    and --out is removed again; the line names the pilot, sample(0.0) and the error."""
    out = study / "first"
    argv = ["run", str(study / "step.toml"), "--no-plots", "--out", str(out)]
    argv += [*_pilot(study, "Sleepy"), "--set", "pilot.args={at_s=-1.0}"]
    assert main(argv) == 2
    assert capsys.readouterr().err == (
        f"testbed: error: pilot Sleepy ({study / 'sleepy.py'}): sample(0.0) raised ValueError: "
        "pilot fell asleep at 0.0\n"
    )
    assert not out.exists()
