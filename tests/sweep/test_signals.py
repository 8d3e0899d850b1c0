"""Real signals to a real ``testbed sweep`` (pool and ``--dask local``): exit codes, the one line,
a journal of complete rows that ``--resume`` completes exactly, and no process left behind. Last,
a Ctrl-C landing, deterministically, in the dry run made before the first run.

Every sweep runs ``s100-teleop-v1`` for 8 simulated seconds, 3 BER values × 8 seeds (24 runs):
still running when the first journal line appears. Waits are bounded by multiples of the time
the sweep took to record its first run (``scale``: interpreter start, grid check, worker spawn,
one run on this machine under its present load), polled, never slept blindly. The pool's
interrupted sweep is resumed by a second pool sweep; the ``--dask local`` one by ``main`` in
this process with the runs executed here (``execute_run``, the backends' worker function): what
the resume reads and completes is the journal, whoever runs the rest, and a second
LocalCluster would cost seconds of start-up for nothing the test checks.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from testbed.cli.main import main
from testbed.sweep import execute_run, read_journal
from tests.processes import default_sigint

pytestmark = pytest.mark.usefixtures("no_sweep_plots")  # conftest.py: not their subject

SHORT = ["--set", "duration_s=8", "--set", "metrics.settle_s=1"]
SWEEP = """\
schema = 1
id = "signals-v1"
description = "3 BER values x 8 seeds"
scenario = "s100-teleop-v1"
seeds = 8
metrics = ["link.uplink.per", "command_age_s.mean"]

[grid]
"link.ber" = [0.0, 1e-4, 1e-3]
"""
SEEDS = 8
TOTAL = 3 * SEEDS


def _stat(pid: int) -> tuple[str, int, int] | None:
    """(state, ppid, start time) of ``pid`` from /proc, or None if it is gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = text[text.rfind(")") + 2 :].split()
    return fields[0], int(fields[1]), int(fields[19])


def _descendants(root: int) -> dict[int, int]:
    """Every process below ``root``: {pid: start time} (a scan of /proc for ppid chains)."""
    parents: dict[int, tuple[int, int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit() and (stat := _stat(int(entry.name))) is not None:
            parents[int(entry.name)] = (stat[1], stat[2])
    found: dict[int, int] = {}
    frontier = [root]
    while frontier:
        parent = frontier.pop()
        for pid, (ppid, start) in parents.items():
            if ppid == parent and pid not in found:
                found[pid] = start
                frontier.append(pid)
    return found


def _alive(processes: dict[int, int]) -> list[int]:
    """Those of ``processes`` still running (same pid and start time, not a zombie)."""
    alive = []
    for pid, start in processes.items():
        stat = _stat(pid)
        if stat is not None and stat[2] == start and stat[0] not in ("Z", "X"):
            alive.append(pid)
    return alive


def _poll(condition: Callable[[], bool], bound_s: float) -> bool:
    deadline = time.monotonic() + bound_s
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.05)
    return condition()


def _journal_lines(path: Path) -> int:
    return path.read_bytes().count(b"\n") if path.exists() else 0


class Sweep:
    """A ``testbed sweep`` subprocess in its own session (so a group signal is a Ctrl-C)."""

    def __init__(self, folder: Path, *extra: str) -> None:
        self.file = folder / "signals.toml"
        self.file.write_text(SWEEP, encoding="utf-8")
        self.out = folder / "out"
        self.extra = extra  # in the CLI's order: --workers, then --dask
        self.argv = [sys.executable, "-m", "testbed", "sweep", str(self.file), *SHORT, *extra]
        self.argv += ["--out", str(self.out)]
        start = time.monotonic()
        self.process = subprocess.Popen(
            self.argv,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,
            preexec_fn=default_sigint,
        )
        journal = self.out / "runs.jsonl"
        # the first recorded run: bounded by a generous multiple of nothing yet known, so poll
        # until it appears or the process ends (a failure shows its stderr)
        while _journal_lines(journal) < 1 and self.process.poll() is None:
            time.sleep(0.05)
        assert self.process.poll() is None, self.stderr()
        self.scale = time.monotonic() - start
        self.children = _descendants(self.process.pid)

    def stderr(self) -> str:
        assert self.process.stderr is not None
        if self.process.poll() is None:
            return ""
        return self.process.stderr.read()

    def wait(self) -> tuple[int, str]:
        """Exit code and stderr, within a bound of a few times the first run's time."""
        try:
            self.process.wait(timeout=10 * self.scale + 10)
        except subprocess.TimeoutExpired:
            os.killpg(self.process.pid, signal.SIGKILL)
            self.process.wait()
            pytest.fail(f"the sweep did not end within {10 * self.scale + 10:.0f} s")
        return self.process.returncode, self.stderr()

    def kill_leftovers(self) -> None:
        for pid in _alive(self.children):
            os.kill(pid, signal.SIGKILL)


def _check_interrupted(sweep: Sweep, code: int, expected: int, err: str) -> None:
    assert code == expected, err
    last = err.rstrip("\n").splitlines()[-1]
    done = len(read_journal(sweep.out / "runs.jsonl"))
    resume = " ".join(["testbed sweep", str(sweep.file), *SHORT, *sweep.extra])
    assert last == (
        f"testbed: interrupted after {done} of {TOTAL} runs; journal kept in {sweep.out}; "
        f"resume with: {resume} --out {sweep.out} --resume"
    ), err
    assert "Traceback" not in err and "Error" not in err, err
    data = (sweep.out / "runs.jsonl").read_bytes()
    assert data.endswith(b"\n")
    rows = [json.loads(line) for line in data.splitlines()]  # every line a complete row
    assert 1 <= len(rows) < TOTAL
    assert len({(r["point"], r["seed"]) for r in rows}) == len(rows)
    results = (sweep.out / "results.csv").read_text(encoding="utf-8").splitlines()
    assert len(results) == 1 + len(rows)  # regenerated from the journal
    assert (sweep.out / "aggregate.csv").exists()
    # no worker, nanny or resource tracker outlives the sweep
    assert sweep.children, "no worker processes seen"
    assert _poll(lambda: not _alive(sweep.children), 5 * sweep.scale + 5), _alive(sweep.children)


def _resume_completes_the_rest(sweep: Sweep, *extra: str) -> None:
    before = len(read_journal(sweep.out / "runs.jsonl"))
    argv = [sys.executable, "-m", "testbed", "sweep", str(sweep.file), *SHORT, *extra]
    resumed = subprocess.run(
        [*argv, "--out", str(sweep.out), "--resume"], capture_output=True, text=True, check=False
    )
    assert resumed.returncode == 0, resumed.stderr
    assert f"{TOTAL - before} ran now" in resumed.stdout
    keys = [(r["point"], r["seed"]) for r in read_journal(sweep.out / "runs.jsonl")]
    assert sorted(keys) == [(p, s) for p in range(3) for s in range(SEEDS)]  # each exactly once


def test_pool_ctrl_c_exits_130_with_one_line_keeps_the_journal_and_resumes(
    tmp_path: Path,
) -> None:
    sweep = Sweep(tmp_path, "--workers", "2")
    try:
        os.killpg(sweep.process.pid, signal.SIGINT)  # a Ctrl-C: the whole process group
        code, err = sweep.wait()
        _check_interrupted(sweep, code, 128 + signal.SIGINT, err)
    finally:
        sweep.kill_leftovers()
    _resume_completes_the_rest(sweep, "--workers", "2")


def test_pool_sigterm_exits_143_with_one_line_and_no_orphan(tmp_path: Path) -> None:
    sweep = Sweep(tmp_path, "--workers", "2")
    try:
        sweep.process.send_signal(signal.SIGTERM)  # `kill PID`: the sweep only
        code, err = sweep.wait()
        _check_interrupted(sweep, code, 128 + signal.SIGTERM, err)
    finally:
        sweep.kill_leftovers()


@pytest.mark.parametrize("backend", [("--workers", "2"), ("--workers", "2", "--dask", "local")])
def test_sigkill_of_the_sweep_takes_its_workers_and_the_resource_tracker(
    tmp_path: Path, backend: tuple[str, ...]
) -> None:
    sweep = Sweep(tmp_path, *backend)
    try:
        assert len(sweep.children) >= 2
        sweep.process.kill()  # the sweep alone: nothing can clean up but the kernel
        assert sweep.process.wait(timeout=10 * sweep.scale + 10) == -signal.SIGKILL
        gone = _poll(lambda: not _alive(sweep.children), 5 * sweep.scale + 5)
        assert gone, f"orphans: {_alive(sweep.children)}"
    finally:
        sweep.kill_leftovers()
        if sweep.process.stderr is not None:
            sweep.process.stderr.close()


def test_dask_local_ctrl_c_exits_130_with_one_line_and_resumes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    extra = ("--workers", "2", "--dask", "local")
    sweep = Sweep(tmp_path, *extra)
    try:
        os.killpg(sweep.process.pid, signal.SIGINT)
        code, err = sweep.wait()
        _check_interrupted(sweep, code, 128 + signal.SIGINT, err)
    finally:
        sweep.kill_leftovers()
    before = len(read_journal(sweep.out / "runs.jsonl"))
    monkeypatch.setattr(
        "testbed.sweep.runner.outcomes", lambda specs, *_: (execute_run(s) for s in specs)
    )
    assert main(["sweep", str(sweep.file), *SHORT, "--out", str(sweep.out), "--resume"]) == 0
    assert f"{TOTAL - before} ran now" in capsys.readouterr().out
    keys = [(r["point"], r["seed"]) for r in read_journal(sweep.out / "runs.jsonl")]
    assert sorted(keys) == [(p, s) for p in range(3) for s in range(SEEDS)]  # each exactly once


@pytest.mark.slow
def test_dask_local_sigterm_exits_143_with_one_line_and_no_orphan(tmp_path: Path) -> None:
    sweep = Sweep(tmp_path, "--workers", "2", "--dask", "local")
    try:
        sweep.process.send_signal(signal.SIGTERM)
        code, err = sweep.wait()
        _check_interrupted(sweep, code, 128 + signal.SIGTERM, err)
    finally:
        sweep.kill_leftovers()


# --- Ctrl-C before the first run ----------------------------------------------------------------


def _ctrl_c_in_the_first_simulation(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Raise a KeyboardInterrupt (what the CLI's SIGINT handler raises) inside the next
    simulation run in this process, once; make a run list that starts afterwards fail the test.
    Returns the count of simulations entered (one element each)."""
    import simpy

    real_run = simpy.Environment.run
    entered: list[int] = []

    def ctrl_c_once(self: simpy.Environment, until: Any = None) -> Any:
        entered.append(1)
        if len(entered) == 1:
            raise KeyboardInterrupt
        return real_run(self, until)

    monkeypatch.setattr(simpy.Environment, "run", ctrl_c_once)
    monkeypatch.setattr("testbed.sweep.runner.outcomes", lambda *args: pytest.fail("runs began"))
    return entered


def test_ctrl_c_during_the_metric_check_exits_130_and_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The dry run that lists the metrics (check_metrics) runs in the sweep's own process:
    interrupted, it stops early and returns what it ran, as every run does; the sweep must
    stop there too, not take it for a finished run and go on with the runs."""
    path = tmp_path / "signals.toml"
    path.write_text(SWEEP, encoding="utf-8")
    out = tmp_path / "out"
    entered = _ctrl_c_in_the_first_simulation(monkeypatch)
    assert main(["sweep", str(path), *SHORT, "--workers", "2", "--out", str(out)]) == 130
    assert entered == [1]  # the dry run, and nothing after it
    err = capsys.readouterr().err
    assert err == "testbed: interrupted before the first run; nothing written\n"
    assert not out.exists()  # a rerun is not refused as "already holds a sweep"


def test_ctrl_c_during_the_metric_check_of_a_resume_keeps_the_journal(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "signals.toml"
    path.write_text(SWEEP.replace("seeds = 8", "seeds = 1"), encoding="utf-8")
    out = tmp_path / "out"
    with monkeypatch.context() as inline:  # the 3 runs in this process
        inline.setattr(
            "testbed.sweep.runner.outcomes",
            lambda specs, *_: (execute_run(spec) for spec in specs),
        )
        assert main(["sweep", str(path), *SHORT, "--out", str(out)]) == 0
    journal = out / "runs.jsonl"
    journal.write_bytes(b"".join(journal.read_bytes().splitlines(keepends=True)[:2]))
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    capsys.readouterr()
    entered = _ctrl_c_in_the_first_simulation(monkeypatch)
    assert main(["sweep", str(path), *SHORT, "--out", str(out), "--resume"]) == 130
    assert entered == [1]
    resume = f"testbed sweep {path} {' '.join(SHORT)} --out {out} --resume"
    assert capsys.readouterr().err == (
        f"testbed: interrupted after 2 of 3 runs; journal kept in {out}; resume with: {resume}\n"
    )
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
