"""A link model or control law of the user's whose method raises, driven through the command
line: :func:`testbed.cli.main.main` in this process (``main``), and for one case of each mode
family through the real command line (a subprocess, as a user runs it): a link model's
``state`` raising in ``testbed run``, and a control law raising in the MAVLink gateway. The
subject here is the error line and what is kept, which ``main`` returns and writes the same in
or out of a child; the children check that nothing between the console script and ``main``
(the signals it holds, a traceback at exit) changes them, and spare the others a child's
start-up (≈ 1 s each).

Before, a link model whose ``state``, ``airtime_s``, ``error_model`` or error model's
``corrupt`` raised, or a depth law whose ``update`` or ``reset`` raised, ended ``testbed run``
(and ``trials``, ``live``, the MAVLink gateway) with a Python traceback and exit 1, and a
``state`` that is not a method was silently never asked. The user's plug-in is the user's input:
now each is one line on stderr naming the model (its class and file), the method and the
exception, exit 2, no traceback, and what ran before the error is kept, marked incomplete (as
for an interrupt: ``metrics.json`` ``"complete": false`` with the ``failure`` and the user's
line, ``events.csv`` ending in ``testbed,failed``). A sweep records the point as failed with
that line and runs the others.

Truths: the user's own file (its class, its raising line, counted from the text below), the
time the model is written to break at, and the ``link_state.csv`` rows a model that never
breaks writes for the same instants.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from tests.processes import Runner, in_process, one_error_line, run_testbed

PLUGINS = '''
from testbed.channel import StandardLink


class Faulty:
    """The preset's link; its method ``where`` raises from ``at_s`` [s] on."""

    def __init__(self, config, where="state", at_s=5.0):
        self.base, self.where, self.at_s = StandardLink(config), where, at_s

    def _check(self, name, t_s):
        if name == self.where and t_s >= self.at_s:
            raise ValueError(f"{name} broke at {t_s:.2f}")

    def airtime_s(self, size_bytes, t_s):
        self._check("airtime_s", t_s)
        return self.base.airtime_s(size_bytes, t_s)

    def error_model(self, rng):
        self._check("error_model", 0.0)
        return Errors(self, self.base.error_model(rng))

    def state(self, t_s):
        self._check("state", t_s)
        return {"bitrate_bps": self.base.config.bitrate_bps}


class Errors:
    def __init__(self, model, errors):
        self.model, self.errors = model, errors

    def corrupt(self, data, p, t_s):
        self.model._check("corrupt", t_s)
        return self.errors.corrupt(data, p, t_s)


class Stateful(Faulty):
    """A model whose ``state`` is a number, not the method."""

    state = 3.0


def no_model(config):
    raise RuntimeError("no model today")


class Depth:
    """A P depth hold whose ``where`` method raises from ``at_s`` [s] (the depth reading's
    time) on."""

    def __init__(self, where="update", at_s=5.0):
        self.where, self.at_s = where, at_s

    def reset(self):
        if self.where == "reset":
            raise KeyError("reset broke")

    def update(self, target, depth, imu, dt_s):
        if self.where == "update" and depth.time_s >= self.at_s:
            raise ZeroDivisionError(f"update broke at {depth.time_s:.2f}")
        return (0.0, 0.0, 40.0 * (target.depth_m - depth.depth_m))


class Tired(Depth):
    """The same hold, whose ``reset`` raises from its ``calls``-th call on (a disarmed vehicle
    resets its hold every frame)."""

    def __init__(self, calls=150):
        super().__init__(where="none")
        self.left = calls

    def reset(self):
        self.left -= 1
        if self.left < 0:
            raise KeyError("tired of resetting")
'''


def line_of(text: str) -> int:
    """The 1-based line of plugins.py that is ``text``."""
    return PLUGINS.split("\n").index(text) + 1


RAISING_LINE = line_of('            raise ValueError(f"{name} broke at {t_s:.2f}")')
"""The line of plugins.py where Faulty raises."""

SCENARIO = """\
schema = 1
id = "still-v1"
description = "centred sticks in depth hold over S100"
duration_s = 10.0
{trials}
[link]
preset = "s100"
[pilot]
kind = "scripted"
[metrics]
settle_s = 2.0
"""

BREAK_S = 5.0


@pytest.fixture
def testbed(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> Runner:
    """``testbed ARGS`` run in this process (:func:`tests.processes.run_main`)."""
    return in_process(monkeypatch, capsys)


@pytest.fixture
def study(tmp_path: Path) -> Path:
    folder = tmp_path / "study"
    folder.mkdir()
    (folder / "plugins.py").write_text(PLUGINS)
    (folder / "still.toml").write_text(SCENARIO.format(trials=""))
    (folder / "trials.toml").write_text(SCENARIO.format(trials="trials = 2"))
    return folder


def model(where: str, at_s: float = BREAK_S, name: str = "Faulty") -> list[str]:
    return [
        "--set",
        f"link.model=plugins.py:{name}",
        "--set",
        f'link.model_args={{where="{where}", at_s={at_s}}}',
    ]


def law(where: str, at_s: float = BREAK_S) -> list[str]:
    return [
        "--set",
        "vehicle.control.depth=plugins.py:Depth",
        "--set",
        f'vehicle.control.depth_args={{where="{where}", at_s={at_s}}}',
    ]


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(encoding="utf-8") as handle:
        return list(csv.DictReader(handle))


def _check_kept(out: Path, failure_head: str, user_line: str) -> dict[str, object]:
    """What ran before the error is written and marked: metrics.json incomplete with the
    failure and the user's line, events.csv ending in testbed,failed, the series up to the
    break and no later."""
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["complete"] is False
    assert metrics["failure"].startswith(failure_head), metrics["failure"]
    assert metrics["failure"].endswith(f" (at {user_line})")
    assert BREAK_S - 0.5 < metrics["sim_s"] < BREAK_S + 1.0
    events = _rows(out / "events.csv")
    assert (events[-1]["source"], events[-1]["kind"]) == ("testbed", "failed")
    series_t = [float(row["t_s"]) for row in _rows(out / "series.csv")]
    assert series_t and max(series_t) <= metrics["sim_s"]
    return metrics


@pytest.mark.parametrize(
    ("where", "call"),
    [("state", "state(5.0)"), ("airtime_s", "airtime_s("), ("corrupt", "corrupt(<")],
)
def test_a_link_model_method_that_raises_part_way_is_one_line_exit_2_keeping_what_ran(
    study: Path, testbed: Runner, where: str, call: str
) -> None:
    run = run_testbed if where == "state" else testbed  # one through a child, as a user runs it
    done = run(["run", "still.toml", "--out", "out", "--no-plots", *model(where)], study)
    line = one_error_line(done)
    part = "link model's error model Errors" if where == "corrupt" else "link model Faulty"
    head = f"{part} ({study / 'plugins.py'}): {call}"
    assert line.startswith(f"testbed: error: {head}"), line
    assert f"raised ValueError: {where} broke at " in line
    assert line.endswith("is in out)")
    user_line = f"{study / 'plugins.py'}:{RAISING_LINE}"
    _check_kept(study / "out", f"LinkModelError: {head}", user_line)
    if where == "state":  # the state rows are the never-breaking model's, up to the break
        states = _rows(study / "out" / "link_state.csv")
        series_t = [row["t_s"] for row in _rows(study / "out" / "series.csv")]
        assert [row["t_s"] for row in states] == series_t
        assert {row["bitrate_bps"] for row in states} == {"1900"}


def test_an_error_model_that_raises_as_it_is_made_is_one_line_and_writes_nothing(
    study: Path, testbed: Runner
) -> None:
    done = testbed(
        ["run", "still.toml", "--out", "out", "--no-plots", *model("error_model", at_s=0.0)], study
    )
    line = one_error_line(done)
    assert line == (
        f"testbed: error: link model Faulty ({study / 'plugins.py'}): error_model(rng) for the "
        "vehicle raised ValueError: error_model broke at 0.00"
    )
    assert not (study / "out").exists()


def test_a_state_that_is_not_a_method_is_refused_before_the_run(
    study: Path, testbed: Runner
) -> None:
    """It used to be silently ignored: no link_state.csv, no word."""
    argv = ["run", "still.toml", "--out", "out", "--no-plots", *model("state", name="Stateful")]
    line = one_error_line(testbed(argv, study))
    assert line == (
        f"testbed: error: link model Stateful ({study / 'plugins.py'}): state is 3.0, not a "
        "method: expected state(t_s) -> Mapping[str, float], or no attribute 'state'"
    )
    assert not (study / "out").exists()


def test_a_link_model_factory_that_raises_is_one_line_naming_the_key(
    study: Path, testbed: Runner
) -> None:
    done = testbed(
        ["run", "still.toml", "--out", "out", "--set", "link.model=plugins.py:no_model"], study
    )
    line = one_error_line(done)
    assert line == "testbed: error: --set: link.model: RuntimeError: no model today"


def test_a_control_law_that_raises_part_way_is_one_line_exit_2_keeping_what_ran(
    study: Path, testbed: Runner
) -> None:
    done = testbed(["run", "still.toml", "--out", "out", "--no-plots", *law("update")], study)
    line = one_error_line(done)
    raised = "update raised ZeroDivisionError: update broke at "
    head = f"depth law Depth ({study / 'plugins.py'}): {raised}"
    assert line.startswith(f"testbed: error: {head}"), line
    raising = line_of('            raise ZeroDivisionError(f"update broke at {depth.time_s:.2f}")')
    _check_kept(study / "out", f"ControlLawError: {head}", f"{study / 'plugins.py'}:{raising}")


def test_a_control_laws_reset_that_raises_at_the_first_frame_is_one_line(
    study: Path, testbed: Runner
) -> None:
    done = testbed(["run", "still.toml", "--out", "out", "--no-plots", *law("reset")], study)
    line = one_error_line(done)
    assert line == (
        f"testbed: error: depth law Depth ({study / 'plugins.py'}): reset raised KeyError: "
        "'reset broke'"
    )
    assert not (study / "out").exists()  # nothing ran: the disarmed vehicle resets at t = 0


def test_trials_keep_the_failed_trials_part_and_name_it(study: Path, testbed: Runner) -> None:
    done = testbed(["run", "trials.toml", "--out", "out", "--no-plots", *model("state")], study)
    line = one_error_line(done)
    assert line.endswith(
        f"(what ran in trial 1 of 2, to t = 5.0 s of 10 s, is in {Path('out', 'trial-1')})"
    )
    document = json.loads((study / "out" / "trials.json").read_text())
    assert (document["failed_trial"], document["trials_finished"], document["complete"]) == (
        1,
        0,
        False,
    )
    _check_kept(
        study / "out" / "trial-1",
        "LinkModelError: link model Faulty",
        f"{study / 'plugins.py'}:{RAISING_LINE}",
    )


def test_a_sweep_records_the_failing_point_with_the_line_and_runs_the_rest(
    study: Path, testbed: Runner
) -> None:
    (study / "broken-v1.toml").write_text(
        """\
schema = 1
id = "broken-v1"
description = "a link model that breaks part way at one point"
scenario = "still.toml"
seeds = [0]
metrics = ["depth_error_m.mean"]
[set]
"link.model" = "plugins.py:Faulty"
[grid]
"link.model_args" = [{ at_s = 5.0 }, { at_s = 100.0 }]
"""
    )
    done = testbed(["sweep", "broken-v1.toml", "--out", "sweep", "--workers", "2"], study)
    assert done.returncode == 1 and "Traceback" not in done.stderr, (
        done.stderr
    )  # a sweep's "some failed"
    runs = [json.loads(row) for row in (study / "sweep" / "runs.jsonl").read_text().splitlines()]
    status = {run["link.model_args"]["at_s"]: (run["status"], run["error"]) for run in runs}
    assert status[100.0] == ("ok", "")
    assert status[5.0][0] == "failed"
    assert status[5.0][1] == (
        f"LinkModelError: link model Faulty ({study / 'plugins.py'}): state(5.0) raised "
        f"ValueError: state broke at 5.00 (at {study / 'plugins.py'}:{RAISING_LINE})"
    )


@pytest.mark.parametrize(
    ("argv", "banner"),
    [
        (["live", "--port", "0"], ()),  # its console's address is on stdout
        (
            ["mavlink", "--link", "s100", "--gcs", "udpout:127.0.0.1:9"],
            ("testbed: mavlink: gateway to the vehicle through the s100 link",),
        ),
    ],
    ids=["live", "gateway"],
)
def test_the_real_time_modes_say_the_same_line_and_keep_what_ran(
    study: Path, testbed: Runner, argv: list[str], banner: tuple[str, ...]
) -> None:
    """``testbed live`` and the MAVLink gateway (real time, 1 s into a 4-s session)."""
    command = [argv[0], "still.toml", *argv[1:], "--duration", "4", "--out", "out", "--no-plots"]
    done = testbed([*command, *model("state", at_s=1.0)], study)
    line = one_error_line(done, *banner)
    assert line == (
        f"testbed: error: link model Faulty ({study / 'plugins.py'}): state(1.0) raised "
        "ValueError: state broke at 1.00 (what ran to t = 1.0 s of 4 s, is in out)"
    )
    metrics = json.loads((study / "out" / "metrics.json").read_text())
    assert metrics["complete"] is False and metrics["sim_s"] == 1.0


@pytest.mark.parametrize(
    ("argv", "banner", "laws", "call"),
    [
        (["live", "--port", "0"], (), law("update", at_s=1.0), "update raised ZeroDivisionError"),
        (
            ["mavlink", "--gcs", "udpout:127.0.0.1:9"],
            ("testbed: mavlink: ArduSub vehicle (sysid 1)",),
            ["--set", "vehicle.control.depth=plugins.py:Tired"],
            "reset raised KeyError: 'tired of resetting'",
        ),
        (
            ["mavlink", "--link", "s100", "--gcs", "udpout:127.0.0.1:9"],
            ("testbed: mavlink: gateway to the vehicle through the s100 link",),
            ["--set", "vehicle.control.depth=plugins.py:Tired"],
            "reset raised KeyError: 'tired of resetting'",
        ),
    ],
    ids=["live", "mavlink", "gateway"],
)
def test_a_control_law_that_raises_in_the_real_time_modes_is_the_same_line(
    study: Path,
    testbed: Runner,
    argv: list[str],
    banner: tuple[str, ...],
    laws: list[str],
    call: str,
) -> None:
    """A depth law raising about 1 s into a 4-s session of ``testbed live`` (armed in depth hold
    by the scenario), ``testbed mavlink`` and the gateway (the vehicle waits disarmed for a
    ground station that never comes, resetting its hold each frame): the same line, what ran
    kept."""
    command = [argv[0], "still.toml", *argv[1:], "--duration", "4", "--out", "out", "--no-plots"]
    run = run_testbed if "--link" in argv else testbed  # the gateway through a child
    line = one_error_line(run([*command, *laws], study), *banner)
    name = "Tired" if "Tired" in laws[-1] else "Depth"
    assert line.startswith(f"testbed: error: depth law {name} ({study / 'plugins.py'}): {call}")
    assert line.endswith(" s of 4 s, is in out)"), line
    metrics = json.loads((study / "out" / "metrics.json").read_text())
    assert metrics["complete"] is False and 0.9 < metrics["sim_s"] < 3.0
    assert metrics["failure"].startswith(f"ControlLawError: depth law {name} (")
