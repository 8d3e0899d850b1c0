"""``testbed sweep`` and ``testbed plot``: bad input is one line and exit 2, before any work."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import pytest

from testbed.cli.main import main
from testbed.sweep import expand, load_sweep
from testbed.sweep.spec import check_points

SHORT = ["--set", "duration_s=8", "--set", "metrics.settle_s=1"]
SWEEP = """\
schema = 1
id = "checks-v1"
description = "d"
scenario = "s100-teleop-v1"
metrics = {metrics}
[grid]
{grid}
"""


def _sweep(folder: Path, grid: str = '"link.ber" = [0.0, 1e-3]', metrics: str = "[]") -> Path:
    path = folder / "checks.toml"
    path.write_text(SWEEP.format(grid=grid, metrics=metrics), encoding="utf-8")
    return path


def _one_line(capsys: pytest.CaptureFixture[str], fragment: str) -> None:
    err = capsys.readouterr().err
    assert fragment in err and err.count("\n") == 1 and "Traceback" not in err, err


@pytest.mark.parametrize(
    ("argv", "fragment"),
    [
        (["--dask", "not-an-address"], "--dask: expected 'local' or a scheduler address"),
        (["--dask", "tcp://host"], "--dask: expected 'local'"),
        (["--dask", "tcp://localhost:99999"], "--dask: port must be in [1, 65535], got 99999"),
        (["--dask", "tcp://localhost:0"], "--dask: port must be in [1, 65535], got 0"),
        (["--resume"], "does not exist; drop --resume"),
    ],
)
def test_bad_options_exit_2_before_any_work(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], fragment: str
) -> None:
    out = tmp_path / "out"
    assert main(["sweep", str(_sweep(tmp_path)), *SHORT, *argv, "--out", str(out)]) == 2
    _one_line(capsys, fragment)
    assert not out.exists()


def test_an_unreachable_scheduler_is_one_line_and_leaves_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Refused before anything is written: a rerun without --dask is not "already holds a
    sweep". No run may start either (the dry run of the metric check is made first). The
    client is given 1 s to connect instead of the sweep's 10 s (nothing listens on port 9: it
    retries the refused connection until its timeout, then fails the same way)."""
    import distributed

    monkeypatch.setattr("testbed.sweep.runner.outcomes", lambda *args: pytest.fail("runs started"))
    client = distributed.Client
    monkeypatch.setattr(
        distributed, "Client", lambda address, timeout: client(address, timeout=min(timeout, 1))
    )
    argv = ["sweep", str(_sweep(tmp_path)), *SHORT, "--dask", "tcp://127.0.0.1:9"]
    assert main([*argv, "--out", str(tmp_path / "out")]) == 2
    _one_line(capsys, "--dask: cannot reach tcp://127.0.0.1:9")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("sweep_id", ["../../escaped-v1", "/tmp/abs-v1", "a/b-v1", "Big-v1", "x"])
def test_a_sweep_id_must_be_a_versioned_id(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    sweep_id: str,
) -> None:
    """The id names the default results folder, sweeps/<id>/: it may not leave it."""
    path = tmp_path / "s.toml"
    path.write_text(_sweep(tmp_path).read_text().replace('"checks-v1"', json.dumps(sweep_id)))
    monkeypatch.chdir(tmp_path)
    assert main(["sweep", str(path), *SHORT]) == 2
    err = capsys.readouterr().err
    expected = f"{path}: id: must match ^[a-z0-9-]+-v[0-9]+$ (e.g. 'ber-vs-lag-v1'), got "
    assert err == f"testbed: error: {expected}{sweep_id!r}\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["checks.toml", "s.toml"]


TEN_BER = "0.0, 1e-6, 1e-5, 1e-4, 2e-4, 5e-4, 1e-3, 2e-3, 5e-3, 1e-2"


@pytest.mark.parametrize(
    ("seeds", "grid", "fragment"),
    [
        ("10000000000", "[0.0, 1e-3]", "seeds: must be ≤ 10000, got 10000000000"),
        (repr(list(range(10001))), "[0.0, 1e-3]", "seeds: must hold ≤ 10000 seeds, got 10001"),
        (
            "10000",
            f"[{TEN_BER}, 2e-2]",
            "grid, seeds: 11 points × 10000 seeds = 110000 runs, more than the 100000 a sweep "
            "may hold",
        ),
    ],
)
def test_sizes_over_the_limits_exit_2_before_anything_is_built(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    seeds: str,
    grid: str,
    fragment: str,
) -> None:
    """Refused before the seed list is built (10^10 seeds: a MemoryError) and before the
    points are checked (110,000 points: ≈ 15 min)."""
    monkeypatch.setattr("testbed.sweep.spec.check_points", lambda *a: pytest.fail("checked"))
    path = _sweep(tmp_path, f'"link.ber" = {grid}', metrics=f"[]\nseeds = {seeds}")
    assert main(["sweep", str(path), *SHORT, "--out", str(tmp_path / "out")]) == 2
    _one_line(capsys, f"{path}: {fragment}")
    assert not (tmp_path / "out").exists()


def test_the_run_limit_is_inclusive(tmp_path: Path) -> None:
    path = _sweep(tmp_path, f'"link.ber" = [{TEN_BER}]', metrics="[]\nseeds = 10000")
    assert len(expand(load_sweep(str(path), SHORT[1::2]))) == 100_000  # 10 points × 10,000


@pytest.mark.parametrize("override", ["link.ber=0.5", "link={ber = 0.5}"])
def test_set_of_a_swept_key_exits_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], override: str
) -> None:
    """The grid point's value comes after --set: the --set would be silently lost."""
    argv = ["sweep", str(_sweep(tmp_path)), *SHORT, "--set", override]
    assert main([*argv, "--out", str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err == "testbed: error: --set: link.ber: also swept in [grid]\n"
    assert not (tmp_path / "out").exists()


def test_resume_of_a_folder_without_a_sweep_exits_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "empty").mkdir()
    argv = ["sweep", str(_sweep(tmp_path)), *SHORT, "--out", str(tmp_path / "empty"), "--resume"]
    assert main(argv) == 2
    _one_line(capsys, "holds no sweep")


def test_out_must_be_creatable_and_writable(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _sweep(tmp_path)
    afile = tmp_path / "afile"
    afile.write_text("x")
    assert main(["sweep", str(path), *SHORT, "--out", str(afile)]) == 2
    _one_line(capsys, "exists and is not a directory")
    assert main(["sweep", str(path), *SHORT, "--out", str(afile / "sub" / "out")]) == 2
    _one_line(capsys, "is a file")
    if os.geteuid() != 0:  # root writes anywhere
        locked = tmp_path / "locked"
        locked.mkdir(mode=0o500)
        assert main(["sweep", str(path), *SHORT, "--out", str(locked / "out")]) == 2
        _one_line(capsys, "is not writable")


def test_an_unknown_metric_fails_before_the_first_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _sweep(tmp_path, metrics='["command_age_s.mean", "no.such.metric"]')
    out = tmp_path / "out"
    assert main(["sweep", str(path), *SHORT, "--workers", "1", "--out", str(out)]) == 2
    _one_line(capsys, "metrics: unknown metric 'no.such.metric' (known: ")
    assert not (out / "runs.jsonl").exists()  # no run was made


def test_a_grid_point_bad_only_in_combination_fails_before_the_first_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # every value loads on its own; link.ipg_s with link.ipg = telerobotics-2018 does not
    grid = '"link.ipg" = ["fixed", "telerobotics-2018"]\n"link.ipg_s" = [0.6, 1.2]'
    out = tmp_path / "out"
    assert main(["sweep", str(_sweep(tmp_path, grid)), *SHORT, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert 'grid point link.ipg="telerobotics-2018", link.ipg_s=0.6:' in err, err
    assert "link.ipg_s: only used when link.ipg = 'fixed'" in err and err.count("\n") == 1
    assert not out.exists()


def test_a_bad_value_of_a_large_grid_is_named_at_once(tmp_path: Path) -> None:
    """A 100,000-point grid (the most a sweep may hold) whose last value of the first axis is
    bad: found by the one-value pass (≈ 700 loads), not after the whole product."""
    ber = ", ".join(repr(i * 1e-6) for i in range(199)) + ", 2.0"
    gaps = ", ".join(repr(0.5 + i * 0.001) for i in range(500))
    path = _sweep(tmp_path, f'"link.ber" = [{ber}]\n"link.ipg_s" = [{gaps}]')
    start = time.process_time()
    match = r"grid point link.ber=2.0, link.ipg_s=0.5: link.ber: must be in"
    with pytest.raises(Exception, match=match):
        load_sweep(str(path), ['link.ipg="fixed"'])
    per_load = (time.process_time() - start) / 700
    assert per_load > 0.0


def test_checking_prints_progress_and_loads_each_point_once(tmp_path: Path) -> None:
    import io

    path = _sweep(tmp_path, '"link.ber" = [0.0, 1e-4, 1e-3]\n"link.ipg_s" = [0.6, 1.2]')
    sweep = load_sweep(str(path), ['link.ipg="fixed"'])
    stream = io.StringIO()
    check_points(sweep, stream)  # 6 points, checked in well under the 1-s progress interval
    assert stream.getvalue() == ""


# --- testbed plot ----------------------------------------------------------------------------


def _results(folder: Path) -> Path:
    path = folder / "results.csv"
    path.write_text(
        "point,seed,link.ber,status,error,m\n0,0,0.0,ok,,1.0\n1,0,0.001,ok,,2.0\n",
        encoding="utf-8",
    )
    return path


@pytest.mark.parametrize(
    ("content", "fragment"),
    [
        (b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\xff\xfe", "binary, not UTF-8"),
        (b"point,seed,status\x00,error\n", "not a results.csv"),
        (b"hello,world\n1,2\n", "not a results.csv"),
    ],
)
def test_plot_of_a_binary_or_garbled_file_exits_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], content: bytes, fragment: str
) -> None:
    path = tmp_path / "results.csv"
    path.write_bytes(content)
    assert main(["plot", str(path), "--x", "link.ber", "--y", "m"]) == 2
    _one_line(capsys, fragment)


def test_plot_of_rows_longer_than_the_head_exits_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "results.csv"
    path.write_text("point,seed,status,error,m\n0,0,ok,,1.0,9,9\n", encoding="utf-8")
    assert main(["plot", str(path), "--x", "seed", "--y", "m"]) == 2
    _one_line(capsys, "more cells than the head")


@pytest.mark.parametrize(
    ("out", "fragment"),
    [
        ("p.xyz", "unsupported extension '.xyz'"),
        ("afile/p.png", "exists and is not a directory"),
        ("adir", "is a directory"),
    ],
)
def test_plot_bad_out_exits_2_before_reading(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], out: str, fragment: str
) -> None:
    (tmp_path / "afile").write_text("x")
    (tmp_path / "adir.png").mkdir()
    target = tmp_path / out
    argv = ["plot", str(tmp_path / "missing.csv"), "--x", "link.ber", "--y", "m"]
    assert main([*argv, "--out", str(target)]) == 2  # --out is checked first
    _one_line(capsys, fragment)


def test_plot_without_an_extension_prints_the_png_it_wrote(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _results(tmp_path)
    argv = ["plot", str(path), "--x", "link.ber", "--y", "m", "--out", str(tmp_path / "noext")]
    assert main(argv) == 0
    printed = capsys.readouterr().out.strip()
    assert printed == str(tmp_path / "noext.png")
    assert Path(printed).read_bytes().startswith(b"\x89PNG")
    assert not (tmp_path / "noext").exists()


@pytest.mark.parametrize(
    ("scenario", "fixed", "grid", "message"),
    [
        (
            "s100-teleop-v1",
            '"link.bogus" = 1',
            '"link.ber" = [0.0]',
            "{path}: [set]: link.bogus: unknown key (known: ",
        ),
        (
            "no-such-scenario-v1",
            "",
            '"link.ber" = [0.0]',
            "{path}: scenario: unknown scenario id 'no-such-scenario-v1' (known: ",
        ),
        (
            "missing.toml",
            "",
            '"link.ber" = [0.0]',
            "{path}: scenario: {folder}/missing.toml: file not found",
        ),
        (
            "s100-teleop-v1",
            "",
            '"link.bitrate_bps" = { start = 1000, stop = 2000, num = 3 }',
            "{path}: grid.link.bitrate_bps.scale: required key missing",
        ),
        (
            "s100-teleop-v1",
            "",
            '"link.bitrate_bps" = { scale = "linear", start = 1000, '
            "stop = 1000.0000000001, num = 3 }",
            "{path}: grid.link.bitrate_bps.num: 3 values from 1000.0 to 1000.0000000001 are only 1 "
            "distinct ones at 12 significant digits",
        ),
        (
            "s100-teleop-v1",
            "",
            '"link.ber" = { scale = "log", start = 1e-5, stop = 1e-3, num = 3, include = [1e-4] }',
            "{path}: grid.link.ber.include: 0.0001 is already in the range or repeated",
        ),
    ],
)
def test_errors_of_the_sweep_file_name_it_and_the_key(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    scenario: str,
    fixed: str,
    grid: str,
    message: str,
) -> None:
    """Not "--set" (none was given): the file, and the key in it."""
    path = tmp_path / "s.toml"
    path.write_text(
        f'schema = 1\nid = "s-v1"\ndescription = "d"\nscenario = "{scenario}"\n'
        f"[set]\nduration_s = 8.0\n{fixed}\n[grid]\n{grid}\n",
        encoding="utf-8",
    )
    assert main(["sweep", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    expected = "testbed: error: " + message.format(path=path, folder=tmp_path)
    assert err.startswith(expected) and err.count("\n") == 1, err
    assert not (tmp_path / "out").exists()


def test_user_files_in_set_and_grid_are_taken_from_the_sweep_files_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # A study kept in one folder (a sweep over layout files of its own, a model in [set]) ran
    # only from that folder: [set] and [grid] paths were the working directory's, unlike the
    # sweep's scenario and paths in scenario files.
    study = tmp_path / "study"
    study.mkdir()
    data = Path(__file__).parents[2] / "testbed" / "vehicle" / "data"
    (study / "my-layout.toml").write_text((data / "thrusters" / "bluerov2.toml").read_text())
    (study / "my-model.toml").write_text((data / "models" / "bluerov2.toml").read_text())
    (study / "s.toml").write_text(
        'schema = 1\nid = "study-v1"\ndescription = "d"\nscenario = "s100-teleop-v1"\n'
        '[set]\n"vehicle.model" = "my-model.toml"\n'
        '[grid]\n"vehicle.thrusters" = ["my-layout.toml", "bluerov2"]\n'
    )
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    sweep = load_sweep("../study/s.toml")
    layout, model = str(study.resolve() / "my-layout.toml"), str(study.resolve() / "my-model.toml")
    assert sweep.axes == (("vehicle.thrusters", (layout, "bluerov2")),)
    assert f'vehicle.model="{model}"' in sweep.overrides
    assert {name for name, _ in sweep.inputs} == {"package:s100-teleop-v1", layout, model}
    assert [spec.overrides[-1] for spec in expand(sweep)] == [
        f'vehicle.thrusters="{layout}"',
        'vehicle.thrusters="bluerov2"',
    ]
