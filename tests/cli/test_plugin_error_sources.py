"""A factory of the user's (pilot, link model, control law) that fails when the run calls it: the
one line names where the value that broke it came from.

The factories here refuse a value they are given; the test gives that value once in the
scenario file and once by ``--set`` (over a file that is fine, or over a packaged scenario),
and the line must name that source: the file, or ``--set`` with the overridden keys. Before,
every such line named the scenario file (or ``package:<id>``), even for a value the file never
held.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from testbed.cli.main import main

PLUGINS = '''
from testbed.channel import StandardLink
from testbed.operator.pilots import PilotSample


class Cautious:
    """A pilot that holds still and refuses a surge stick beyond 1."""

    def __init__(self, at_s, surge=0.5):
        if abs(surge) > 1.0:
            raise ValueError(f"surge must be in [-1, 1], got {surge}")

    def sample(self, t_s):
        return PilotSample((0.0, 0.0, 0.0, 0.0, 0.0, 0.0))


def quiet_link(config, scale=1.0):
    """The preset's link, for links without bit errors only."""
    if config.ber > 0.0:
        raise ValueError(f"made for error-free links, got ber = {config.ber}")
    if scale <= 0.0:
        raise ValueError(f"scale must be > 0, got {scale}")
    return StandardLink(config)


class Depth:
    """A depth law that refuses a negative gain (it never flies)."""

    def __init__(self, kp=40.0):
        if kp < 0.0:
            raise ValueError(f"kp must be >= 0, got {kp}")

    def reset(self):
        pass

    def update(self, target, depth, imu, dt_s):
        raise AssertionError("not flown here")
'''

SCENARIO = """\
schema = 1
id = "sources-v1"
description = "a pilot, a link model and a depth law of the user's"
duration_s = 20.0

[link]
preset = "s100"
ber = 0.0
model = "plugins.py:quiet_link"
model_args = {{ scale = {scale} }}

[pilot]
kind = "python"
factory = "plugins.py:Cautious"
args = {{ at_s = 5.0, surge = {surge} }}

[vehicle.control]
depth = "plugins.py:Depth"
depth_args = {{ kp = {kp} }}
"""


@pytest.fixture
def study(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    (tmp_path / "plugins.py").write_text(PLUGINS, encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    return tmp_path


def error_line(study: Path, capsys: pytest.CaptureFixture[str], *args: str) -> str:
    """The one error line of ``testbed run`` (exit 2, nothing written)."""
    out = study / "out"
    code = main(["run", *args, "--out", str(out), "--no-plots"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and err.startswith("testbed: error: "), err
    assert not out.exists()
    return err.removeprefix("testbed: error: ").rstrip("\n")


def scenario(study: Path, *, surge: float = 0.5, kp: float = 40.0, scale: float = 1.0) -> str:
    (study / "s.toml").write_text(SCENARIO.format(surge=surge, kp=kp, scale=scale))
    return "s.toml"


def test_a_bad_value_in_the_file_names_the_file(
    study: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = scenario(study, surge=2.0)
    assert error_line(study, capsys, bad) == (
        "s.toml: pilot.factory (called with pilot.args = {'at_s': 5.0, 'surge': 2.0}): "
        "ValueError: surge must be in [-1, 1], got 2.0"
    )
    # an override elsewhere changes nothing of the call: still the file's
    assert error_line(study, capsys, bad, "--set", "duration_s=30").startswith(
        "s.toml: pilot.factory (called with"
    )


def test_a_set_value_names_the_set_key(study: Path, capsys: pytest.CaptureFixture[str]) -> None:
    good = scenario(study)
    cases = {
        ("pilot.args.surge=2.0",): (
            "--set: pilot.args.surge (calling pilot.factory with pilot.args = "
            "{'at_s': 5.0, 'surge': 2.0}): ValueError: surge must be in [-1, 1], got 2.0"
        ),
        # a later table replaces what an earlier override set inside it: only it is named
        ("pilot.args.surge=0.2", "pilot.args={at_s=1.0, surge=-3.0}"): (
            "--set: pilot.args (calling pilot.factory with pilot.args = "
            "{'at_s': 1.0, 'surge': -3.0}): ValueError: surge must be in [-1, 1], got -3.0"
        ),
        ("vehicle.control.depth_args.kp=-1.0",): (
            "--set: vehicle.control.depth_args.kp (calling vehicle.control.depth with "
            "vehicle.control.depth_args = {'kp': -1.0}): ValueError: kp must be >= 0, got -1.0"
        ),
        ("link.model_args={scale=0.0}",): (
            "--set: link.model_args (calling link.model with link.model_args = {'scale': 0.0}): "
            "ValueError: scale must be > 0, got 0.0"
        ),
        # a link key changes the config the model is given
        ("link.ber=1e-05",): (
            "--set: link.ber (calling link.model with link.model_args = {'scale': 1.0}): "
            "ValueError: made for error-free links, got ber = 1e-05"
        ),
    }
    for overrides, line in cases.items():
        sets = [item for override in overrides for item in ("--set", override)]
        assert error_line(study, capsys, good, *sets) == line


def test_a_factory_set_on_a_packaged_scenario_names_the_set_keys_not_the_package(
    study: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    line = error_line(
        study,
        capsys,
        "s100-teleop-v1",
        "--set",
        "link.model=plugins.py:quiet_link",
        "--set",
        "link.model_args={scale=-1.0}",
    )
    assert line == (
        "--set: link.model, link.model_args (called with link.model_args = {'scale': -1.0}): "
        "ValueError: made for error-free links, got ber = 7e-06"
    )
