"""Repeated trials: a short station-keeping scenario run three times — trial directories, the
trials.json rows and their mean ± std, determinism, an interrupted trial, the trials figure —
and the CLI's one line for a bad ``trials`` value."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from testbed.cli.main import main
from testbed.run import trials as trials_module
from testbed.run.outputs import prepare_out_dir
from testbed.run.runner import RunResult, run_scenario
from testbed.run.scenario import load_scenario
from testbed.run.scenario_config import Scenario
from testbed.run.trials import HEADLINE, TRIALS_FILE, WALL_CLOCK_KEYS, run_trials

SCENARIO = """\
schema = 1
id = "station-trials-v1"
description = "station keeping on motion capture, past the mission's 10-s leg"
duration_s = 11.0
seed = 7
trials = {trials}

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


def write_scenario(tmp_path: Path, trials: int) -> Path:
    path = tmp_path / f"station-trials-{trials}.toml"
    path.write_text(SCENARIO.format(trials=trials), encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def scenario(tmp_path_factory: pytest.TempPathFactory) -> Scenario:
    return load_scenario(str(write_scenario(tmp_path_factory.mktemp("scenario"), 3)))


def without_wall_clock(document: dict[str, Any]) -> dict[str, Any]:
    doc = json.loads(json.dumps(document))
    for row in doc["trials"]:
        for key in WALL_CLOCK_KEYS:
            row.pop(key)
    for key in WALL_CLOCK_KEYS:
        doc["across_trials"].pop(key)
    return doc


def test_trials_write_each_run_and_the_mean_over_them(scenario: Scenario, tmp_path: Path) -> None:
    out = tmp_path / "out"
    prepare_out_dir(out)
    result = run_trials(scenario, out)
    assert result.stopped is None
    for k in (1, 2, 3):
        metrics = json.loads((out / f"trial-{k}" / "metrics.json").read_text())
        assert metrics["complete"] is True and metrics["seed"] == 6 + k
        assert {"events.csv", "series.csv"} <= set(metrics["files"])
        assert metrics["mission"]["samples"] > 0
    doc = json.loads((out / TRIALS_FILE).read_text())
    assert doc["complete"] is True and doc["trials_finished"] == 3
    assert [row["seed"] for row in doc["trials"]] == [7, 8, 9]
    assert [row["dir"] for row in doc["trials"]] == ["trial-1", "trial-2", "trial-3"]
    for name, _ in HEADLINE:
        values = [row[name] for row in doc["trials"]]
        # none under autonomy (the ISMC flies: no attitude or depth hold)
        if name in ("yaw_error_std_deg", "depth_error_mean_m") or name.startswith("image"):
            assert values == [None] * 3 and doc["across_trials"][name]["n"] == 0
            continue
        assert all(v is not None for v in values), name
        across = doc["across_trials"][name]
        assert across["mean"] == pytest.approx(float(np.mean(values)), rel=1e-12, abs=1e-15)
        assert across["std"] == pytest.approx(float(np.std(values, ddof=1)), rel=1e-9, abs=1e-15)
        assert across["n"] == 3
    # headline figures are those of each trial's metrics.json
    first = json.loads((out / "trial-1" / "metrics.json").read_text())
    row = doc["trials"][0]
    assert row["position_error_final_m"] == first["mission"]["position_error_m"]["final"]
    assert row["command_lag_mean_s"] == first["command_lag_s"]["mean"]

    again = tmp_path / "again"
    prepare_out_dir(again)
    run_trials(scenario, again)
    assert without_wall_clock(json.loads((again / TRIALS_FILE).read_text())) == without_wall_clock(
        doc
    )
    other = tmp_path / "other"
    prepare_out_dir(other)
    shifted = run_trials(scenario, other, seed=8)
    assert [row["seed"] for row in shifted.document["trials"]] == [8, 9, 10]
    same_seed = shifted.document["trials"][0]["position_error_mean_m"]
    assert same_seed == doc["trials"][1]["position_error_mean_m"]  # seed 8 either way


def test_interrupted_trial_keeps_the_finished_ones(
    scenario: Scenario, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def interrupted_second(scenario: Scenario, *, seed: int | None = None) -> RunResult:
        result = run_scenario(scenario, seed=seed)
        return dataclasses.replace(result, stopped=KeyboardInterrupt()) if seed == 8 else result

    monkeypatch.setattr(trials_module, "run_scenario", interrupted_second)
    out = tmp_path / "out"
    prepare_out_dir(out)
    result = run_trials(scenario, out)
    assert isinstance(result.stopped, KeyboardInterrupt)
    assert json.loads((out / "trial-1" / "metrics.json").read_text())["complete"] is True
    assert json.loads((out / "trial-2" / "metrics.json").read_text())["complete"] is False
    assert not (out / "trial-3").exists()
    doc = json.loads((out / TRIALS_FILE).read_text())
    assert doc["complete"] is False and doc["interrupted_trial"] == 2
    assert [row["seed"] for row in doc["trials"]] == [7]
    assert doc["across_trials"]["rtf"]["std"] is None  # one trial: no spread (NaN → null)


def test_cli_interrupted_trials_say_one_line_and_exit_130(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    def interrupted_first(scenario: Scenario, *, seed: int | None = None) -> RunResult:
        raise KeyboardInterrupt

    monkeypatch.setattr(trials_module, "run_scenario", interrupted_first)
    out = tmp_path / "out"
    code = main(["run", str(write_scenario(tmp_path, 2)), "--out", str(out), "--no-plots"])
    assert code == 130
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("testbed: interrupted in trial 1 of 2")
    assert json.loads((out / TRIALS_FILE).read_text())["trials"] == []


def test_trials_figure_and_mission_plot(scenario: Scenario, tmp_path: Path) -> None:
    from testbed.report.mission_plots import plot_mission, plot_trials

    short = dataclasses.replace(scenario, trials=2)
    out = tmp_path / "out"
    prepare_out_dir(out)
    result = run_trials(short, out, trials_plot=plot_trials)
    assert (out / "trials.png").read_bytes()[:4] == b"\x89PNG"
    assert out / "trials.png" in result.files
    track = result.tracks[0]
    path = plot_mission(
        track.series, tmp_path / "mission.png", title="t", waypoints_ned=[(0, 0, 1)]
    )
    assert path.read_bytes()[:4] == b"\x89PNG"


def test_run_without_autonomy_has_no_mission_key() -> None:
    plain = load_scenario(
        "s100-teleop-v1", ["duration_s=3", "pilot.start_s=1", "metrics.settle_s=1"]
    )
    metrics = run_scenario(plain).metrics
    assert "mission" not in metrics
    assert "command_lag_s" in metrics


@pytest.mark.parametrize("value", ["0", "101", "2.5", "true"])
def test_cli_bad_trials_is_one_line_naming_the_key(
    value: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(SCENARIO.replace("trials = {trials}", f"trials = {value}"), encoding="utf-8")
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bad.toml: trials:" in err[0], err


def test_cli_trials_print_a_line_per_trial_and_the_mean(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    code = main(["run", str(write_scenario(tmp_path, 2)), "--out", str(out), "--no-plots"])
    assert code == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("trial 1 seed 7: ") and lines[1].startswith("trial 2 seed 8: ")
    assert lines[2].startswith("2 trials (mean ± std over trials): position error mean ")
    assert (out / "trial-2" / "metrics.json").is_file() and (out / TRIALS_FILE).is_file()
    assert not (out / "trials.png").exists()


def _results(out: Path) -> set[str]:
    return {str(p.relative_to(out)) for p in out.rglob("*")}


def test_force_replaces_the_earlier_results_whatever_their_shape(tmp_path: Path) -> None:
    """--force into a directory that holds another run's results leaves only the new run's
    (a mixed set would be read as one): three trials → one trial → a single run → two trials.
    A file of the user's own in the directory is never touched."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine", encoding="utf-8")

    def run(trials: int) -> set[str]:
        # 2 s, not 11: which files a run or a trial writes follows from the scenario's
        # configuration (testbed.run.outputs.write_run), not from how long it flew
        scenario = str(write_scenario(tmp_path, trials))
        argv = ["run", scenario, "--out", str(out), "--no-plots", "--force"]
        code = main([*argv, "--set", "duration_s=2"])
        assert code == 0
        return _results(out)

    single = {"notes.txt", "metrics.json", "events.csv", "series.csv"}
    trial = {"metrics.json", "events.csv", "series.csv"}

    def trials_set(n: int) -> set[str]:
        dirs = {f"trial-{k}" for k in range(1, n + 1)}
        inside = {f"trial-{k}/{name}" for k in range(1, n + 1) for name in trial}
        return {"notes.txt", TRIALS_FILE} | dirs | inside

    assert run(3) == trials_set(3)
    assert run(2) == trials_set(2)
    assert run(1) == single
    assert run(2) == trials_set(2)
    assert (out / "notes.txt").read_text(encoding="utf-8") == "mine"


def test_the_estimate_is_drawn_from_when_navigation_was_ready() -> None:
    """Before its first fix the filter sits at (0, 0): rows before ``ready_s`` are left out of
    the drawn estimate (NaN), the rest kept as recorded; never ready: none; unknown: all."""
    from testbed.report.mission_plots import estimate_track

    series = {
        "t_s": np.array([0.0, 0.05, 0.1, 0.15]),
        "est_n": np.array([0.0, 0.0, -1.0, -1.01]),
        "est_e": np.array([0.0, 0.0, 1.0, 1.02]),
    }
    east, north = estimate_track(series, 0.1)
    assert np.isnan(east[:2]).all() and np.isnan(north[:2]).all()
    assert east[2:].tolist() == [1.0, 1.02] and north[2:].tolist() == [-1.0, -1.01]
    assert series["est_n"][0] == 0.0  # the series itself is left as recorded
    assert np.isnan(estimate_track(series, math.nan)[0]).all()
    assert estimate_track(series, None)[1].tolist() == series["est_n"].tolist()


def test_trials_of_a_teleoperated_scenario_summarise_its_command_figures(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Trials without autonomy summarise what a teleoperated run measures (command lag and
    age, yaw error, energy), each the mean and sample std of the trials' own metrics.json;
    no mission figure and no trials figure (it draws mission tracks) — it used to print
    n/a for every figure and draw an empty figure."""
    # Each trial's own run plots (state, speeds, …: ≈ 5 s of the test's 7) are not the subject;
    # without --no-plots the trials figure's drawer is still handed to run_trials, so its
    # absence below is the subject's doing, not the option's.
    monkeypatch.setattr("testbed.report.run_plots.write_run_plots", lambda result, out: [])
    out = tmp_path / "t"
    argv = ["run", "s100-teleop-v1", "--set", "trials=3", "--set", "duration_s=20"]
    assert main([*argv, "--out", str(out)]) == 0
    runs = [json.loads((out / f"trial-{k}/metrics.json").read_text()) for k in (1, 2, 3)]
    lags = np.array([m["command_lag_s"]["mean"] for m in runs])
    yaw = np.array([m["attitude_error_deg"]["yaw"]["std"] for m in runs])
    depth = np.array([m["depth_error_m"]["mean"] for m in runs])
    document = json.loads((out / TRIALS_FILE).read_text())
    across = document["across_trials"]
    assert document["mission"] is False
    assert across["command_lag_mean_s"]["mean"] == pytest.approx(lags.mean())
    assert across["yaw_error_std_deg"]["std"] == pytest.approx(yaw.std(ddof=1))
    assert not (out / "trials.png").exists()
    summary = capsys.readouterr().out.splitlines()[-2]
    assert "position error" not in summary and "n/a" not in summary
    assert (
        f"command lag mean {1000 * lags.mean():.0f} ± {1000 * lags.std(ddof=1):.0f} ms" in summary
    )
    assert f"depth error mean {1000 * depth.mean():.0f} ± {1000 * depth.std(ddof=1):.0f} mm" in (
        summary
    )


def test_image_trials_carry_the_image_figures(tmp_path: Path) -> None:
    """Trials of an image scenario: each trial's images per minute, latency and PSNR in
    trials.json, as its metrics.json has them (an images researcher's review: trials dropped
    every image figure)."""
    overrides = ["duration_s=40", "images.changes=[]", "trials=2"]
    scenario = load_scenario("s100-video-v1", overrides)
    out = tmp_path / "images"
    prepare_out_dir(out)
    run_trials(scenario, out)
    doc = json.loads((out / TRIALS_FILE).read_text())
    for k, row in enumerate(doc["trials"], start=1):
        images = json.loads((out / f"trial-{k}" / "metrics.json").read_text())["images"]
        assert row["images_per_minute"] == images["per_minute"] > 0
        assert row["image_latency_mean_s"] == images["latency_s"]["mean"]
        assert row["image_psnr_mean_db"] == images["psnr_db"]["mean"]
    assert doc["across_trials"]["images_per_minute"]["n"] == 2
