"""``operator.mode = "guided"`` holds a point, so the layout must push along body x and along
body y each on its own; load refuses a layout that cannot, with one line naming operator.mode.

Independent truth: the layouts' geometry. ``ecs-2h`` keeps two thrusters, LateralFrontLeft and
LateralBackRight, whose directions are ±(0.707, 0.707, 0) in mate-rov's frame: every force the
pair can make lies on that one diagonal, so no combination of them is a pure surge or a pure
sway (checked below from the thrusters' directions as the file gives them, not from the
allocator). The BlueROV2 and its Heavy have four vectored horizontals at ±45°, which span the
horizontal plane.
"""

from __future__ import annotations

import textwrap
import tomllib
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from testbed.cli.main import main
from testbed.config import ConfigError
from testbed.run import load_scenario


def _guided(folder: Path, thrusters: str) -> Path:
    path = folder / f"guided-{thrusters}.toml"
    path.write_text(
        textwrap.dedent(
            f"""\
            schema = 1
            id = "guided-layout-v1"
            description = "guided on the {thrusters} layout"
            duration_s = 20.0
            [link]
            preset = "s100"
            [vehicle]
            thrusters = "{thrusters}"
            [vehicle.sensors.position]
            rate_hz = 20.0
            noise_m = 0.005
            [operator]
            mode = "guided"
            [pilot]
            kind = "supervisor"
            goals = []
            """
        )
    )
    return path


def _horizontal_directions(layout: str) -> np.ndarray:
    """(n, 2) the horizontal parts of the layout's thruster directions, as its file gives them."""
    text = (resources.files("testbed.vehicle") / f"data/thrusters/{layout}.toml").read_text()
    return np.array([t["direction"][:2] for t in tomllib.loads(text)["thrusters"]])


def test_the_ecs_2h_pair_pushes_along_one_diagonal_only() -> None:
    horizontal = _horizontal_directions("ecs-2h")
    pushing = horizontal[np.linalg.norm(horizontal, axis=1) > 0.0]
    assert len(pushing) == 2
    assert np.linalg.matrix_rank(pushing, tol=1e-3) == 1  # one line: no pure x, no pure y
    assert abs(pushing[0, 0]) == pytest.approx(abs(pushing[0, 1]))  # at 45° to both axes


def test_guided_is_refused_on_ecs_2h(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _guided(tmp_path, "ecs-2h")
    with pytest.raises(ConfigError) as refused:
        load_scenario(str(path))
    message = str(refused.value)
    assert message.startswith(f"{path}: operator.mode: 'guided' holds a point")
    assert "'ecs-2h' cannot make one" in message
    assert "x 0 N, y 0 N" in message
    assert "\n" not in message
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "operator.mode: 'guided'" in err[0], err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("layout", ["bluerov2", "bluerov2-heavy"])
def test_guided_is_accepted_on_the_bluerov2_layouts(tmp_path: Path, layout: str) -> None:
    assert np.linalg.matrix_rank(_horizontal_directions(layout)) == 2  # spans the plane
    scenario = load_scenario(str(_guided(tmp_path, layout)))
    assert scenario.operator.mode == "guided"
    assert scenario.vehicle.thrusters == layout
