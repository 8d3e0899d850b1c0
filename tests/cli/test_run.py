"""`testbed run` and `testbed scenarios`: outputs on success, one line and exit 2 on bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from testbed.cli.main import main


def test_run_writes_metrics_events_and_series(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "run"
    code = main(
        [
            "run",
            "s100-teleop-v1",
            "--set",
            "duration_s=15",
            "--seed",
            "3",
            "--out",
            str(out),
            "--no-plots",
        ]
    )
    assert code == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["scenario"] == "s100-teleop-v1" and metrics["seed"] == 3
    assert metrics["sim_s"] == 15.0
    for key in (
        "link",
        "ipg_s",
        "command_lag_s",
        "command_age_s",
        "signal_lag_s",
        "odometry_age_s",
    ):
        assert key in metrics
    for key in ("velocity_tracking_rmse", "attitude_error_deg", "energy_wh"):
        assert key in metrics
    assert (out / "events.csv").read_text().startswith("t_s,source,kind")
    assert (out / "series.csv").read_text().startswith("t_s,cmd_x")
    assert f"wrote {out}" in capsys.readouterr().out


def test_scenarios_lists_the_default(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["scenarios"]) == 0
    assert "s100-teleop-v1" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["run", "{tmp}/missing.toml"], "missing.toml: file not found"),
        (["run", "{tmp}/bad.toml"], "bad.toml: malformed TOML"),
        (["run", "{tmp}/unknown.toml"], "unknown.toml: wobble: unknown key"),
        (["run", "s100-teleop-v1", "--set", "link.ber=lots"], "--set: link.ber: expected a number"),
        (["run", "s100-teleop-v1", "--set", "link.ber=2"], "--set: link.ber: must be in [0, 1]"),
        (["run", "s100-teleop-v1", "--set", "noequals"], "expected KEY=VALUE"),
        (["run", "no-such-scenario-v1"], "unknown scenario id"),
        (["run", "s100-teleop-v1", "--seed", "-1"], "--seed: must be ≥ 0"),
    ],
)
def test_bad_input_exits_2_with_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], fragment: str
) -> None:
    (tmp_path / "bad.toml").write_text("schema = 1\nid = [\n", encoding="utf-8")
    good = (Path(__file__).parents[2] / "testbed" / "scenarios" / "s100-teleop-v1.toml").read_text()
    (tmp_path / "unknown.toml").write_text("wobble = 1\n" + good, encoding="utf-8")
    argv = [a.replace("{tmp}", str(tmp_path)) for a in args]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert fragment in err
    assert err.count("\n") == 1 and "Traceback" not in err


def test_an_interrupt_before_anything_is_written_leaves_no_directory(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Ctrl-C while the nodes are built: the --out made for the run (and its new parents) is
    removed again; one given that already existed is kept, as it was."""
    import testbed.run.runner as runner

    def interrupted(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(runner, "run_scenario", interrupted)
    made = tmp_path / "new" / "out"
    assert main(["run", "--out", str(made), "--no-plots"]) == 130
    assert capsys.readouterr().err == "testbed: interrupted\n"
    assert not (tmp_path / "new").exists()
    given = tmp_path / "given"
    given.mkdir()
    assert main(["run", "--out", str(given), "--no-plots"]) == 130
    assert given.is_dir() and not any(given.iterdir())


def test_a_full_disk_is_one_line_naming_the_file_and_exit_1(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The disk fills while the results are written (ENOSPC from the series writer, as a full
    filesystem gives it): one line naming the file, exit 1, no traceback."""
    import errno

    from testbed.run.recorder import Recorder

    def full(self: Recorder, path: Path) -> None:
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    monkeypatch.setattr(Recorder, "write_series_csv", full)
    out = tmp_path / "run"
    code = main(["run", "--set", "duration_s=12", "--out", str(out), "--no-plots"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1
    assert len(err) == 1 and err[0].startswith("testbed: cannot write "), err
    assert err[0].endswith(f"{out / 'series.csv'}: No space left on device"), err
    assert not (out / "metrics.json").exists()  # no finished result claimed


def test_the_summary_shows_n_a_where_metrics_json_has_null(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Nothing gets through (BER 0.5): no PER to speak of on the silent side and no command
    age; the summary says n/a, as metrics.json says null (it printed 'PER nan %' and
    'inf ms')."""
    out = tmp_path / "run"
    argv = ["run", "--set", "link.ber=0.5", "--set", "duration_s=20", "--out", str(out)]
    assert main([*argv, "--no-plots"]) == 0
    text = capsys.readouterr().out
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["link"]["downlink"]["per"] is None
    assert metrics["command_age_s"]["mean"] is None
    assert "downlink 0/0 frames, PER n/a," in text and "command age mean n/a;" in text
    assert "nan" not in text and "inf" not in text


def test_the_summary_gives_the_depth_error_as_the_trial_lines_do(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A depth law is compared by its depth error: the run's summary gives metrics.json's
    depth_error_m mean in mm (only the trials' lines had it), n/a where no depth hold flew."""
    argv = ["run", "--set", "duration_s=15", "--no-plots", "--out"]
    assert main([*argv, str(tmp_path / "held")]) == 0
    depth = json.loads((tmp_path / "held" / "metrics.json").read_text())["depth_error_m"]
    assert f"; depth error mean {1000 * depth['mean']:.0f} mm; energy " in capsys.readouterr().out
    assert main([*argv, str(tmp_path / "manual"), "--set", "operator.mode=manual"]) == 0
    manual = json.loads((tmp_path / "manual" / "metrics.json").read_text())["depth_error_m"]
    assert manual["mean"] is None
    assert "; depth error mean n/a; energy " in capsys.readouterr().out


def test_a_mission_that_never_started_says_why(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """USBL alone (σ 0.5 m, 0.5 Hz) never gets the position σ to ready_sigma_m (0.5 m): the
    tree never ticks, the vehicle drifts, and the run said nothing (every figure n/a, exit 0).
    metrics.json now has ready_s null beside ready_sigma_m and the summary says why; with
    motion capture ready_s is the first tick's time."""
    usbl = "vehicle.navigation={acoustic={rate_hz=0.5, noise_m=0.5, delay_s=0.75}}"
    common = ["run", "heavy-waypoint-v1", "--set", "trials=1", "--set", "duration_s=20"]
    out = tmp_path / "usbl"
    assert main([*common, "--set", usbl, "--no-plots", "--out", str(out)]) == 0
    mission = json.loads((out / "metrics.json").read_text())["mission"]
    assert mission["ready_s"] is None and mission["ready_sigma_m"] == 0.5
    summary = capsys.readouterr().out
    assert "mission never started: navigation not ready (position σ > ready_sigma_m = 0.5 m" in (
        summary
    )
    # no mission status at all: one n/a for the goals (it printed "goals reached n/a/n/a")
    assert mission["goals"] is None and mission["goals_reached"] is None
    assert "; goals reached n/a; estimate error mean" in summary and "n/a/n/a" not in summary
    mocap = tmp_path / "mocap"
    assert main([*common, "--no-plots", "--out", str(mocap)]) == 0
    mission = json.loads((mocap / "metrics.json").read_text())["mission"]
    assert 0.0 <= mission["ready_s"] <= 0.1  # motion capture: ready at once
    summary = capsys.readouterr().out
    assert "never started" not in summary
    assert f"; goals reached {mission['goals_reached']}/{mission['goals']}; " in summary


def test_a_gap_shorter_than_the_round_trip_is_warned_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """68-B chunks on the S100 need 0.596 s a cycle, the 2021 rule gives 0.594 s: the run goes
    on (the overlap may be what is studied) after one warning line naming the fix."""
    argv = ["run", "s100-video-v1", "--set", "duration_s=15", "--set", "images.changes=[]"]
    argv += ["--no-plots", "--out", str(tmp_path / "r")]
    assert main([*argv, "--set", "images.chunk_bytes=68"]) == 0
    warnings = [line for line in capsys.readouterr().err.splitlines() if line]
    assert len(warnings) == 1 and warnings[0].startswith("testbed: warning: link: ")
    assert "0.596 s" in warnings[0] and "link.ipg_s ≥ 0.596" in warnings[0]
    assert main([*argv[:-1], str(tmp_path / "ok"), "--set", "images.chunk_bytes=67"]) == 0
    assert capsys.readouterr().err == ""


def test_the_summary_says_how_many_frames_in_the_per_collided(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The acoustic s2c preset under the 2021 gap: the replies collide with the next orders,
    and the downlink line says so beside the PER (it read "PER 100.00 %" as if bit errors),
    and that the operator lost them while it transmitted (two nodes: no other cause)."""
    out = tmp_path / "r"
    argv = ["run", "s100-teleop-v1", "--set", "link.preset=s2c", "--set", "duration_s=20"]
    assert main([*argv, "--set", "metrics.settle_s=5", "--no-plots", "--out", str(out)]) == 0
    down = json.loads((out / "metrics.json").read_text())["link"]["downlink"]
    assert down["frames_collided"] > 0
    line = next(li for li in capsys.readouterr().out.splitlines() if "downlink" in li)
    deaf = down["copies_lost_transmitting"]
    assert deaf == down["frames_collided"]  # one copy a frame at the one receiver
    assert f"(collided {deaf}: {deaf} copies lost while the receiver transmitted)" in line


def test_a_capsized_vehicle_is_said_in_the_summary(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A BlueROV2 whose CoG is 2 cm above its CoB (its own model file) has a negative
    metacentric height: flown without an attitude hold it turns over. The run says so in one
    warning line, and ``max_tilt_deg`` holds the largest |roll| and |pitch| of series.csv and
    the first time past 90°; the standard vehicle (CoG below the CoB) gets no such line."""
    from importlib import resources

    model = resources.files("testbed.vehicle").joinpath("data/models/bluerov2.toml").read_text()
    top = model.replace("cog_m = [0.0, 0.0, 0.02]", "cog_m = [0.0, 0.0, -0.02]")
    assert top != model
    (tmp_path / "top.toml").write_text(top)
    argv = ["run", "s100-teleop-v1", "--set", "duration_s=30", "--set", "operator.mode=manual"]
    out = tmp_path / "top"
    model_path = str(tmp_path / "top.toml")
    assert (
        main([*argv, "--set", f"vehicle.model={model_path}", "--no-plots", "--out", str(out)]) == 0
    )
    tilt = json.loads((out / "metrics.json").read_text())["max_tilt_deg"]
    series = np.genfromtxt(out / "series.csv", delimiter=",", names=True)
    over = series["t_s"][(np.abs(series["roll_deg"]) > 90) | (np.abs(series["pitch_deg"]) > 90)]
    assert over.size and tilt["capsized_s"] == pytest.approx(over[0])
    assert tilt["roll"] == pytest.approx(np.abs(series["roll_deg"]).max(), abs=1e-3)  # 3 places
    lines = capsys.readouterr().out.splitlines()
    assert f"  warning: the vehicle capsized at t = {over[0]:.1f} s" in "\n".join(lines)
    assert main([*argv, "--no-plots", "--out", str(tmp_path / "std")]) == 0
    standard = json.loads((tmp_path / "std" / "metrics.json").read_text())["max_tilt_deg"]
    assert standard["capsized_s"] is None and standard["roll"] < 90.0
    assert "warning" not in capsys.readouterr().out


def test_results_are_not_written_through_a_planted_link(tmp_path: Path) -> None:
    """A link planted at the old fixed temporary name (``.tmp-events.csv``) in a results folder
    another user can write: the run writes its own new temporary files, the link's target is
    untouched, and the results are regular files with the usual mode (0666 less the umask)."""
    import os
    import stat

    out, victim = tmp_path / "out", tmp_path / "victim.txt"
    out.mkdir()
    victim.write_text("keep me")
    for name in ("events.csv", "series.csv", "metrics.json"):
        (out / f".tmp-{name}").symlink_to(victim)
    argv = ["run", "s100-teleop-v1", "--set", "duration_s=12", "--no-plots", "--force"]
    assert main([*argv, "--out", str(out)]) == 0
    assert victim.read_text() == "keep me"
    mask = os.umask(0)
    os.umask(mask)
    for name in ("events.csv", "series.csv", "metrics.json"):
        info = (out / name).lstat()
        assert stat.S_ISREG(info.st_mode) and stat.S_IMODE(info.st_mode) == 0o666 & ~mask


def test_an_end_effector_mission_on_a_vehicle_without_an_arm_is_refused(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """ee_waypoint's points are the jaws'; heavy-waypoint-v1 has no arm. It flew the hull to
    them, exit 0, "goals reached 1/1" (an operator's end-effector goal was refused already)."""
    argv = ["run", "heavy-waypoint-v1", "--set", "trials=1", "--out", str(tmp_path / "r")]
    assert main([*argv, "--set", "vehicle.autonomy.mission=ee_waypoint"]) == 2
    assert capsys.readouterr().err == (
        "testbed: error: --set: vehicle.autonomy.mission: missions/ee_waypoint.json: child "
        "'alpha_standard_jaws_tool' is the arm's end effector, and the vehicle has no arm "
        "(vehicle.arm); for the hull's own waypoints use child 'base_link'\n"
    )
    assert not (tmp_path / "r").exists()


def test_a_mission_after_or_beyond_the_run_is_said_not_settled(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """A start after the run's end is refused; goals after it are warned of (a shortened
    run may mean it); a run that ends mid-trajectory has no final target, where the summary
    said "settled 0.00 s after the final target (at 14.9 s)" while the target still moved."""
    common = ["run", "heavy-station-keeping-v1", "--set", "trials=1", "--no-plots"]
    late = ["--set", "duration_s=20", "--set", "vehicle.autonomy.start_s=1000"]
    assert main([*common, *late, "--out", str(tmp_path / "late")]) == 2
    assert "vehicle.autonomy.start_s: must be < duration_s (20.0), got 1000.0" in (
        capsys.readouterr().err
    )
    short = ["--set", "duration_s=15", "--set", "vehicle.autonomy.mission=square"]
    assert main([*common, *short, "--out", str(tmp_path / "short")]) == 0
    mission = json.loads((tmp_path / "short" / "metrics.json").read_text())["mission"]
    assert mission["final_target_s"] is None and mission["time_to_converge_s"] is None
    assert "no final target: it still moved at the last armed row" in capsys.readouterr().out
    supervised = ["run", "s100-supervised-v1", "--set", "duration_s=30", "--no-plots"]
    assert main([*supervised, "--out", str(tmp_path / "goals")]) == 0
    err = capsys.readouterr().err
    assert err == (
        "testbed: warning: pilot.goals[2]…[5] at t ≥ 45 s come after the run's end (30 s): "
        "not sent\n"
    )


def test_a_link_failsafe_that_surfaced_and_disarmed_the_vehicle_is_said(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """At BER 0.1 no S100 frame gets through: the failsafe holds after 1 s and surfaces after
    5 s, which disarms the vehicle; the summary said nothing of it."""
    out = tmp_path / "r"
    argv = ["run", "s100-supervised-v1", "--set", "duration_s=40", "--set", "link.ber=0.1"]
    assert main([*argv, "--no-plots", "--out", str(out)]) == 0
    events = json.loads((out / "metrics.json").read_text())["events"]
    assert (events["failsafe"], events["failsafe_surfaced"]) == (1, 1)
    assert "  link failsafe engaged 1 time, surfaced 1 (then disarmed; events.csv has when)\n" in (
        capsys.readouterr().out
    )
