"""What the system refuses: an --out it cannot write (a name too long, a folder under /proc), a
disk that fills while the sweep writes (a real EFBIG from RLIMIT_FSIZE), a pool worker killed
with SIGKILL. One line each, never a traceback; the journal kept and resumable."""

from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from testbed.cli.main import main
from testbed.sweep import execute_run, read_journal
from tests.sweep.test_signals import _descendants

pytestmark = pytest.mark.usefixtures("no_sweep_plots")  # conftest.py: not their subject

SHORT = ["--set", "duration_s=8", "--set", "metrics.settle_s=1"]


def _sweep(folder: Path, seeds: int = 1) -> Path:
    path = folder / "s.toml"
    path.write_text(
        'schema = 1\nid = "fail-v1"\ndescription = "d"\nscenario = "s100-teleop-v1"\n'
        f'metrics = ["link.uplink.per"]\nseeds = {seeds}\n[grid]\n'
        '"link.ber" = [0.0, 1e-4, 1e-3]\n',
        encoding="utf-8",
    )
    return path


@pytest.mark.parametrize("out", ["x" * 300, "/proc/testbed-sub"])
@pytest.mark.parametrize("command", ["sweep", "run"])
def test_an_out_the_system_refuses_is_one_line_before_any_work(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    out: str,
    command: str,
) -> None:
    """ENAMETOOLONG and ENOENT (no folder can be made under /proc): exit 2, one line naming
    the path, before the grid is checked or a run starts; nothing left behind."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("testbed.sweep.spec.check_points", lambda *a: pytest.fail("checked"))
    monkeypatch.setattr("testbed.run.runner.run_scenario", lambda *a, **k: pytest.fail("ran"))
    source = str(_sweep(tmp_path)) if command == "sweep" else "s100-teleop-v1"
    assert main([command, source, *SHORT, "--out", out]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"testbed: error: --out: {out}") and err.count("\n") == 1, err
    assert "Traceback" not in err
    expected = ["s.toml"] if command == "sweep" else []
    assert sorted(p.name for p in tmp_path.iterdir()) == expected


def _limited(limit_bytes: int) -> None:
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, limit_bytes))


@pytest.mark.slow  # two sweeps of 9 runs in subprocesses: ≈ 10 s alone, a minute under load
def test_a_full_disk_names_the_file_leaves_no_temp_file_and_resumes(tmp_path: Path) -> None:
    """Files may not grow past 12 kB (RLIMIT_FSIZE: the kernel's EFBIG, as ENOSPC on a full
    disk): the sweep stops with one line naming the file and the resume command, exit 1, the
    journal holds only whole records and no ``*.tmp`` is left; the resume, with room, ends
    with every run once."""
    path, out = _sweep(tmp_path, seeds=3), tmp_path / "out"
    argv = [sys.executable, "-m", "testbed", "sweep", str(path), *SHORT, "--workers", "1"]
    full = subprocess.run(
        [*argv, "--out", str(out)],
        capture_output=True,
        text=True,
        check=False,
        preexec_fn=lambda: _limited(12_000),
    )
    last = full.stderr.strip().splitlines()[-1]
    assert full.returncode == 1, full.stderr
    assert "Traceback" not in full.stderr
    assert last.startswith(f"testbed: cannot write {out}/") and "File too large after" in last
    assert last.endswith(f"--out {out} --resume")
    assert not list(out.glob("*.tmp"))
    kept = read_journal(out / "runs.jsonl")  # whole records only (a damaged one would raise)
    assert len(kept) < 9
    resumed = subprocess.run([*argv, "--out", str(out), "--resume"], capture_output=True, text=True)
    assert resumed.returncode == 0, resumed.stderr
    keys = sorted((r["point"], r["seed"]) for r in read_journal(out / "runs.jsonl"))
    assert keys == [(p, s) for p in range(3) for s in range(3)]


@pytest.mark.slow  # two sweeps of 24 runs in subprocesses: ≈ 15 s alone
def test_a_killed_pool_worker_stops_the_sweep_with_one_line_and_it_resumes(
    tmp_path: Path,
) -> None:
    """SIGKILL to one pool worker (as the OOM killer would): exit 1, one line with the resume
    command, no traceback, the finished runs kept; the resume runs the rest."""
    path, out = _sweep(tmp_path, seeds=8), tmp_path / "out"
    argv = [sys.executable, "-m", "testbed", "sweep", str(path), *SHORT, "--workers", "2"]
    process = subprocess.Popen(
        [*argv, "--out", str(out)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
    )
    assert process.stderr is not None
    line = process.stderr.readline()  # the first progress line: the pool is running
    assert "/24 runs" in line, line
    workers: list[int] = []
    deadline = time.monotonic() + 30
    while not workers and time.monotonic() < deadline:
        workers = [
            pid
            for pid in _descendants(process.pid)
            if "spawn_main" in Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace")
        ]
    assert workers, "no pool worker found"
    os.kill(workers[0], signal.SIGKILL)
    err = process.stderr.read()
    process.stderr.close()
    assert process.wait(timeout=60) == 1, err
    assert "Traceback" not in err
    last = err.strip().splitlines()[-1]
    assert last.startswith("testbed: a worker process of the sweep died"), err
    assert last.endswith(f"--out {out} --resume")
    before = read_journal(out / "runs.jsonl")
    resumed = subprocess.run([*argv, "--out", str(out), "--resume"], capture_output=True, text=True)
    assert resumed.returncode == 0, resumed.stderr
    assert f"{24 - len(before)} ran now" in resumed.stdout
    keys = sorted((r["point"], r["seed"]) for r in read_journal(out / "runs.jsonl"))
    assert keys == [(p, s) for p in range(3) for s in range(8)]


def test_a_killed_dask_worker_is_replaced_and_no_run_is_lost(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """SIGKILL to one ``--dask local`` worker mid-sweep: the nanny starts a new worker, the
    scheduler runs the lost task again, and the sweep ends with every run, its results
    byte-identical to an undisturbed sweep of the same points and seeds (run by ``main`` in this
    process, the runs one after another here: ``execute_run``, the backends' worker function)."""
    path = _sweep(tmp_path, seeds=2)
    longer = ["--set", "duration_s=20", "--set", "metrics.settle_s=1"]  # runs still going
    argv = [sys.executable, "-m", "testbed", "sweep", str(path), *longer, "--workers", "2"]
    out, reference = tmp_path / "dask", tmp_path / "reference"
    process = subprocess.Popen(
        [*argv, "--dask", "local", "--out", str(out)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert process.stderr is not None
    line = process.stderr.readline()  # the first progress line: the workers are running
    assert "/6 runs" in line and not line.startswith("fail-v1: 6/6"), line

    def workers() -> set[int]:
        return {
            pid
            for pid in _descendants(process.pid)
            if "spawn_main" in Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace")
        }

    before = workers()
    assert len(before) == 2, before
    os.kill(min(before), signal.SIGKILL)
    done_at_kill = len((out / "runs.jsonl").read_text(encoding="utf-8").splitlines())
    assert done_at_kill < 6 and process.poll() is None  # the kill came mid-sweep
    err = process.stderr.read()
    process.stderr.close()
    assert process.wait(timeout=120) == 0, err
    assert "Traceback" not in err
    journal = read_journal(out / "runs.jsonl")
    keys = sorted((r["point"], r["seed"]) for r in journal)
    assert keys == [(p, s) for p in range(3) for s in range(2)]
    monkeypatch.setattr(
        "testbed.sweep.runner.outcomes", lambda specs, *_: (execute_run(s) for s in specs)
    )
    assert main(["sweep", str(path), *longer, "--out", str(reference)]) == 0
    for name in ("results.csv", "aggregate.csv"):
        assert (out / name).read_bytes() == (reference / name).read_bytes(), name
