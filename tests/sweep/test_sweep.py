"""`testbed sweep`: grid expansion, pool and Dask give the same rows, kill -9 and resume, failures.

Every sweep here runs ``s100-teleop-v1`` for 8 simulated seconds (≈ 0.15 s of CPU per run).
Where the backend is not what a test is about (resuming, --seeds, a reference sweep to compare
with), the runs execute in this process (``inline_runs``: ``execute_run``, the backends' worker
function, unchanged) rather than in a process pool that starts its workers (≈ 1.5 s of imports
each) for every sweep.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import os
import shutil
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from testbed.cli.main import main
from testbed.config import ConfigError, parse_override
from testbed.run.runner import run_scenario
from testbed.run.scenario import load_scenario
from testbed.sweep import (
    EXCLUDED_METRICS,
    RunSpec,
    Sweep,
    aggregate_rows,
    execute_run,
    expand,
    flatten_metrics,
    load_sweep,
    read_journal,
    sweep_names,
    toml_literal,
)

pytestmark = pytest.mark.usefixtures("no_sweep_plots")  # conftest.py: not their subject

SHORT = ["--set", "duration_s=8", "--set", "metrics.settle_s=1"]
BER_SWEEP = """\
schema = 1
id = "ber-small-v1"
description = "3 BER values x {seeds} seeds"
scenario = "s100-teleop-v1"
seeds = {seeds}
metrics = ["link.uplink.per", "command_age_s.mean"]

[grid]
"link.ber" = {{ scale = "log", start = 1e-4, stop = 1e-3, num = 2, include = [0.0] }}
"""


def _write_sweep(folder: Path, seeds: int) -> Path:
    path = folder / f"ber-{seeds}.toml"
    path.write_text(BER_SWEEP.format(seeds=seeds), encoding="utf-8")
    return path


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(encoding="utf-8", newline="") as handle:
        return list(csv.DictReader(handle))


# --- the sweep file ------------------------------------------------------------------------------


def test_log_and_linear_ranges_expand_to_the_closed_form(tmp_path: Path) -> None:
    path = tmp_path / "grid.toml"
    path.write_text(
        'schema = 1\nid = "grid-v1"\ndescription = "d"\nscenario = "s100-teleop-v1"\n'
        'seeds = [7, 3]\n[set]\n"link.ipg" = "fixed"\n[grid]\n'
        '"link.ber" = { scale = "log", start = 1e-6, stop = 1e-3, num = 4, include = [0.0] }\n'
        "[grid.link]\nipg_s = { scale = 'linear', start = 0.5, stop = 1.5, num = 5 }\n",
        encoding="utf-8",
    )
    sweep = load_sweep(str(path))
    (ber_key, ber), (ipg_key, ipg) = sweep.axes
    assert (ber_key, ipg_key) == ("link.ber", "link.ipg_s")  # file order; nested tables dotted
    assert ber == (0.0, 1e-6, 1e-5, 1e-4, 1e-3)  # 10^(-6..-3), rounded to 12 digits: exact
    assert ipg == pytest.approx((0.5, 0.75, 1.0, 1.25, 1.5), abs=0.0)
    assert sweep.seeds == (7, 3)
    runs = expand(sweep)
    assert len(runs) == 5 * 5 * 2
    assert [(r.point, r.seed) for r in runs[:3]] == [(0, 7), (0, 3), (1, 7)]
    # last axis fastest: point 1 is (ber 0, ipg 0.75); point 5 is (ber 1e-6, ipg 0.5)
    assert runs[2].overrides == ('link.ipg="fixed"', "link.ber=0.0", "link.ipg_s=0.75")
    assert runs[10].overrides[1:] == ("link.ber=1e-06", "link.ipg_s=0.5")
    scenario = load_scenario(runs[10].scenario, runs[10].overrides)
    assert scenario.link.channel.ber == 1e-6 and scenario.link.ipg_s == 0.5


def test_packaged_ber_vs_lag_sweeps_ber_from_0_to_1e3_on_a_log_grid() -> None:
    assert "ber-vs-lag-v1" in sweep_names()
    sweep = load_sweep("ber-vs-lag-v1")
    ber = dict(sweep.axes)["link.ber"]
    assert ber[0] == 0.0 and ber[-1] == 1e-3
    ratios = np.diff(np.log10(ber[1:]))
    assert np.allclose(ratios, ratios[0]) and ratios[0] > 0  # evenly spaced exponents
    assert "link.ipg_s" in dict(sweep.axes)
    for name in sweep_names():
        assert load_sweep(name).id == name


@pytest.mark.parametrize(
    "value",
    [0.0, 1e-5, 3.16227766017e-05, 0.1 + 0.2, -7, True, "ecs-3h", [-0.5, 0.0, 1.0], [], math.inf],
)
def test_toml_literal_round_trips_through_set_parsing(value: object) -> None:
    _, parsed = parse_override(f"k={toml_literal(value)}")
    assert parsed == value and type(parsed) is type(value)


@pytest.mark.parametrize(
    ("grid", "fragment"),
    [
        ('"link.ber" = []', "grid.link.ber: expected a non-empty array"),
        (
            '"link.ber" = { scale = "log", start = 0.0, stop = 1e-3, num = 3 }',
            "grid.link.ber.start",
        ),
        (
            '"link.ber" = { scale = "cubic", start = 1.0, stop = 2.0, num = 3 }',
            "grid.link.ber.scale",
        ),
        ('"link.ber" = [0.0, 2.0]', "grid point link.ber=2.0: link.ber: must be in [0, 1]"),
        ('"link.wobble" = [1]', "link.wobble: unknown key"),
        ('"seed" = [1, 2]', "grid.seed: 'seed' cannot be swept"),
        ('"duration_s" = [5.0]', "grid.duration_s: also fixed in [set]"),
        ('"link.ber" = [0.0, 1e-3, 0.0]', "grid.link.ber: must not repeat a value, got 0.0 twice"),
        ('"link.ber" = [0, 0.0]', "grid.link.ber: must not repeat a value, got 0.0 twice"),
        ('"link" = {}', "grid.link: expected a non-empty array or a range table"),
        ("[grid.link]", "grid.link: expected a non-empty array or a range table"),
        (
            '"link.ber" = { scale = "linear", start = 0.0, stop = 1e-3, num = 100000000000 }',
            "grid.link.ber.num: must be ≤ 10000, got 100000000000",
        ),
        (
            '"link.ber" = { scale = "linear", start = 0.0, stop = 1e-3, num = 10000 }\n'
            '"link.ipg_s" = [0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 4.5, 5.0, 5.5]',
            "grid, seeds: 110000 points × 1 seeds = 110000 runs, more than the 100000",
        ),
    ],
)
def test_bad_sweep_files_exit_2_with_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], grid: str, fragment: str
) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(
        'schema = 1\nid = "bad-v1"\ndescription = "d"\nscenario = "s100-teleop-v1"\n'
        f'[set]\nduration_s = 8.0\n"metrics.settle_s" = 1.0\n[grid]\n{grid}\n',
        encoding="utf-8",
    )
    assert main(["sweep", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert fragment in err and err.count("\n") == 1, err
    assert not (tmp_path / "out").exists()


# --- aggregation ---------------------------------------------------------------------------------


def _toy_sweep() -> Sweep:
    return Sweep(
        id="toy-v1",
        description="",
        scenario="s100-teleop-v1",
        overrides=(),
        axes=(("link.ber", (0.0, 1e-3)),),
        seeds=(0, 1, 2, 3, 4),
        metrics=("m",),
        source="toy",
    )


def test_interval_of_a_probability_stays_within_zero_and_one() -> None:
    """Two seeds with PER 0.02 and 0.12: mean 0.07, s = 0.0707, t(0.975, 1) = 12.706205, so
    the t interval is 0.07 ± 0.635 = (−0.565, 0.705); a PER cannot be below 0, so the interval
    is (0, 0.705). The same numbers as another metric keep their t interval."""
    sweep = dataclasses.replace(_toy_sweep(), metrics=("link.uplink.per", "m"))
    rows = [
        {"point": 0, "seed": s, "status": "ok", "error": "", "link.uplink.per": v, "m": v}
        for s, v in ((0, 0.02), (1, 0.12))
    ]
    (point, _) = aggregate_rows(sweep, rows)
    half = 12.7062047 * math.sqrt(0.005) / math.sqrt(2)
    assert point["m.ci_low"] == pytest.approx(0.07 - half) and point["m.ci_low"] < 0
    assert point["link.uplink.per.ci_low"] == 0.0
    assert point["link.uplink.per.ci_high"] == pytest.approx(0.07 + half)
    near_one = [dict(r, **{"link.uplink.per": 1 - r["m"]}) for r in rows]
    (point, _) = aggregate_rows(sweep, near_one)
    assert point["link.uplink.per.ci_high"] == 1.0
    assert point["link.uplink.per.ci_low"] == pytest.approx(0.93 - half)


def test_aggregate_median_p95_and_student_t_interval_by_hand() -> None:
    rows: list[dict[str, object]] = [
        {"point": 0, "seed": s, "status": "ok", "error": "", "m": float(v)}
        for s, v in zip(range(5), [3, 1, 5, 2, 4], strict=True)
    ]
    rows += [
        {"point": 1, "seed": 0, "status": "ok", "error": "", "m": 1.0},
        {"point": 1, "seed": 1, "status": "ok", "error": "", "m": 3.0},
        {"point": 1, "seed": 2, "status": "ok", "error": "", "m": None},  # null metric
        {"point": 1, "seed": 3, "status": "failed", "error": "boom"},
    ]
    first, second = aggregate_rows(_toy_sweep(), rows)
    # 1..5: median 3, p95 (linear interpolation) 4 + 0.8·1 = 4.8, s = √2.5, t(0.975, 4) = 2.776445
    assert first["m.median"] == 3.0 and first["m.p95"] == pytest.approx(4.8)
    half = 2.7764451052 * math.sqrt(2.5) / math.sqrt(5)
    assert (first["m.ci_low"], first["m.ci_high"]) == pytest.approx((3 - half, 3 + half))
    # {1, 3}: mean 2, s = √2, t(0.975, 1) = 12.706205 → half width 12.706205
    assert second["n_ok"] == 3 and second["n_failed"] == 1 and second["m.n"] == 2
    assert (second["m.ci_low"], second["m.ci_high"]) == pytest.approx(
        (2 - 12.7062047, 2 + 12.7062047)
    )
    assert second["link.ber"] == 1e-3
    only_other = {"point": 0, "seed": 0, "status": "ok", "error": "", "other": 1.0}
    with pytest.raises(ConfigError, match="unknown metric 'm'"):
        aggregate_rows(_toy_sweep(), [only_other])


def test_image_runs_record_their_chunk_size_and_mode_after_the_metrics() -> None:
    image_keys = ("images.changes=[]", "images.chunk_bytes=20", "images.selective_repeat=false")
    images = execute_run(RunSpec(0, 0, "s100-video-v1", (*SHORT[1::2], *image_keys)))
    assert images.error == "" and images.metrics is not None
    assert list(images.metrics)[-2:] == ["images.chunk_bytes", "images.selective_repeat"]
    assert images.metrics["images.chunk_bytes"] == 20
    assert images.metrics["images.selective_repeat"] is False
    teleop = execute_run(RunSpec(0, 0, "s100-teleop-v1", tuple(SHORT[1::2])))
    assert teleop.metrics is not None and not any(k.startswith("images.") for k in teleop.metrics)


# --- running -------------------------------------------------------------------------------------


@pytest.fixture
def inline_runs() -> Iterator[None]:
    """The runs of every sweep started in this process execute here, one after another."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(
            "testbed.sweep.runner.outcomes",
            lambda specs, *_: (execute_run(spec) for spec in specs),
        )
        yield


@pytest.fixture(scope="module")
def pool_sweep(tmp_path_factory: pytest.TempPathFactory, no_sweep_plots: None) -> tuple[Path, Path]:
    """The 3 BER × 2 seeds sweep through the local process pool: (sweep file, results dir)."""
    folder = tmp_path_factory.mktemp("pool")
    path = _write_sweep(folder, seeds=2)
    out = folder / "out"
    assert main(["sweep", str(path), *SHORT, "--workers", "2", "--out", str(out)]) == 0
    return path, out


def test_pool_rows_match_a_direct_run(pool_sweep: tuple[Path, Path]) -> None:
    _, out = pool_sweep
    rows = _rows(out / "results.csv")
    assert [(r["point"], r["seed"]) for r in rows] == [(p, s) for p in "012" for s in "01"]
    assert [r["link.ber"] for r in rows[::2]] == ["0.0", "0.0001", "0.001"]
    assert all(r["status"] == "ok" and r["error"] == "" for r in rows)
    # a second method: the same (point, seed) run in this process, outside the sweep
    overrides = ["duration_s=8", "metrics.settle_s=1", "link.ber=0.001"]
    metrics = run_scenario(load_scenario("s100-teleop-v1", overrides), seed=1).metrics
    expected = flatten_metrics({k: v for k, v in metrics.items() if k not in EXCLUDED_METRICS})
    row = rows[5]
    assert not {"wall_s", "rtf", "scenario"} & set(row)  # wall-clock or constant: not in rows
    assert {k: row[k] for k in expected} == {
        k: ""
        if v is None
        else ("true" if v else "false")
        if isinstance(v, bool)
        else repr(v)
        if isinstance(v, float)
        else str(v)
        for k, v in expected.items()
    }
    assert float(rows[4]["link.uplink.per"]) > 0.0  # BER 1e-3 loses orders; BER 0 does not
    assert float(rows[0]["link.uplink.per"]) == 0.0
    aggregate = _rows(out / "aggregate.csv")
    assert [a["n_ok"] for a in aggregate] == ["2", "2", "2"]
    ages = [float(rows[i]["command_age_s.mean"]) for i in (4, 5)]
    assert float(aggregate[2]["command_age_s.mean.median"]) == pytest.approx(np.median(ages))


def test_dask_local_cluster_gives_identical_rows(
    pool_sweep: tuple[Path, Path], tmp_path: Path
) -> None:
    path, pool_out = pool_sweep
    out = tmp_path / "dask"
    argv = ["sweep", str(path), *SHORT, "--dask", "local", "--workers", "2", "--out", str(out)]
    assert main(argv) == 0
    assert (out / "results.csv").read_bytes() == (pool_out / "results.csv").read_bytes()
    assert (out / "aggregate.csv").read_bytes() == (pool_out / "aggregate.csv").read_bytes()


def test_existing_results_need_resume_and_the_same_sweep(
    pool_sweep: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path, pool_out = pool_sweep
    out = tmp_path / "copy"
    shutil.copytree(pool_out, out)
    assert main(["sweep", str(path), *SHORT, "--out", str(out)]) == 2
    assert "add --resume" in capsys.readouterr().err
    other = ["--set", "duration_s=9", "--set", "metrics.settle_s=1"]
    assert main(["sweep", str(path), *other, "--out", str(out), "--resume"]) == 2
    err = capsys.readouterr().err
    assert "holds a different sweep" in err and "duration_s: 8.0 → 9.0" in err
    assert main(["sweep", str(path), *SHORT, "--out", str(out), "--resume"]) == 0
    assert "0 ran now" in capsys.readouterr().out  # everything was done already


def test_a_torn_last_journal_line_is_cut_and_the_run_redone(
    pool_sweep: tuple[Path, Path], tmp_path: Path, inline_runs: None
) -> None:
    path, pool_out = pool_sweep
    out = tmp_path / "torn"
    shutil.copytree(pool_out, out)
    journal = out / "runs.jsonl"
    data = journal.read_bytes()
    last_start = data.rstrip(b"\n").rfind(b"\n") + 1
    journal.write_bytes(data[: last_start + 40])  # a kill in the middle of the last write
    (out / "results.csv").unlink()
    assert len(read_journal(journal)) == 5
    assert main(["sweep", str(path), *SHORT, "--workers", "1", "--out", str(out), "--resume"]) == 0
    lines = journal.read_bytes().splitlines()
    keys = [(json.loads(line)["point"], json.loads(line)["seed"]) for line in lines]
    assert sorted(keys) == [(p, s) for p in range(3) for s in range(2)]  # each exactly once
    assert (out / "results.csv").read_bytes() == (pool_out / "results.csv").read_bytes()


_RECORD = {"point": 0, "seed": 0, "link.ber": 0.0, "status": "ok", "error": ""}


@pytest.mark.parametrize(
    "line",
    [
        b"[1, 2]",
        b'"a string"',
        b"{}",
        json.dumps(_RECORD | {"point": 99}).encode(),  # no such point (3 points)
        json.dumps(_RECORD | {"seed": 7}).encode(),  # no such seed (seeds 0 and 1)
        json.dumps(_RECORD | {"point": -1}).encode(),
        json.dumps(_RECORD | {"point": "0"}).encode(),
        json.dumps(_RECORD | {"seed": True}).encode(),
        json.dumps(_RECORD | {"status": "maybe"}).encode(),
        json.dumps({k: v for k, v in _RECORD.items() if k != "error"}).encode(),
        b"\xff\xfe not UTF-8",
    ],
)
def test_a_damaged_journal_record_exits_2_naming_its_line(
    pool_sweep: tuple[Path, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    line: bytes,
) -> None:
    path, pool_out = pool_sweep
    out = tmp_path / "damaged"
    shutil.copytree(pool_out, out)
    journal = out / "runs.jsonl"
    data = journal.read_bytes()
    journal.write_bytes(data + line + b"\n")  # line 7, after the 6 runs
    assert main(["sweep", str(path), *SHORT, "--out", str(out), "--resume"]) == 2
    err = capsys.readouterr().err
    damaged = "line 7: damaged record (not written by testbed sweep)"
    assert err == f"testbed: error: {journal}: {damaged}\n"
    assert journal.read_bytes() == data + line + b"\n"  # left as it was


def test_a_journal_that_is_a_directory_exits_2_naming_it(
    pool_sweep: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path, pool_out = pool_sweep
    out = tmp_path / "dir"
    shutil.copytree(pool_out, out)
    (out / "runs.jsonl").unlink()
    (out / "runs.jsonl").mkdir()
    assert main(["sweep", str(path), *SHORT, "--out", str(out), "--resume"]) == 2
    err = capsys.readouterr().err
    assert err == f"testbed: error: {out / 'runs.jsonl'}: cannot read the journal: Is a directory\n"


def test_sigkill_mid_sweep_then_resume_finishes_every_run_once(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], inline_runs: None
) -> None:
    """A real pool sweep killed with its workers (SIGKILL to its process group) after its first
    run; the resume runs exactly the rest, and the tables equal an undisturbed sweep's."""
    path = _write_sweep(tmp_path, seeds=6)
    killed, fresh = tmp_path / "killed", tmp_path / "fresh"
    argv = [sys.executable, "-m", "testbed", "sweep", str(path), *SHORT, "--workers", "2"]
    process = subprocess.Popen(
        [*argv, "--out", str(killed)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # its own process group: the kill takes the workers too
    )
    assert process.stderr is not None
    line = process.stderr.readline()  # the first progress line: "ber-small-v1: k/18 runs ..."
    done = int(line.split(":")[1].split("/")[0])
    assert 1 <= done < 18, line
    os.killpg(process.pid, signal.SIGKILL)
    assert process.wait() == -signal.SIGKILL
    process.stderr.close()
    before = read_journal(killed / "runs.jsonl")
    assert 1 <= len(before) < 18
    assert main(["sweep", str(path), *SHORT, "--out", str(killed), "--resume"]) == 0
    assert f"{18 - len(before)} ran now" in capsys.readouterr().out
    keys = [(r["point"], r["seed"]) for r in read_journal(killed / "runs.jsonl")]
    assert sorted(keys) == [(p, s) for p in range(3) for s in range(6)]  # each exactly once
    assert main(["sweep", str(path), *SHORT, "--out", str(fresh)]) == 0
    assert (killed / "results.csv").read_bytes() == (fresh / "results.csv").read_bytes()
    assert (killed / "aggregate.csv").read_bytes() == (fresh / "aggregate.csv").read_bytes()


def test_a_failing_point_is_recorded_and_the_sweep_completes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Every bad value is refused at load now, so a run that raises is made here: the runner
    fails for BER > 0 and the runs execute in this process (the backends' worker function,
    :func:`execute_run`, unchanged)."""
    path = tmp_path / "fail.toml"
    path.write_text(
        'schema = 1\nid = "fail-v1"\ndescription = "d"\nscenario = "s100-teleop-v1"\n'
        'metrics = ["link.uplink.per"]\nseeds = [0, 1]\n[grid]\n"link.ber" = [0.0, 1e-3]\n',
        encoding="utf-8",
    )
    real = run_scenario

    def flaky(scenario: Any, *, seed: int | None = None) -> Any:
        if scenario.link.channel.ber > 0.0:
            raise ValueError("stuck force must be within\n[-1, 1] N")
        return real(scenario, seed=seed)

    monkeypatch.setattr("testbed.run.runner.run_scenario", flaky)
    monkeypatch.setattr(
        "testbed.sweep.runner.outcomes",
        lambda specs, *_: (execute_run(spec) for spec in specs),
    )
    out = tmp_path / "out"
    assert main(["sweep", str(path), *SHORT, "--out", str(out)]) == 1
    rows = _rows(out / "results.csv")
    assert [r["status"] for r in rows] == ["ok", "ok", "failed", "failed"]
    failed = rows[2]
    # one line, naming where the failure was raised in code not the testbed's (this test's)
    where = f"(at {Path(__file__).resolve()}:{flaky.__code__.co_firstlineno + 2})"
    assert failed["error"] == f"ValueError: stuck force must be within [-1, 1] N {where}"
    assert failed["link.uplink.per"] == ""  # no metrics for a failed run, and no partial row
    stdout = capsys.readouterr().out
    assert "4 runs, 2 failed" in stdout
    assert stdout.count("FAILED point") == 2 and "FAILED point 1 seed 1" in stdout
    aggregate = _rows(out / "aggregate.csv")
    assert [(a["n_ok"], a["n_failed"]) for a in aggregate] == [("2", "0"), ("0", "2")]


def test_seeds_option_runs_the_first_seeds_and_resume_adds_the_rest(
    pool_sweep: tuple[Path, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    inline_runs: None,
) -> None:
    """--seeds 1 runs seed 0 at every point: the very rows the full (pool) sweep holds for
    seed 0 (a second run of the same runs, here in this process); --resume without --seeds adds
    seed 1 (3 runs), and the tables then equal the full sweep's."""
    path, pool_out = pool_sweep
    out = tmp_path / "one"
    assert main(["sweep", str(path), *SHORT, "--seeds", "1", "--out", str(out)]) == 0
    rows = _rows(out / "results.csv")
    assert [(r["point"], r["seed"]) for r in rows] == [("0", "0"), ("1", "0"), ("2", "0")]
    full = [r for r in _rows(pool_out / "results.csv") if r["seed"] == "0"]
    assert rows == full
    capsys.readouterr()
    assert main(["sweep", str(path), *SHORT, "--seeds", "1", "--out", str(out), "--resume"]) == 0
    assert "0 ran now" in capsys.readouterr().out
    assert main(["sweep", str(path), *SHORT, "--out", str(out), "--resume"]) == 0
    assert "3 ran now" in capsys.readouterr().out
    for table in ("results.csv", "aggregate.csv"):
        assert (out / table).read_bytes() == (pool_out / table).read_bytes()
    assert main(["sweep", str(path), *SHORT, "--seeds", "1", "--out", str(out), "--resume"]) == 2
    assert "seeds: 1 removed" in capsys.readouterr().err  # shrinking is not resuming
    for bad in ("0", "3"):
        assert main(["sweep", str(path), *SHORT, "--seeds", bad, "--out", str(tmp_path / bad)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "--seeds: must be in 1..2" in err
