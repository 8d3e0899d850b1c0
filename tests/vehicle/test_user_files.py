"""A user's own vehicle model and thruster layout files, named by path in a scenario.

Checked against what the files say: a model whose buoyancy the user changed floats where
B·fraction = W puts it (the hull's submerged fraction, linear across the surface), and a layout
with one thruster turned round allocates with that column of the packaged matrix negated.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from testbed.config import ConfigError
from testbed.run.scenario import load_scenario
from testbed.vehicle.hydrodynamics import load_model
from testbed.vehicle.physics import Physics
from testbed.vehicle.thruster_config import load_thruster_config
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
    with pytest.raises(ConfigError, match=r"vehicle\.thrusters: unknown thruster configuration"):
        load_scenario("s100-teleop-v1", [f"vehicle.thrusters={tmp_path / 'none.toml'}"])


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
