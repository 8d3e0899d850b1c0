"""``--resume`` and ``--out``: provenance in sweep.json, identity by value, growing a sweep,
retrying failed runs, refusing a folder that is not empty, the lock, damaged manifests.

Sweeps here are 2–3 BER points × 1 seed of ``s100-teleop-v1`` for 8 simulated seconds
(≈ 0.15 s of CPU per run). The runs execute in this process (``execute_run``, the backends'
worker function, unchanged): what is tested here is the sweep's bookkeeping, the same whichever
backend ran the runs, and a process pool would start its worker (≈ 1.5 s of imports) for every
sweep. The backends themselves, and resuming after a real kill or interrupt, are tested in
test_sweep.py, test_signals.py and test_failures.py.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import shutil
from collections.abc import Iterator
from importlib import resources
from pathlib import Path
from typing import Any

import pytest

import testbed
from testbed.cli.main import main
from testbed.run.runner import run_scenario
from testbed.sweep import execute_run, read_journal

pytestmark = pytest.mark.usefixtures("no_sweep_plots")  # conftest.py: not their subject

SHORT = ["--set", "duration_s=8", "--set", "metrics.settle_s=1", "--workers", "1"]


def _sweep(folder: Path, ber: str = "[0.0, 1e-3]", scenario: str = "s100-teleop-v1") -> Path:
    path = folder / "s.toml"
    path.write_text(
        f'schema = 1\nid = "resume-v1"\ndescription = "d"\nscenario = "{scenario}"\n'
        f'metrics = ["link.uplink.per"]\nseeds = 1\n[grid]\n"link.ber" = {ber}\n',
        encoding="utf-8",
    )
    return path


def _one_line(capsys: pytest.CaptureFixture[str], fragment: str) -> str:
    err = capsys.readouterr().err
    assert fragment in err and err.count("\n") == 1 and "Traceback" not in err, err
    return err


@pytest.fixture(scope="module", autouse=True)
def _runs_in_this_process() -> Iterator[None]:
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(
            "testbed.sweep.runner.outcomes", lambda specs, *_: (execute_run(s) for s in specs)
        )
        yield


@pytest.fixture(scope="module")
def done(tmp_path_factory: pytest.TempPathFactory, no_sweep_plots: None) -> tuple[Path, Path]:
    """A finished 2-point sweep: (sweep file, results folder)."""
    folder = tmp_path_factory.mktemp("done")
    path, out = _sweep(folder), folder / "out"
    assert main(["sweep", str(path), *SHORT, "--out", str(out)]) == 0
    return path, out


def _copy(done: tuple[Path, Path], tmp_path: Path) -> Path:
    out = tmp_path / "copy"
    shutil.copytree(done[1], out)
    return out


def test_sweep_json_records_the_inputs_sha256_and_the_version(done: tuple[Path, Path]) -> None:
    manifest = json.loads((done[1] / "sweep.json").read_text())
    entry = resources.files("testbed").joinpath("scenarios", "s100-teleop-v1.toml")
    digest = hashlib.sha256(entry.read_bytes()).hexdigest()
    assert manifest["inputs"] == {"package:s100-teleop-v1": digest}
    assert manifest["testbed"] == testbed.__version__
    assert manifest["set"] == {"duration_s": 8.0, "metrics": {"settle_s": 1.0}}


def test_resume_refuses_a_changed_user_scenario_naming_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The review's case: the scenario file gains ``ber`` between the runs and the resume."""
    source = resources.files("testbed").joinpath("scenarios", "s100-teleop-v1.toml").read_text()
    scenario = tmp_path / "mine.toml"
    scenario.write_text(source.replace('id = "s100-teleop-v1"', 'id = "mine-v1"'))
    path, out = _sweep(tmp_path, scenario="mine.toml"), tmp_path / "out"
    assert main(["sweep", str(path), *SHORT, "--out", str(out)]) == 0
    held = json.loads((out / "sweep.json").read_text())["inputs"]
    assert held == {str(scenario): hashlib.sha256(scenario.read_bytes()).hexdigest()}
    scenario.write_text(scenario.read_text() + "\n# edited\n")
    capsys.readouterr()
    assert main(["sweep", str(path), *SHORT, "--out", str(out), "--resume"]) == 2
    _one_line(capsys, f"input {scenario}: changed (SHA-256 ")


def test_resume_compares_values_not_text(
    done: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """8 = 8.0 = 8e0, --set order, an inline table = its keys: the same sweep, nothing to run;
    another value is refused naming the key, old → new."""
    path, out = done[0], _copy(done, tmp_path)
    same = ["--set", "metrics={settle_s = 1e0}", "--set", "duration_s=8.0", "--workers", "1"]
    assert main(["sweep", str(path), *same, "--out", str(out), "--resume"]) == 0
    assert "0 ran now" in capsys.readouterr().out
    other = ["--set", "metrics.settle_s=2", "--set", "duration_s=8", "--workers", "1"]
    assert main(["sweep", str(path), *other, "--out", str(out), "--resume"]) == 2
    _one_line(capsys, "[set]/--set metrics.settle_s: 1.0 → 2.0")


def test_resume_grows_the_grid_running_only_the_new_points(
    done: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """BER 1e-4 added between 0 and 1e-3: one run; the rows then equal a fresh sweep's."""
    out = _copy(done, tmp_path)
    grown = _sweep(tmp_path, "[0.0, 1e-4, 1e-3]")
    assert main(["sweep", str(grown), *SHORT, "--out", str(out), "--resume"]) == 0
    assert "1 ran now" in capsys.readouterr().out
    fresh = tmp_path / "fresh"
    assert main(["sweep", str(grown), *SHORT, "--out", str(fresh)]) == 0
    for table in ("results.csv", "aggregate.csv"):
        assert (out / table).read_bytes() == (fresh / table).read_bytes()
    capsys.readouterr()
    assert main(["sweep", str(done[0]), *SHORT, "--out", str(out), "--resume"]) == 2
    _one_line(capsys, "grid.link.ber: 0.0001 removed")


def test_resume_takes_the_grid_in_another_order_as_the_same_runs(
    done: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """[1e-3, 0.0] after [0.0, 1e-3]: it called the journal "damaged" (the points' numbers
    moved); now nothing runs and the tables equal a fresh sweep's of that order."""
    out = _copy(done, tmp_path)
    swapped = _sweep(tmp_path, "[1e-3, 0.0]")
    assert main(["sweep", str(swapped), *SHORT, "--out", str(out), "--resume"]) == 0
    assert "0 ran now" in capsys.readouterr().out
    fresh = tmp_path / "fresh"
    assert main(["sweep", str(swapped), *SHORT, "--out", str(fresh)]) == 0
    for table in ("results.csv", "aggregate.csv"):
        assert (out / table).read_bytes() == (fresh / table).read_bytes()


def test_a_key_given_twice_in_grid_or_set_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A quoted dotted key and a nested one name one setting: TOML takes both and the last
    won, silently (a figure of the wrong BER values)."""
    for table, lines in (
        ("grid", '[grid]\n"link.ber" = [0.0, 1e-4]\nlink.ber = [1e-3, 1e-2]\n'),
        ("set", '[set]\n"link.ber" = 1e-3\nlink.ber = 0.0\n[grid]\n"link.ipg_s" = [0.6]\n'),
    ):
        path = tmp_path / f"{table}.toml"
        head = 'schema = 1\nid = "twice-v1"\ndescription = "d"\nscenario = "s100-teleop-v1"\n'
        path.write_text(head + "seeds = 1\n" + lines, encoding="utf-8")
        assert main(["sweep", str(path), "--out", str(tmp_path / table)]) == 2
        _one_line(capsys, f"{path}: {table}.link.ber: given twice")


def test_failed_runs_are_run_again_on_resume(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Runs at BER > 0 fail in the first invocation (the runner raises);
    --resume runs exactly those again, and their rows then are the successful ones."""
    path, out = _sweep(tmp_path), tmp_path / "out"
    real = run_scenario

    def flaky(scenario: Any, *, seed: int | None = None) -> Any:
        if scenario.link.channel.ber > 0.0:
            raise OSError("scenario file moved away")
        return real(scenario, seed=seed)

    monkeypatch.setattr("testbed.run.runner.run_scenario", flaky)
    assert main(["sweep", str(path), *SHORT, "--out", str(out)]) == 1
    assert "FAILED point 1 seed 0" in capsys.readouterr().out
    monkeypatch.setattr("testbed.run.runner.run_scenario", real)
    assert main(["sweep", str(path), *SHORT, "--out", str(out), "--resume"]) == 0
    assert "2 runs, 0 failed; 1 ran now" in capsys.readouterr().out
    statuses = [(r["point"], r["status"]) for r in read_journal(out / "runs.jsonl")]
    assert statuses == [(0, "ok"), (1, "failed"), (1, "ok")]  # the failure stays on record
    results = (out / "results.csv").read_text().splitlines()
    assert [line.split(",")[3] for line in results[1:]] == ["ok", "ok"]


@pytest.mark.parametrize("held", ["runs.jsonl", "results.csv"])
def test_a_non_empty_out_is_refused_without_resume_and_force_starts_afresh(
    done: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str], held: str
) -> None:
    """A user's file or a stray journal (no sweep.json) is neither overwritten nor adopted;
    --force removes a sweep's files only and starts afresh."""
    out = tmp_path / "user"
    out.mkdir()
    (out / held).write_text("mine\n")
    argv = ["sweep", str(done[0]), *SHORT, "--out", str(out)]
    assert main(argv) == 2
    _one_line(capsys, f"--out: {out} is not empty (use --force to write a sweep there)")
    assert [p.name for p in out.iterdir()] == [held]
    assert main([*argv, "--force", "--resume"]) == 2
    _one_line(capsys, "--force: not with --resume")
    assert main([*argv, "--force"]) == 0
    assert (out / "results.csv").read_bytes() == (done[1] / "results.csv").read_bytes()
    (out / "notes.txt").write_text("mine\n")
    assert main([*argv, "--force"]) == 0  # the sweep's files replaced, the user's kept
    assert (out / "notes.txt").read_text() == "mine\n"
    assert (out / "results.csv").read_bytes() == (done[1] / "results.csv").read_bytes()


def test_a_second_sweep_on_a_locked_out_is_refused(
    done: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = _copy(done, tmp_path)
    with (out / ".sweep.lock").open("a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # as a running sweep holds it
        assert main(["sweep", str(done[0]), *SHORT, "--out", str(out), "--resume"]) == 2
        _one_line(capsys, f"--out: {out} is in use by another testbed sweep")
    assert main(["sweep", str(done[0]), *SHORT, "--out", str(out), "--resume"]) == 0


@pytest.mark.parametrize(
    ("content", "fragment"),
    [
        ("{not json", "sweep.json: damaged (not a sweep.json written by testbed sweep)"),
        ("[1, 2]", "sweep.json: damaged (not a sweep.json written by testbed sweep)"),
        ('{"id": "resume-v1", "seeds": [0]}', "was written by an older testbed"),
    ],
)
def test_a_damaged_or_old_sweep_json_is_not_called_a_different_sweep(
    done: tuple[Path, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    content: str,
    fragment: str,
) -> None:
    out = _copy(done, tmp_path)
    (out / "sweep.json").write_text(content)
    assert main(["sweep", str(done[0]), *SHORT, "--out", str(out), "--resume"]) == 2
    _one_line(capsys, fragment)
