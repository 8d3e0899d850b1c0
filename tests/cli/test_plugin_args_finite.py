"""A NaN or an infinity in a factory's arguments (a pilot's ``args``, a link model's
``model_args``, a control law's ``depth_args``/``attitude_args``, ``testbed link --model-args``)
is refused when the scenario loads: one line naming the file (or ``--set``) and the key, exit 2,
as the scenario's own numeric keys refuse them.

Before, they reached the factory and the run went on, and ``metrics.json`` (strict JSON)
recorded them as ``null``: the record misstated what ran. Finite arguments are recorded as the
file gives them.
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import pytest

from testbed.cli.main import main

PLUGINS = '''
from testbed.channel import StandardLink
from testbed.operator.pilots import PilotSample


class Still:
    """A pilot that holds still whatever it is given."""

    def __init__(self, at_s, surge=0.5, gains=()):
        pass

    def sample(self, t_s):
        return PilotSample((0.0, 0.0, 0.0, 0.0, 0.0, 0.0))


def plain_link(config, scale=1.0):
    return StandardLink(config)


class Depth:
    """A depth law that is never flown here (the runs fail before it would)."""

    def __init__(self, kp=40.0, gains=()):
        pass

    def reset(self):
        pass

    def update(self, target, depth, imu, dt_s):
        raise AssertionError("not flown here")
'''

PILOT_ONLY = """\
schema = 1
id = "finite-v1"
description = "a pilot of the user's"
duration_s = 6.0

[metrics]
settle_s = 1.0

[pilot]
kind = "python"
factory = "plugins.py:Still"
args = {pilot_args}
"""

WITH_MODEL_AND_LAW = """
[link]
model = "plugins.py:plain_link"
model_args = {model_args}

[vehicle.control]
depth = "plugins.py:Depth"
depth_args = {depth_args}
"""


@pytest.fixture
def study(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    (tmp_path / "plugins.py").write_text(PLUGINS, encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    return tmp_path


def scenario(study: Path, pilot_args: str, model_args: str = "", depth_args: str = "") -> str:
    text = PILOT_ONLY.format(pilot_args=pilot_args)
    if model_args:
        text += WITH_MODEL_AND_LAW.format(model_args=model_args, depth_args=depth_args)
    (study / "s.toml").write_text(text, encoding="utf-8")
    return "s.toml"


def refused(study: Path, capsys: pytest.CaptureFixture[str], argv: list[str]) -> str:
    """The one error line of ``testbed ARGV`` (exit 2; a run writes nothing)."""
    out = study / "out"
    code = main([*argv, "--out", str(out), "--no-plots"] if argv[0] == "run" else argv)
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1, err
    assert not out.exists()
    return err.rstrip("\n")


NOT_FINITE = [  # the file's args tables, and the line
    ("{ at_s = 1.0, surge = nan }", "", "", "pilot.args.surge: must be a finite number, got nan"),
    ("{ at_s = inf }", "", "", "pilot.args.at_s: must be a finite number, got inf"),
    ("{ at_s = 1.0 }", "{ scale = -inf }", "{}", "link.model_args.scale: must be a finite number, "
     "got -inf"),
    ("{ at_s = 1.0 }", "{}", "{ kp = 1.0, gains = [1.0, nan] }",
     "vehicle.control.depth_args.gains[1]: must be a finite number, got nan"),
]  # fmt: skip


@pytest.mark.parametrize(("pilot_args", "model_args", "depth_args", "line"), NOT_FINITE)
def test_a_non_finite_argument_in_the_file_is_one_line_naming_it(
    study: Path,
    capsys: pytest.CaptureFixture[str],
    pilot_args: str,
    model_args: str,
    depth_args: str,
    line: str,
) -> None:
    name = scenario(study, pilot_args, model_args, depth_args)
    assert refused(study, capsys, ["run", name]) == f"testbed: error: s.toml: {line}"


def test_a_non_finite_argument_by_set_names_set(
    study: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    name = scenario(study, "{ at_s = 1.0 }")
    argv = ["run", name, "--set", "pilot.args.gains={ x = [0.5, -inf] }"]
    assert refused(study, capsys, argv) == (
        "testbed: error: --set: pilot.args.gains.x[1]: must be a finite number, got -inf"
    )


def test_testbed_link_refuses_a_non_finite_model_argument(
    study: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["link", "--frames", "5", "--model", "plugins.py:plain_link"]
    assert refused(study, capsys, [*argv, "--model-args", "{ scale = nan }"]) == (
        "testbed: error: --model-args: scale: must be a finite number, got nan"
    )


def test_finite_arguments_are_recorded_as_the_file_gives_them(study: Path) -> None:
    args = "{ at_s = 1.0, surge = -0.25, gains = [1e-300, 1.7e308, -3] }"
    out = study / "out"
    assert main(["run", scenario(study, args), "--out", str(out), "--no-plots"]) == 0
    recorded = json.loads((out / "metrics.json").read_text(encoding="utf-8"))["inputs"]
    assert recorded["pilot"] == {
        "factory": "plugins.py:Still",
        "args": tomllib.loads(f"a = {args}")["a"],
    }
