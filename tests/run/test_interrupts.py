"""An interrupt that a compiled library reported as its own error still ends a run the way
Ctrl-C does: what ran is kept, marked partial.

numba's kernels call back into Python (``numba.core.serialize._numba_unpickle``) each time
one hands a new array back (here a kernel the test adds to the navigation filter's frame,
:func:`tests.interrupts.calling_back`); a KeyboardInterrupt raised there (as a real signal's
handler can be, at any Python line) comes out of the kernel as ``SystemError``, caused by it.
"""

from __future__ import annotations

import json
import os
import signal
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import simpy
from numba.core import serialize

from testbed.cli.options import Terminated
from testbed.run.interrupts import interrupt_of
from testbed.run.outputs import write_run
from testbed.run.runner import run_scenario
from testbed.run.scenario import load_scenario
from testbed.vehicle.localization import KalmanLocalizer
from tests.interrupts import call_back, calling_back, interrupt_at_line
from tests.processes import check_set


def test_the_interrupt_is_found_as_the_cause_or_the_context_of_another_error() -> None:
    interrupt = Terminated()
    try:
        try:
            raise interrupt
        except KeyboardInterrupt as caught:
            raise SystemError("returned a result with an exception set") from caught
    except SystemError as wrapped:
        assert interrupt_of(wrapped) is interrupt  # the SIGTERM one: exit code 143 kept
    try:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt:
            raise OSError("while cleaning up")  # noqa: B904 (the implicit context is the point)
    except OSError as during:
        assert isinstance(interrupt_of(during), KeyboardInterrupt)
    assert interrupt_of(ValueError("no interrupt")) is None
    looped = ValueError("a cycle")
    looped.__context__ = RuntimeError()
    looped.__context__.__context__ = looped
    assert interrupt_of(looped) is None


def test_a_run_interrupted_inside_a_kernels_callback_keeps_what_ran(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    scenario = load_scenario("s100-supervised-v1", ["duration_s=6"])
    seen: dict[str, int] = {}
    simulate = simpy.Environment.run

    def run_with_an_interrupt(env: simpy.Environment, until: Any = None) -> Any:
        # inside the simulation only: building the vehicle calls the kernels once too (to
        # compile them before the clock starts), and an interrupt there has nothing to keep
        with interrupt_at_line(1, serialize._numba_unpickle) as raised:
            try:
                return simulate(env, until)
            finally:
                seen.update(raised)

    monkeypatch.setattr(simpy.Environment, "run", run_with_an_interrupt)
    monkeypatch.setattr(KalmanLocalizer, "step", calling_back(KalmanLocalizer.step))
    call_back()  # the process's first callback, which cannot take an exception: not in the run
    result = run_scenario(scenario, seed=0)
    assert seen["raised"] == 1  # the kernel did call back, and was interrupted there
    assert isinstance(result.stopped, KeyboardInterrupt)
    assert 0.0 <= result.metrics["sim_s"] < 6.0
    write_run(result, tmp_path / "run")  # what `testbed run` writes
    metrics = check_set(tmp_path / "run")
    assert metrics["complete"] is False
    assert metrics["sim_s"] == pytest.approx(result.metrics["sim_s"])


def test_an_interrupt_while_plotting_a_finished_run_keeps_its_results(tmp_path: Path) -> None:
    """Ctrl-C lands while a finished run's plots are drawn: the data files and metrics.json are
    written anyway (the run is complete; it lists the plots made before), then the interrupt
    goes on up (``testbed run`` ends with one line and 130)."""
    result = run_scenario(load_scenario("s100-teleop-v1", ["duration_s=12"]), seed=0)
    assert result.stopped is None

    def plots(_: object, staging: Path) -> list[Path]:  # interrupted after its first figure
        (staging / "first.png").write_bytes(b"png")
        raise KeyboardInterrupt

    out = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt):
        write_run(result, out, plots=plots)
    metrics = check_set(out)  # exactly the files beside it: no half-drawn plot, no staging
    assert metrics["complete"] is True
    assert set(metrics["files"]) == {"events.csv", "series.csv"}


@pytest.mark.usefixtures("ctrl_c_as_a_terminal")
def test_ctrl_c_while_the_data_files_are_written_keeps_them_whole(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A (second) Ctrl-C while the events file is written: the data files and metrics.json
    are written whole, the plots are not begun, then the interrupt goes on up. A live
    session's double Ctrl-C left an empty folder under 'results in DIR'."""
    result = run_scenario(load_scenario("s100-teleop-v1", ["duration_s=12"]), seed=0)
    write_events = type(result.recorder).write_events_csv

    def interrupted_midway(recorder: object, path: Path, until_s: float) -> None:
        os.kill(os.getpid(), signal.SIGINT)  # handled at once, inside the write, unless held
        write_events(recorder, path, until_s)  # type: ignore[arg-type]

    monkeypatch.setattr(type(result.recorder), "write_events_csv", interrupted_midway)
    plotted: list[Path] = []
    out = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt):
        write_run(result, out, plots=lambda _, staging: plotted)
    metrics = check_set(out)
    assert set(metrics["files"]) == {"events.csv", "series.csv"}
    assert (out / "events.csv").read_text().count("\n") > 100  # whole: every event row


def test_an_interrupt_as_the_data_files_writing_begins_still_writes_them(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A (second) Ctrl-C that lands as write_run enters its held stretch, before it holds
    signals: it went on up with nothing written, and a live session's double Ctrl-C printed
    'results in DIR' over a folder without metrics.json. The data and metrics.json are now
    written whole first, then the interrupt goes on up."""
    from testbed.run import outputs

    result = run_scenario(load_scenario("s100-teleop-v1", ["duration_s=12"]), seed=0)
    held = outputs.deferred_interrupts
    entered: list[int] = []

    def interrupted_as_it_begins() -> Any:
        entered.append(1)
        if len(entered) == 1:  # the first stretch: the signal lands before it is held
            raise KeyboardInterrupt
        return held()

    monkeypatch.setattr(outputs, "deferred_interrupts", interrupted_as_it_begins)
    out = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt):
        write_run(result, out, plots=lambda _, staging: [])
    metrics = check_set(out)
    assert set(metrics["files"]) == {"events.csv", "series.csv"}  # no plots begun
    assert (out / "series.csv").read_text().count("\n") > 100


@pytest.fixture
def ctrl_c_as_a_terminal() -> Iterator[None]:
    """SIGINT handled as Python does by default (a KeyboardInterrupt), also where the tests run
    with it ignored (a shell's background job), so the CLI installs its handlers as for a user."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


@pytest.mark.usefixtures("ctrl_c_as_a_terminal")
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_after_the_simulation_ended_keeps_the_whole_run(
    signum: signal.Signals, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: Any
) -> None:
    """Ctrl-C (or SIGTERM) while a finished run is reduced to its metrics: the run is reduced
    whole and written, the command ends with its one line and 130/143 (it used to print
    ``testbed: interrupted`` and write nothing, the simulation thrown away)."""
    from testbed.cli.main import main
    from testbed.run import runner

    reduce = runner.compute_metrics
    signalled = {"n": 0}

    def reduce_with_a_signal(*args: Any, **kwargs: Any) -> Any:
        signalled["n"] += 1
        os.kill(os.getpid(), signum)  # delivered at the next Python line, here
        return reduce(*args, **kwargs)

    monkeypatch.setattr(runner, "compute_metrics", reduce_with_a_signal)
    out = tmp_path / "r"
    argv = ["run", "s100-teleop-v1", "--set", "duration_s=12", "--no-plots", "--out", str(out)]
    assert main(argv) == (130 if signum == signal.SIGINT else 143)
    assert signalled["n"] == 1
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["sim_s"] == 12.0 and metrics["complete"] is False  # marked: it was cut
    assert (out / "series.csv").read_text().count("\n") == 1 + 12 * 20  # 20 Hz rows, all
    err = [line for line in capsys.readouterr().err.splitlines() if line]
    assert len(err) == 1 and str(out) in err[0]
