"""What a pilot or link model of the user's own may break, and what the testbed then says
(found by a user review): an air time that is not a finite number > 0, a sample that is not a
pilot's; the closed forms that know only the preset; a sweep switching factories; helpers
beside the pilot's file; what metrics.json and a failed sweep run tell a colleague."""

from __future__ import annotations

import csv
import hashlib
import json
import math
import shlex
import textwrap
from pathlib import Path

import pytest

import testbed
from testbed.channel.model import LinkModelError
from testbed.cli.main import main
from testbed.operator.pilots import PilotSample
from testbed.run.runner import run_scenario
from testbed.run.scenario import load_scenario
from tests.run.test_plugins import _scenario_text, write_study

pytestmark = pytest.mark.usefixtures("no_sweep_plots")  # conftest.py: not their subject

BROKEN_LINKS = """
from testbed.channel import StandardLink


class Fixed:
    def __init__(self, config, airtime_s):
        # "nan" and "inf" as text: a scenario refuses non-finite numbers in a factory's args
        value = float(airtime_s) if airtime_s in ("nan", "inf") else airtime_s
        self.base, self.value = StandardLink(config), value

    def airtime_s(self, size_bytes, t_s):
        return self.value

    def error_model(self, rng):
        return self.base.error_model(rng)


class Returns:
    # errors that return what the scenario says (returns) instead of the received copy

    def __init__(self, config, returns):
        self.base, self.returns = StandardLink(config), returns

    def airtime_s(self, size_bytes, t_s):
        return self.base.airtime_s(size_bytes, t_s)

    def error_model(self, rng):
        return self

    def corrupt(self, data, p_independent, t_s):
        flipped = bytes([data[0] ^ 3]) + data[1:]
        return {
            "none": None,
            "text": ("abc", 0),
            "negative": (data, -5),
            "short": (data[:-1], 0),
            "uncounted": (flipped, 0),
            "overcounted": (flipped, 3),
            "counted": (flipped, 2),
        }[self.returns]
"""

ODD_PILOTS = '''
from testbed.operator.pilots import PilotSample


class TupleSample:
    def sample(self, t_s):
        return (0.0,) * 6


class TimeKeeper:
    """Surge stick = 0.5 when every time it was given was a float."""

    def sample(self, t_s):
        return PilotSample((0.5 if isinstance(t_s, float) else -0.5, 0.0, 0.0, 0.0, 0.0, 0.0))


class Sleepy:
    def sample(self, t_s):
        if t_s > 12.0:
            raise ValueError(f"pilot fell asleep at {t_s:.1f}")
        return PilotSample((0.0,) * 6)
'''


HELPED = """
from testbed.operator.pilots import PilotSample

import contracts_helper  # a module beside this file (a name no other test module imports)


class Helped:
    def sample(self, t_s):
        return PilotSample((contracts_helper.SURGE, 0.0, 0.0, 0.0, 0.0, 0.0))
"""


@pytest.fixture
def study(tmp_path: Path) -> Path:
    """test_plugins's study folder, with the broken models and odd pilots beside."""
    folder = write_study(tmp_path / "study")
    (folder / "broken_links.py").write_text(BROKEN_LINKS)
    (folder / "odd_pilots.py").write_text(ODD_PILOTS)
    (folder / "helped.py").write_text(HELPED)
    (folder / "contracts_helper.py").write_text("SURGE = 0.25\n")
    return folder


def _write_sweep(study: Path, sweep_id: str, factory: str, duration_s: float) -> Path:
    """A one-run sweep file in ``study`` flying ``factory``'s pilot (no args) on step.toml."""
    path = study / f"{sweep_id}.toml"
    path.write_text(
        textwrap.dedent(
            f"""\
            schema = 1
            id = "{sweep_id}-v1"
            description = "a pilot of one's own"
            scenario = "step.toml"
            seeds = 1
            metrics = ["energy_wh"]
            [set]
            "pilot.factory" = "{factory}"
            "pilot.args" = {{}}
            "duration_s" = {duration_s}
            [grid]
            "link.ber" = [0.0]
            """
        )
    )
    return path


@pytest.mark.parametrize("airtime", ['"nan"', "-0.5", "0.0", '"inf"', '"0.1"', "false"])
def test_an_air_time_that_is_not_a_finite_number_above_zero_is_one_line_naming_the_model(
    study: Path, airtime: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """A NaN air time used to give a "successful" run with events at t = nan and a negative
    command age; a negative one, simpy's traceback naming no model."""
    link = f'model = "broken_links.py:Fixed"\nmodel_args = {{ airtime_s = {airtime} }}'
    (study / "broken.toml").write_text(_scenario_text('kind = "scripted"', link))
    argv = ["run", str(study / "broken.toml"), "--out", str(study / "out"), "--no-plots"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert f"link model Fixed ({study / 'broken_links.py'}): airtime_s(" in err
    assert "expected a finite time > 0 [s]" in err
    with pytest.raises(LinkModelError):
        run_scenario(load_scenario(str(study / "broken.toml")))


@pytest.mark.parametrize(
    "returns", ["none", "text", "negative", "short", "uncounted", "overcounted", "counted"]
)
def test_received_bytes_that_break_the_error_models_contract_are_one_line_naming_the_model(
    study: Path, returns: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """corrupt() must give bytes of the sent length and the count of the bits that differ
    (counted again by the medium, by XOR): anything else used to give a traceback naming no
    model, or a trace whose deliveries and counts disagreed (a negative count, flips counted
    as none). The copy flipped in two bits and counted 2 is a good one: its frames fail the
    CRC and the run counts them corrupted."""
    link = f'model = "broken_links.py:Returns"\nmodel_args = {{ returns = "{returns}" }}'
    (study / "returns.toml").write_text(_scenario_text('kind = "scripted"', link))
    argv = ["run", str(study / "returns.toml"), "--out", str(study / "out"), "--no-plots"]
    if returns == "counted":
        assert main(argv) == 0
        uplink = json.loads((study / "out" / "metrics.json").read_text())["link"]["uplink"]
        assert uplink["frames_delivered"] == 0
        assert uplink["frames_corrupted"] == uplink["frames_sent"] - uplink["frames_dropped"] > 0
        return
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert f"link model's error model Returns ({study / 'broken_links.py'}): corrupt(<" in err
    assert "expected (bytes of the same length, the number of bits that differ" in err


def test_the_token_cycles_closed_form_is_not_claimed_for_a_model_it_does_not_know(
    study: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """At 570 bit/s an order and its reply outlast the gap the S100 preset's 1900 bit/s sets:
    given as the preset's key, the run warns and says reply_fits_gap false; given as a model,
    the closed form (the preset's bit rate) would say true, so it says nothing (null)."""
    keyed = run_scenario(load_scenario(str(study / "step.toml"), ["link.bitrate_bps=570"]))
    assert keyed.metrics["reply_fits_gap"] is False
    link = 'model = "my_links.py:constant"\nmodel_args = { bitrate_bps = 570.0 }'
    (study / "slow.toml").write_text(_scenario_text('kind = "scripted"', link))
    argv = ["run", str(study / "slow.toml"), "--out", str(study / "out"), "--no-plots"]
    assert main(argv) == 0
    assert "warning" not in capsys.readouterr().err
    metrics = json.loads((study / "out" / "metrics.json").read_text())
    assert metrics["reply_fits_gap"] is None and metrics["token_round_trip_s"] is None
    modelled = run_scenario(load_scenario(str(study / "slow.toml")))
    assert modelled.metrics["link"] == keyed.metrics["link"]  # the same link, the same fates
    from tests.channel.test_link_model import StepRate  # the API's model: the same

    api = run_scenario(load_scenario(str(study / "step.toml")), link_model=StepRate(1.0, 1.0, 0))
    assert api.metrics["reply_fits_gap"] is None and math.isnan(api.metrics["token_round_trip_s"])


def test_a_sweeps_set_switches_the_link_model_and_clears_the_scenarios_arguments(
    study: Path, tmp_path: Path
) -> None:
    """``"link.model_args" = {}`` in ``[set]`` is one value, the whole table: it replaces the
    scenario's arguments (they used to be merged key by key, so the new factory got the old
    one's); each row is the direct run with the same overrides."""
    link = 'model = "my_links.py:constant"\nmodel_args = { bitrate_bps = 1400.0 }'
    pilot = 'kind = "python"\nfactory = "my_pilots.py:StepPilot"\nargs = { at_s = 15.0 }'
    (study / "modelled.toml").write_text(_scenario_text(pilot, link))
    sweep_file = study / "switch.toml"
    sweep_file.write_text(
        textwrap.dedent(
            """\
            schema = 1
            id = "switch-v1"
            description = "another model, no arguments"
            scenario = "modelled.toml"
            seeds = 1
            metrics = ["command_lag_s.mean"]
            [set]
            "link.model" = "broken_links.py:Fixed"
            "link.model_args" = { airtime_s = 0.2 }
            "pilot.args" = { at_s = 5.0, surge = 0.2 }
            "duration_s" = 15.0
            [grid]
            "link.ber" = [0.0, 1e-5]
            """
        )
    )
    out = tmp_path / "out"
    assert main(["sweep", str(sweep_file), "--workers", "1", "--out", str(out)]) == 0
    with (out / "results.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    overrides = [
        f"link.model={study / 'broken_links.py'}:Fixed",
        "link.model_args={airtime_s=0.2}",
        "pilot.args={at_s=5.0, surge=0.2}",
        "duration_s=15.0",
        "link.ber=1e-05",
    ]
    direct = run_scenario(load_scenario(str(study / "modelled.toml"), overrides), seed=0)
    assert float(rows[1]["command_lag_s.mean"]) == direct.metrics["command_lag_s"]["mean"]
    # each order: the intrinsic delay plus the model's 0.2 s, whatever its size
    delay = direct.scenario.link.channel.intrinsic_delay_s
    assert direct.metrics["command_lag_s"]["mean"] > delay + 0.2


def test_a_pilot_imports_a_module_beside_it_and_both_files_are_recorded_and_held(
    study: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A pilot's file imports a module beside it (as ``python helped.py`` could): the
    run flies the helper's stick, metrics.json records both files' SHA-256, and a sweep's
    ``--resume`` refuses an edited helper."""
    monkeypatch.chdir(tmp_path)  # not the study folder: the helper is found beside the file
    factory = f"pilot.factory={study / 'helped.py'}:Helped"
    result = run_scenario(load_scenario(str(study / "step.toml"), [factory, "pilot.args={}"]))
    assert set(result.recorder.series()["cmd_x"]) <= {0.0, 0.25}
    assert 0.25 in set(result.recorder.series()["cmd_x"])
    files = result.metrics["inputs"]["files"]
    for name in ("helped.py", "contracts_helper.py"):
        path = study / name
        assert files[str(path)] == hashlib.sha256(path.read_bytes()).hexdigest()

    sweep_file = _write_sweep(study, "helped", "helped.py:Helped", 12.0)
    out = tmp_path / "sweep"
    assert main(["sweep", str(sweep_file), "--workers", "1", "--out", str(out)]) == 0
    (study / "contracts_helper.py").write_text("SURGE = 0.5\n")
    sweep_file.write_text(sweep_file.read_text().replace("[0.0]", "[0.0, 1e-5]"))
    assert main(["sweep", str(sweep_file), "--workers", "1", "--out", str(out), "--resume"]) == 2


def test_a_sample_that_is_no_pilots_is_one_line_and_the_pilot_is_given_float_times(
    study: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A sample that is a tuple (not a PilotSample) used to end the run with a traceback of the
    testbed's own frames; ``t_s`` was the int 0 at the first sample."""
    odd = f"pilot.factory={study / 'odd_pilots.py'}"
    argv = ["run", str(study / "step.toml"), "--out", str(study / "out"), "--no-plots"]
    assert main([*argv, "--set", f"{odd}:TupleSample", "--set", "pilot.args={}"]) == 2
    err = capsys.readouterr().err
    assert err == (
        f"testbed: error: pilot TupleSample ({study / 'odd_pilots.py'}): sample(0.0): got a "
        "tuple, not a PilotSample (testbed.operator.pilots)\n"
    )
    keeper = load_scenario(str(study / "step.toml"), [f"{odd}:TimeKeeper", "pilot.args={}"])
    assert set(run_scenario(keeper).recorder.series()["cmd_x"]) <= {0.0, 0.5}


def test_start_s_is_refused_for_a_python_pilot_and_a_forgotten_suffix_is_hinted(
    study: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["run", str(study / "step.toml"), "--out", str(study / "out"), "--no-plots"]
    assert main([*argv, "--set", "pilot.start_s=8"]) == 2
    assert "pilot.start_s: not used when kind = 'python'" in capsys.readouterr().err
    assert main([*argv, "--set", "pilot.factory=my_pilots_typo:StepPilot"]) == 2
    assert "(a file is named as 'my_pilots_typo.py:StepPilot')" in capsys.readouterr().err


class HeldSticks:
    """A pilot object of the API's caller: surge held at 0.25."""

    def sample(self, t_s: float) -> PilotSample:
        return PilotSample((0.25, 0.0, 0.0, 0.0, 0.0, 0.0))


def test_metrics_name_the_version_and_the_pilot_and_a_failed_sweep_run_says_where_and_how(
    study: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """metrics.json says the testbed's version and the pilot's factory and arguments; a sweep
    run the pilot failed records the line in the pilot's file that raised, and the summary
    gives the command that runs that point alone, which fails the same way."""
    result = run_scenario(load_scenario(str(study / "step.toml")))
    inputs = result.metrics["inputs"]
    assert inputs["testbed"] == testbed.__version__
    assert inputs["pilot"] == {
        "factory": f"{study / 'my_pilots.py'}:StepPilot",
        "args": {"at_s": 15.0},
    }
    # a pilot object handed to the API flies instead of the scenario's: the record names it
    handed = run_scenario(load_scenario(str(study / "step.toml")), pilot=HeldSticks())
    assert handed.metrics["inputs"]["pilot"] == {"object": f"{__name__}.HeldSticks"}
    flown = handed.recorder.series()["cmd_x"]  # 0 before the operator's first sample
    assert set(flown) == {0.0, 0.25} and flown[-1] == 0.25
    sweep_file = _write_sweep(study, "sleepy", "odd_pilots.py:Sleepy", 15.0)
    out = tmp_path / "sweep"
    assert main(["sweep", str(sweep_file), "--workers", "1", "--out", str(out)]) == 1
    summary = capsys.readouterr().out
    with (out / "results.csv").open(newline="") as handle:
        (row,) = list(csv.DictReader(handle))
    line = ODD_PILOTS.split("\n").index(
        '            raise ValueError(f"pilot fell asleep at {t_s:.1f}")'
    )
    where = f"(at {study / 'odd_pilots.py'}:{line + 1})"
    pilot = f"pilot Sleepy ({study / 'odd_pilots.py'})"
    assert row["error"].startswith(f"PilotError: {pilot}: sample(12.")
    assert row["error"].endswith(f") raised ValueError: pilot fell asleep at 12.2 {where}")
    command = summary.split("the first failed run alone: ", 1)[1].split("\n", 1)[0]
    words = shlex.split(command)  # the line as a shell would split it
    assert words[:2] == ["testbed", "run"]
    capsys.readouterr()
    assert main([*words[1:], "--out", str(tmp_path / "alone"), "--no-plots"]) == 2
    assert "raised ValueError: pilot fell asleep at 12.2 (what ran" in capsys.readouterr().err
