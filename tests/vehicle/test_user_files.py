"""A user's own vehicle model, thruster layout, arm model and TPIK files, named by path in a
scenario.

Checked against what the files say: a model whose buoyancy the user changed floats where
B·fraction = W puts it (the hull's submerged fraction, linear across the surface), and a layout
with one thruster turned round allocates with that column of the packaged matrix negated.
"""

from __future__ import annotations

import dataclasses
import hashlib
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from testbed.config import ConfigError
from testbed.run.runner import run_scenario
from testbed.run.scenario import load_scenario
from testbed.vehicle.arm import load_arm_model
from testbed.vehicle.hydrodynamics import load_model
from testbed.vehicle.physics import Physics
from testbed.vehicle.thruster_config import load_thruster_config
from testbed.vehicle.tpik import load_tpik_config
from testbed.vehicle.vehicle import Vehicle

DATA = resources.files("testbed.vehicle").joinpath("data")


def _copy(kind: str, name: str, to: Path, replace: tuple[str, str]) -> Path:
    text = DATA.joinpath(kind, f"{name}.toml").read_text(encoding="utf-8")
    assert text.count(replace[0]) == 1
    to.write_text(text.replace(*replace), encoding="utf-8")
    return to


def test_a_users_model_file_is_the_model_flown(tmp_path: Path) -> None:
    """bluerov2 with 20 N more buoyancy floats higher, exactly where its own figures say."""
    path = _copy(
        "models", "bluerov2", tmp_path / "light.toml", ("buoyancy_n = 114.8", "buoyancy_n = 134.8")
    )
    model = load_model(str(path))
    assert model.buoyancy_n == 134.8 and model.weight_n == load_model("bluerov2").weight_n
    with Physics(model, start_position_ned=(0.0, 0.0, 0.5)) as sim:
        for _ in range(int(40.0 / sim.dt_s)):
            sim.step(np.zeros(6))
        depth = sim.state().position_ned[2]
    cob_depth = (model.weight_n / model.buoyancy_n - 0.5) * model.hull_size_m[2]
    assert depth == pytest.approx(cob_depth - model.cob_m[2], abs=0.005)


def test_a_users_layout_file_in_a_scenario(tmp_path: Path) -> None:
    """The scenario names the file by path; the vehicle allocates with the file's geometry."""
    left = 'name = "VerticalLeft"\nposition_m = [-0.11, 0.01, 0.0]\ndirection = [0.0, 0.0, '
    path = _copy(
        "thrusters", "bluerov2", tmp_path / "flipped.toml", (left + "1.0]", left + "-1.0]")
    )
    scenario = load_scenario("s100-teleop-v1", [f"vehicle.thrusters={path}"])
    assert scenario.vehicle.thrusters == str(path)
    packaged = np.array(load_thruster_config("bluerov2").matrix)
    with Vehicle(scenario.vehicle, np.random.default_rng(0)) as vehicle:
        mine = np.array(vehicle.thruster_config.matrix)
    column = vehicle.thruster_names.index("VerticalLeft")
    assert np.array_equal(mine[:, column], -packaged[:, column])
    others = [i for i in range(packaged.shape[1]) if i != column]
    assert np.array_equal(mine[:, others], packaged[:, others])


def test_bad_user_files_are_one_line_errors(tmp_path: Path) -> None:
    bad = _copy("models", "bluerov2", tmp_path / "bad.toml", ("mass_kg = 11.5", "mass_kg = -1.0"))
    with pytest.raises(ConfigError) as err:
        load_scenario("s100-teleop-v1", [f"vehicle.model={bad}"])
    message = str(err.value)
    assert message.startswith("--set: vehicle.model: ") and str(bad) in message
    assert "mass_kg" in message and "\n" not in message
    missing = tmp_path / "none.toml"
    with pytest.raises(ConfigError) as err:
        load_scenario("s100-teleop-v1", [f"vehicle.thrusters={missing}"])
    assert str(err.value) == (
        f"--set: vehicle.thrusters: thruster configuration file not found: {missing.absolute()}"
    )


@pytest.mark.parametrize(
    ("mass", "weight", "refused"),
    [
        ("130.0", "127.5", True),  # a review: W = m·g held for g = 0.98 and the model ran
        ("11.5", "110.0", True),  # 9.565 m/s², 1.4 % under 9.78
        ("11.5", "114.3", True),  # 9.939 m/s², past 9.83 + 1 %
        ("11.5", "112.8", False),  # packaged: 9.81
        ("11.5", "112.4", False),  # 9.774 m/s²: 0.06 % under 9.78, rounding
    ],
)
def test_a_models_weight_is_its_mass_times_g(
    tmp_path: Path, mass: str, weight: str, refused: bool
) -> None:
    text = DATA.joinpath("models", "bluerov2.toml").read_text(encoding="utf-8")
    assert text.count("mass_kg = 11.5") == 1 and text.count("weight_n = 112.8") == 1
    text = text.replace("mass_kg = 11.5", f"mass_kg = {mass}")
    path = tmp_path / "odd.toml"
    path.write_text(text.replace("weight_n = 112.8", f"weight_n = {weight}"), encoding="utf-8")
    if not refused:
        assert load_model(str(path)).weight_n == float(weight)
        return
    with pytest.raises(ConfigError) as info:
        load_scenario("s100-teleop-v1", [f"vehicle.model={path}"])
    message = str(info.value)
    assert message.startswith(f"--set: vehicle.model: {path}: weight_n: must be mass_kg·g ")
    assert f"got {weight.removesuffix('.0')}" in message and "\n" not in message


def _tpik_file(to: Path, rate_hz: str) -> Path:
    """The packaged alpha5-heavy TPIK table as a user's file: its keys at the top level."""
    text = DATA.joinpath("tpik.toml").read_text(encoding="utf-8")
    table = text[text.index("[alpha5-heavy]\n") : text.index("[alpha5-heavy-hardware]")]
    table = table.removeprefix("[alpha5-heavy]\n").replace("[[alpha5-heavy.limit_tasks]]", "[[")
    assert table.count("rate_hz = 30.0") == 1
    to.write_text(table.replace("[[", "[[limit_tasks]]").replace("30.0", rate_hz, 1))
    return to


def test_a_users_arm_and_tpik_files_are_the_arm_flown(tmp_path: Path) -> None:
    """vehicle.arm.model and vehicle.arm.tpik take a path like vehicle.model: the vehicle's
    manipulator and its physics carry the file's arm (a heavier first link), the TPIK the file's
    rate, and the run's inputs hold both files' SHA-256."""
    arm = _copy("arms", "alpha5", tmp_path / "myarm.toml", ("mass_kg = 0.194", "mass_kg = 0.5"))
    tpik = _tpik_file(tmp_path / "mytpik.toml", "20.0")
    scenario = load_scenario(
        "uvms-station-keeping-v1", [f"vehicle.arm.model={arm}", f"vehicle.arm.tpik={tpik}"]
    )
    packaged = load_arm_model()
    with Vehicle(scenario.vehicle, np.random.default_rng(0)) as vehicle:
        manipulator = vehicle.manipulator
        assert manipulator is not None
        assert manipulator.model.links[0].mass_kg == 0.5 != packaged.links[0].mass_kg
        assert manipulator.model.links[1:] == packaged.links[1:]
        assert vehicle.physics.arm_model is not None
        assert vehicle.physics.arm_model.links[0].mass_kg == 0.5
        assert manipulator.tpik == dataclasses.replace(load_tpik_config(), rate_hz=20.0)
    files = dict(scenario.files)
    for path in (arm, tpik):
        assert files[str(path)] == hashlib.sha256(path.read_bytes()).hexdigest()


def test_arm_and_tpik_paths_in_a_scenario_file_are_taken_beside_it(tmp_path: Path) -> None:
    folder = tmp_path / "study"
    folder.mkdir()
    _copy("arms", "alpha5", folder / "myarm.toml", ("mass_kg = 0.194", "mass_kg = 0.5"))
    _tpik_file(folder / "mytpik.toml", "20.0")
    text = resources.files("testbed").joinpath("scenarios", "uvms-waypoint-v1.toml").read_text()
    assert text.count('model = "alpha5"') == 1
    mine = 'model = "myarm.toml"\ntpik = "mytpik.toml"'
    path = folder / "uvms.toml"
    path.write_text(text.replace('model = "alpha5"', mine))
    scenario = load_scenario(str(path))
    assert scenario.vehicle.arm is not None
    assert scenario.vehicle.arm.model == str(folder / "myarm.toml")
    assert scenario.vehicle.arm.arm_model().links[0].mass_kg == 0.5
    assert load_tpik_config(scenario.vehicle.arm.tpik).rate_hz == 20.0
    assert [name for name, _ in scenario.files] == [
        str(path),
        str(folder / "myarm.toml"),
        str(folder / "mytpik.toml"),
    ]


def test_a_bad_user_tpik_file_names_the_key_the_file_and_its_key(tmp_path: Path) -> None:
    tpik = _tpik_file(tmp_path / "fast.toml", "-1.0")
    with pytest.raises(ConfigError) as err:
        load_scenario("uvms-waypoint-v1", [f"vehicle.arm.tpik={tpik}"])
    message = str(err.value)
    assert message.startswith(f"--set: vehicle.arm.tpik: {tpik}: rate_hz: must be ")
    assert "\n" not in message


def test_a_users_model_flies_the_ismc_with_the_gains_the_scenario_gives(tmp_path: Path) -> None:
    """A model file of the user's own has no packaged ISMC gains: refused in one line naming
    the key until kp, rho and lambda_ are all set; then the Heavy's figures under another name,
    with the Heavy's gains given, fly exactly as the packaged Heavy (a review: no way to fly
    the autonomy with a model of one's own, and the error named the packaged gains file)."""
    path = _copy(
        "models", "bluerov2-heavy", tmp_path / "my-heavy.toml", ('"bluerov2-heavy"', '"my-heavy"')
    )
    short = ["duration_s=12", "trials=1"]
    with pytest.raises(ConfigError) as refused:
        load_scenario("heavy-station-keeping-v1", [f"vehicle.model={path}", *short])
    assert str(refused.value).startswith("--set: vehicle.autonomy.ismc: ")
    assert "'my-heavy' has no packaged ISMC gains" in str(refused.value)
    assert "set kp, rho too" in str(refused.value)  # the scenario sets lambda_ already
    packaged = load_scenario("heavy-station-keeping-v1", short)
    gains = (
        "vehicle.autonomy.ismc.kp=[10.0, 10.0, 6.0, 3.0, 6.0, 10.0]",
        "vehicle.autonomy.ismc.rho=20.0",
    )
    own = load_scenario("heavy-station-keeping-v1", [f"vehicle.model={path}", *short, *gains])
    runs = [run_scenario(scenario) for scenario in (packaged, own)]
    assert runs[0].metrics["mission"] == runs[1].metrics["mission"]
    series = [run.recorder.series() for run in runs]
    assert series[0].keys() == series[1].keys()
    for column in series[0]:
        np.testing.assert_array_equal(series[0][column], series[1][column], err_msg=column)


@pytest.mark.parametrize(
    ("kind", "replace", "named"),
    [  # an extensibility review's files, all of which ran quietly with exit 0
        ("models", ("buoyancy_n = 114.8", "buoyancy_n = 1e9"), "buoyancy_n: must be ≤ 397.2 N"),
        ("models", ("[0.16, 0.16, 0.16]", "[0.16, 0.16, 0.4]"), "inertia_kg_m2[2]: Izz = 0.4 "),
        ("models", ("cog_m = [0.0, 0.0, 0.02]", "cog_m = [0.0, 0.0, 5.0]"), "cog_m[2]: must lie"),
        ("thrusters", ("[0.11, 0.01, 0.0]", "[1e9, 0.01, 0.0]"), "vehicle.thrusters: thruster"),
    ],
)
def test_figures_no_rigid_body_has_are_refused_naming_the_key(
    tmp_path: Path, kind: str, replace: tuple[str, str], named: str
) -> None:
    """B at most the water the hull box holds (1030 kg/m³, 9.83 m/s²: 397.2 N for the
    BlueROV2's 0.457 × 0.338 × 0.254 m), principal moments within the triangle inequality,
    the centres within the hull box, thrusters within the hull's size of the origin (a rod's
    near-zero moment about its axis is a body: the review's 1e-9 kg·m² stays legal)."""
    path = _copy(kind, "bluerov2", tmp_path / "odd.toml", replace)
    key = "vehicle.model" if kind == "models" else "vehicle.thrusters"
    with pytest.raises(ConfigError) as err:
        load_scenario("s100-teleop-v1", [f"{key}={path}"])
    message = str(err.value)
    assert named in message and "\n" not in message, message


def _edited(kind: str, to: Path, *edits: tuple[str, str]) -> Path:
    """The packaged bluerov2 file of ``kind`` with each (old, new) edit made once."""
    text = DATA.joinpath(kind, "bluerov2.toml").read_text(encoding="utf-8")
    for old, new in edits:
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    to.write_text(text, encoding="utf-8")
    return to


@pytest.mark.parametrize(
    ("kind", "edits", "named"),
    [  # a vehicle modeller's review: each ran quietly (exit 0, NaN results) or as a traceback
        ("models", [("mass_kg = 11.5", "mass_kg = inf")], "mass_kg: must be finite, got inf"),
        ("models", [("[0.16, 0.16, 0.16]", "[inf, 0.16, 0.16]")], "inertia_kg_m2[0]: must be fi"),
        ("models", [("[-4.03,", "[-inf,")], "linear_damping[0]: must be finite, got -inf"),
        ("models", [("[-33.8,", "[-inf,")], "quadratic_damping[0]: must be finite, got -inf"),
        ("models", [("[0.0, 0.0, 0.02]", "[0.0, 0.0, inf]")], "cog_m[2]: must be finite"),
        (
            "models",  # grams for kilograms, the weight made to match: it sank 450 m in 12 s
            [("mass_kg = 11.5", "mass_kg = 11500"), ("weight_n = 112.8", "weight_n = 112815")],
            "mass_kg: 11500 kg in a hull box of 0.03923 m³ is 2.931e+05 kg/m³, denser than any",
        ),
        (
            "models",  # g·m² for kg·m²
            [("[0.16, 0.16, 0.16]", "[160.0, 160.0, 160.0]")],
            "inertia_kg_m2[0]: Ixx = 160 kg·m² exceeds 0.5139, the most 11.5 kg inside the",
        ),
        (
            "models",  # its default was Wu's full C_A, the variant that tumbles at speed
            [('\nadded_mass_coriolis = "isotropic"\n', "\n")],
            "added_mass_coriolis: required key missing ('isotropic' as the packaged models",
        ),
        (
            "thrusters",
            [("center_of_mass_m = [0.0, 0.0, -0.09]", "center_of_mass_m = [inf, 0.0, -0.09]")],
            "center_of_mass_m: must be finite, got [inf, 0.0, -0.09]",  # as written (mate-rov)
        ),
        (
            "thrusters",  # moments about a point 2 m away: the axis maxima collapsed
            [("center_of_mass_m = [0.0, 0.0, -0.09]", "center_of_mass_m = [2.0, 0.0, -0.09]")],
            "[0.0, 2.0, 0.09] m in body FRD, lies outside the hull of bluerov2 (half-sizes [",
        ),
    ],
)
def test_a_modellers_slips_are_one_line_naming_the_key(
    tmp_path: Path, kind: str, edits: list[tuple[str, str]], named: str
) -> None:
    path = _edited(kind, tmp_path / "mine.toml", *edits)
    key = "vehicle.model" if kind == "models" else "vehicle.thrusters"
    with pytest.raises(ConfigError) as err:
        load_scenario("s100-teleop-v1", [f"{key}={path}"])
    message = str(err.value)
    assert named in message and "\n" not in message, message


def test_a_model_without_its_coriolis_option_flies_with_the_scenarios(tmp_path: Path) -> None:
    """The option missing from the file is refused alone, not when the scenario sets it."""
    edit = ('\nadded_mass_coriolis = "isotropic"\n', "\n")
    path = _edited("models", tmp_path / "mine.toml", edit)
    scenario = load_scenario(
        "s100-teleop-v1", [f"vehicle.model={path}", "vehicle.added_mass_coriolis=isotropic"]
    )
    assert scenario.vehicle.hydro_model().added_mass_coriolis == "isotropic"


def test_a_layout_that_makes_no_yaw_is_refused_where_the_heading_is_held(tmp_path: Path) -> None:
    """Only the vertical thrusters, all on the centreline: no yaw moment. Depth hold and
    stabilize hold the heading, so they are refused (it ran, the heading drifting 10°);
    manual flies it."""
    text = DATA.joinpath("thrusters", "bluerov2.toml").read_text(encoding="utf-8")
    head, *blocks = text.split("[[thrusters]]")
    kept = [b for b in blocks if "direction = [0.0, 0.0," in b]
    kept = [b.replace("0.11, ", "0.0, ").replace("-0.11, ", "0.0, ") for b in kept]
    assert kept
    path = tmp_path / "verticals.toml"
    path.write_text("[[thrusters]]".join([head, *kept]), encoding="utf-8")
    # the copy kept the packaged file's ArduSub motor list, which names the removed thrusters
    with pytest.raises(ConfigError, match=r"ardusub.motors: .* has no \[ardusub\] table"):
        load_thruster_config(str(path))
    path.write_text(path.read_text(encoding="utf-8").split("\n[ardusub]")[0], encoding="utf-8")
    layout = load_thruster_config(str(path))
    assert not layout.matrix[5].any()  # the file's own geometry: no yaw moment
    for mode in ("depth_hold", "stabilize"):
        with pytest.raises(ConfigError, match=f"operator.mode: '{mode}' holds the heading"):
            load_scenario("s100-teleop-v1", [f"vehicle.thrusters={path}", f"operator.mode={mode}"])
    load_scenario("s100-teleop-v1", [f"vehicle.thrusters={path}", "operator.mode=manual"])


@pytest.mark.parametrize(
    ("edit", "named"),
    [  # a UVMS review: the first crashed the run at its first solve, the second flew 1.4 m off
        (
            (
                "joint_velocity_limits = [0.5, 1.0, 1.0, 1.0]",
                "joint_velocity_limits = [0.5, 1.0, 1.0]",
            ),
            "joint_velocity_limits: 3 values for the arm's 4 joints (alpha5)",
        ),
        (
            ("physical = [0.0, 1.571]", "physical = [0.0, 90.0]"),
            "limit_tasks[0].physical: [0, 90] rad is not inside axis_d's limits [0, 3.49] rad",
        ),
        (  # the start pose outside the safety range: broken from the first instant, accepted
            ("safety = [0.087, 1.475]", "safety = [0.087, 1.1]"),
            "limit_tasks[0].safety: [0.087, 1.1] rad does not hold axis_d's start angle 1.2 rad",
        ),
    ],
)
def test_a_tpik_table_for_another_arm_is_refused_at_load(
    tmp_path: Path, edit: tuple[str, str], named: str
) -> None:
    """The TPIK table's joints are held to the arm's: the count, each limit task's physical
    range inside that joint's limits and its safety range around the start angle (the arm
    model file's own figures)."""
    path = _tpik_file(tmp_path / "mytpik.toml", "30.0")
    text = path.read_text(encoding="utf-8")
    assert text.count(edit[0]) == 1
    path.write_text(text.replace(*edit), encoding="utf-8")
    if "safety" in named or "physical" in named:  # keep the task itself consistent
        path.write_text(path.read_text().replace("safety = [0.087, 1.475]", "safety = [5.0, 84.5]"))
    with pytest.raises(ConfigError) as err:
        load_scenario("uvms-station-keeping-v1", [f"vehicle.arm.tpik={path}"])
    message = str(err.value)
    assert named in message and "\n" not in message, message
