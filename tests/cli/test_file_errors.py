"""Bad names and paths of data files, options misnamed in errors, waypoints beyond the world:
one line naming the option or the source (a scenario file or ``--set``) and the key, exit 2,
before anything runs.

Every data file a user may name (a link preset, a vehicle model, a thruster layout, a mission, an
arm model, a TPIK configuration) is resolved by :func:`testbed.config.user_file`: a packaged
name, or a path (ending in the file type or holding a separator), which must be a file; a missing
one is "file not found" at the resolved path, never an unknown packaged name.
"""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path

import pytest

from testbed.cli.main import main

SCENARIOS = resources.files("testbed").joinpath("scenarios")
ARM = resources.files("testbed.vehicle").joinpath("data", "arms", "alpha5.toml")


def error_line(capsys: pytest.CaptureFixture[str], argv: list[str]) -> str:
    """Run ``testbed ARGV``; it must exit 2 with one line on stderr: that line, prefix off."""
    assert main(argv) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith("testbed: error: ")
    return err.removeprefix("testbed: error: ").removesuffix("\n")


@pytest.fixture
def here(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A fresh working directory (relative paths resolve in it)."""
    monkeypatch.chdir(tmp_path)
    return tmp_path


# --- defect 3: vehicle.arm.model and vehicle.arm.tpik ------------------------------------------


def test_an_unknown_arm_model_names_set_and_the_key(
    here: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # a review: "…/testbed/vehicle/data/alpha7.toml: file not found", naming neither
    argv = ["run", "uvms-waypoint-v1", "--out", "out", "--set", "vehicle.arm.model=alpha7"]
    assert error_line(capsys, argv) == (
        "--set: vehicle.arm.model: unknown arm model 'alpha7' "
        "(packaged: alpha5; or a path to a .toml file)"
    )
    assert not (here / "out").exists()


def test_an_arm_model_path_is_not_joined_into_the_package(
    here: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # a review: study/myarm.toml was looked for as …/data/study/myarm.toml.toml
    argv = ["run", "uvms-waypoint-v1", "--out", "out", "--set"]
    message = error_line(capsys, [*argv, "vehicle.arm.model=study/myarm.toml"])
    assert message == f"--set: vehicle.arm.model: arm model file not found: {here}/study/myarm.toml"
    (here / "etc").mkdir()
    (here / "etc" / "passwd").write_text("root:x:0:0\n")
    message = error_line(capsys, [*argv, "vehicle.arm.model=etc/passwd"])
    assert (
        message == f"--set: vehicle.arm.model: arm model file {here}/etc/passwd: must end in .toml"
    )


def test_a_bad_user_arm_file_names_set_the_key_the_file_and_its_key(
    here: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    text = ARM.read_text(encoding="utf-8")
    assert text.count("mass_kg = 0.194") == 1
    (here / "heavy.toml").write_text(text.replace("mass_kg = 0.194", "mass_kg = -1.0"))
    argv = ["run", "uvms-waypoint-v1", "--out", "out", "--set", "vehicle.arm.model=heavy.toml"]
    message = error_line(capsys, argv)
    assert message.startswith("--set: vehicle.arm.model: heavy.toml: links[0].mass_kg: must be ")


def test_an_unknown_or_missing_tpik_configuration_names_set_and_the_key(
    here: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # a review: "…/data/tpik.toml: nope: no TPIK table…" omitted the key
    argv = ["run", "uvms-waypoint-v1", "--out", "out", "--set"]
    assert error_line(capsys, [*argv, "vehicle.arm.tpik=nope"]) == (
        "--set: vehicle.arm.tpik: unknown TPIK configuration 'nope' "
        "(packaged: alpha5-heavy, alpha5-heavy-hardware, alpha5-heavy-posture; or a path to a "
        ".toml file)"
    )
    assert error_line(capsys, [*argv, "vehicle.arm.tpik=mine.toml"]) == (
        f"--set: vehicle.arm.tpik: TPIK configuration file not found: {here}/mine.toml"
    )


def test_arm_paths_in_a_scenario_file_are_beside_it_and_errors_name_the_file(
    here: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    text = SCENARIOS.joinpath("uvms-waypoint-v1.toml").read_text(encoding="utf-8")
    assert text.count('model = "alpha5"') == 1
    (here / "study").mkdir()
    scenario = here / "study" / "mine.toml"
    scenario.write_text(text.replace('model = "alpha5"', 'model = "arms/myarm.toml"'))
    message = error_line(capsys, ["run", str(scenario), "--out", "out"])
    missing = here / "study" / "arms" / "myarm.toml"
    assert message == f"{scenario}: vehicle.arm.model: arm model file not found: {missing}"


# --- defect 4: a missing file given by path is "file not found", not an unknown name ------------


@pytest.mark.parametrize(
    ("argv", "prefix", "path"),
    [
        (
            ["run", "--set", "vehicle.thrusters=./my-frame.toml"],
            "--set: vehicle.thrusters: thruster configuration",
            "my-frame.toml",
        ),
        (
            ["run", "--set", "vehicle.model=study/nope.toml"],
            "--set: vehicle.model: vehicle model",
            "study/nope.toml",
        ),
        (
            ["run", "--set", "link.preset=study/nope.toml"],
            "--set: link.preset: link preset",
            "study/nope.toml",
        ),
        (
            ["run", "heavy-waypoint-v1", "--set", "vehicle.autonomy.mission=study/nope.json"],
            "--set: vehicle.autonomy.mission: mission",
            "study/nope.json",
        ),
        (["link", "--preset", "nope.toml"], "--preset: link preset", "nope.toml"),
        (["modem-emulator", "--preset", "./nope.toml"], "--preset: link preset", "nope.toml"),
    ],
)
def test_a_missing_file_given_by_path_is_not_found_at_the_resolved_path(
    argv: list[str], prefix: str, path: str, here: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = ["--out", "out"] if argv[0] == "run" else []
    message = error_line(capsys, [*argv, *out])
    assert message == f"{prefix} file not found: {here / path}"


def test_a_mistyped_path_in_a_scenario_file_names_the_file_the_key_and_the_path(
    here: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    text = SCENARIOS.joinpath("s100-teleop-v1.toml").read_text(encoding="utf-8")
    assert text.count('thrusters = "bluerov2"') == 1
    scenario = here / "study.toml"
    scenario.write_text(text.replace('thrusters = "bluerov2"', 'thrusters = "frmaes/mine.toml"'))
    message = error_line(capsys, ["run", str(scenario), "--out", "out"])
    missing = here / "frmaes" / "mine.toml"
    assert message == (
        f"{scenario}: vehicle.thrusters: thruster configuration file not found: {missing}"
    )


def test_unknown_packaged_names_are_still_listed(
    here: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    message = error_line(capsys, ["run", "--out", "out", "--set", "vehicle.thrusters=octo"])
    assert message.startswith("--set: vehicle.thrusters: unknown thruster configuration 'octo' ")
    assert message.endswith("; or a path to a .toml file)")


# --- nits: the option an error names -----------------------------------------------------------


@pytest.mark.parametrize("command", ["link", "modem-emulator"])
def test_an_unknown_preset_names_the_preset_option(
    command: str, here: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert error_line(capsys, [command, "--preset", "nope"]) == (
        "--preset: unknown link preset 'nope' (packaged: m64, s100, s2c, tether; "
        "or a path to a .toml file)"
    )
    # an override's error still names --set
    message = error_line(capsys, [command, "--set", "bogus=1"])
    assert message.startswith("--set: bogus: unknown key")


def test_an_address_not_of_this_machine_names_host(
    here: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # a review: `--host notahost` named --port; 192.0.2.1 (TEST-NET-1) is nobody's address here
    message = error_line(capsys, ["live", "--host", "192.0.2.1", "--port", "0", "--out", "o"])
    assert message.startswith("--host: cannot serve on 192.0.2.1:0 (")


def test_a_host_that_does_not_resolve_names_host() -> None:
    import socket

    from testbed.cli.live import _bind_option

    assert _bind_option(socket.gaierror(-2, "Name or service not known")) == "--host"
    assert _bind_option(OSError(98, "Address already in use")) == "--port"


@pytest.mark.parametrize(
    ("duration", "message"),
    [  # the settle-time note explains only the lower bound (s100-teleop-v1: settle 10 s)
        ("100000", "--duration: must be in (10, 86400] s, got 100000.0"),
        (
            "5",
            "--duration: must be in (10, 86400] s, got 5.0 (above the scenario's metrics.settle_s)",
        ),
    ],
)
def test_hils_duration_note_is_for_a_duration_too_short(
    duration: str, message: str, here: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["hil", "vehicle", "--port", str(here / "no-such-port"), "--duration", duration]
    assert error_line(capsys, argv) == message


# --- nits: mission waypoints are bounded -------------------------------------------------------


def test_a_waypoint_beyond_the_world_names_the_mission_file_and_the_waypoint(
    here: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # a review: x = 1e9 m ran, and reported a mean position error of 3.06e8 m
    points = [
        {"time_from_start": t, "transform": {"x": x, "y": 0, "z": 1, "rx": 0, "ry": 0, "rz": 0}}
        for t, x in ((0.0, 0.0), (30.0, 1e9))
    ]
    mission = {"name": "far", "parent": "map", "child": "base_link", "waypoints": points}
    (here / "far.json").write_text(json.dumps(mission))
    argv = [
        "run",
        "heavy-waypoint-v1",
        "--out",
        "out",
        "--set",
        "vehicle.autonomy.mission=far.json",
    ]
    assert error_line(capsys, argv) == (
        "--set: vehicle.autonomy.mission: far.json: waypoints[1].transform.x: must be in "
        "[-10000, 10000] m (the world's extent), got 1e+09"
    )


def test_an_arm_heavier_in_water_than_the_vehicle_is_refused(
    here: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Alpha 5 with its first link at 400 kg: (m − ρV)·g summed over the links (closed form
    from the file) is ≈ 3.9 kN, thirty times the Heavy's 132.6-N weight; the run used to
    trim it with a 3.9-kN float, silently, and exit 0."""
    import tomllib

    text = ARM.read_text()
    heavy = text.replace("mass_kg = 0.341", "mass_kg = 400.0", 1)
    assert heavy != text
    (here / "heavy-arm.toml").write_text(heavy)
    data = tomllib.loads(heavy)
    links = [data["base"], *data["links"]]
    wet = sum((link["mass_kg"] - 1000.0 * link["volume_l"] / 1000.0) * 9.81 for link in links)
    argv = ["run", "uvms-station-keeping-v1", "--set", "vehicle.arm.model=heavy-arm.toml"]
    line = error_line(capsys, [*argv, "--out", str(here / "out")])
    assert line.startswith("--set: vehicle.arm: the arm (heavy-arm.toml) weighs ")
    stated = float(line.split(" weighs ", 1)[1].split(" N in water", 1)[0])
    assert stated == pytest.approx(wet, rel=1e-3) and "(bluerov2-heavy, 132.6 N)" in line
    assert not (here / "out").exists()
