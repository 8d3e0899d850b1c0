"""Pilots and link models of the user's own, named in scenario files (testbed.run.plugins):
they reach runs, trials and sweeps, with paths taken from the file that names them, one seed
making one result, and one-line errors for every way the name or its arguments can be wrong."""

from __future__ import annotations

import csv
import hashlib
import textwrap
import threading
from pathlib import Path

import numpy as np
import pytest

from testbed.cli.main import main
from testbed.config import ConfigError
from testbed.live.hub import Hub
from testbed.live.session import LiveSession
from testbed.run.runner import run_scenario
from testbed.run.scenario import load_scenario
from testbed.run.trials import run_trials
from testbed.sweep import load_sweep, run_sweep
from tests.channel.test_link_model import order_crossings

PILOTS = '''
import numpy as np
from testbed.operator.pilots import PilotSample


class StepPilot:
    """Surge ``surge`` from ``at_s`` on; nothing else."""

    def __init__(self, at_s, surge=0.5):
        self.at_s, self.surge = at_s, surge

    def sample(self, t_s):
        return PilotSample((self.surge if t_s >= self.at_s else 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))


class NoisyPilot:
    """A new uniform surge stick at each sample, drawn from the run's generator."""

    def __init__(self, rng):
        self.rng = rng

    def sample(self, t_s):
        return PilotSample((float(self.rng.uniform(-1.0, 1.0)), 0.0, 0.0, 0.0, 0.0, 0.0))


def not_a_pilot():
    return 42


def failing(at_s):
    raise RuntimeError(f"no pilot at {at_s}")
'''

LINKS = """
from dataclasses import dataclass

from testbed.channel import StandardLink


@dataclass(frozen=True)
class ConstantRate:
    base: StandardLink
    bitrate_bps: float

    def airtime_s(self, size_bytes, t_s):
        return size_bytes * 8.0 / self.bitrate_bps

    def error_model(self, rng):
        return self.base.error_model(rng)


def constant(config, bitrate_bps=1900.0):
    return ConstantRate(StandardLink(config), bitrate_bps)
"""

SHORT = ["duration_s=30", "metrics.settle_s=10", "trials=1"]


def _scenario_text(pilot: str, link: str = "", extra: str = "") -> str:
    return textwrap.dedent(
        f"""\
        schema = 1
        id = "mine-v1"
        description = "a scenario of my own"
        duration_s = 30.0
        [link]
        preset = "s100"
        {link}
        [pilot]
        {pilot}
        {extra}
        """
    )


def write_study(folder: Path) -> Path:
    """``folder`` made, with the user's pilots, link models and a step scenario naming them."""
    folder.mkdir()
    (folder / "my_pilots.py").write_text(PILOTS)
    (folder / "my_links.py").write_text(LINKS)
    pilot = 'kind = "python"\nfactory = "my_pilots.py:StepPilot"\nargs = { at_s = 15.0 }'
    (folder / "step.toml").write_text(_scenario_text(pilot))
    return folder


@pytest.fixture
def study(tmp_path: Path) -> Path:
    """A folder with the user's pilots, link models and a step scenario naming them."""
    return write_study(tmp_path / "study")


def test_a_pilot_named_in_the_scenario_flies_its_sticks_from_its_arguments(
    study: Path, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """The recorded stick is the step the file's pilot makes from the scenario's args (0.5
    from 15 s, held between the operator's samples), read from the file beside the scenario
    while the working directory is elsewhere; metrics.json records the file's SHA-256."""
    monkeypatch.chdir(tmp_path)
    result = run_scenario(load_scenario(str(study / "step.toml")))
    series = result.recorder.series()
    t, cmd_x = series["t_s"], series["cmd_x"]
    assert np.all(cmd_x[t < 15.0] == 0.0)
    assert np.all(cmd_x[t >= 15.5] == 0.5)  # an operator frame every ≈ 0.3 s on s100
    assert set(np.unique(cmd_x)) == {0.0, 0.5}
    assert result.metrics["signal_lag_reference"] == "operator samples"
    files = result.metrics["inputs"]["files"]
    pilot_file = str(study / "my_pilots.py")
    assert files[pilot_file] == hashlib.sha256(PILOTS.encode()).hexdigest()


def test_a_generator_taking_pilot_draws_from_the_runs_seed_one_seed_one_result(
    study: Path, tmp_path: Path
) -> None:
    """A factory with an ``rng`` parameter gets SeedSequence(seed)'s third child (the rule the
    docs state): the operator's successive sticks are that generator's uniform draws in order.
    Trials of consecutive seeds differ; the same seed writes the same bytes."""
    pilot = 'kind = "python"\nfactory = "my_pilots.py:NoisyPilot"'
    (study / "noisy.toml").write_text(_scenario_text(pilot))
    short = ["duration_s=12", "metrics.settle_s=1"]
    result = run_scenario(load_scenario(str(study / "noisy.toml"), short), seed=7)
    cmd_x = result.recorder.series()["cmd_x"]
    held = cmd_x[np.r_[0, np.flatnonzero(np.diff(cmd_x)) + 1]]  # each sample once, in order
    held = held[1:] if held[0] == 0.0 else held  # centred before the operator's first sample
    child = np.random.SeedSequence(7).spawn(3)[2]
    draws = np.random.default_rng(child).uniform(-1.0, 1.0, len(held))
    assert len(held) > 20
    np.testing.assert_array_equal(held, draws)

    scenario = load_scenario(str(study / "noisy.toml"), [*short, "trials=2"])
    out = tmp_path / "trials"
    out.mkdir()
    trials = run_trials(scenario, out, seed=7)
    assert trials.stopped is None
    first_trial = (out / "trial-1" / "series.csv").read_bytes()
    assert first_trial != (out / "trial-2" / "series.csv").read_bytes()
    again = tmp_path / "again"
    again.mkdir()
    run_trials(scenario, again, seed=7)
    assert (again / "trial-1" / "series.csv").read_bytes() == first_trial


def test_a_link_model_named_in_the_scenario_flies_as_the_presets_key_bit_for_bit(
    study: Path,
) -> None:
    """The second method: the file's constant 1400 bit/s model runs the scenario as
    ``link.bitrate_bps = 1400`` does, every recorded column equal; each 13-B order crosses in
    the intrinsic delay plus 8·13/1400 s; metrics.json names the model as the scenario did."""
    link = 'model = "my_links.py:constant"\nmodel_args = { bitrate_bps = 1400.0 }'
    pilot = 'kind = "python"\nfactory = "my_pilots.py:StepPilot"\nargs = { at_s = 15.0 }'
    (study / "slow.toml").write_text(_scenario_text(pilot, link))
    modelled = run_scenario(load_scenario(str(study / "slow.toml")))
    keyed = run_scenario(load_scenario(str(study / "step.toml"), ["link.bitrate_bps=1400"]))
    for column, values in keyed.recorder.series().items():
        np.testing.assert_array_equal(values, modelled.recorder.series()[column], column)
    crossed = [took for _, took, _ in order_crossings(modelled.recorder.trace)]
    expected = load_scenario("s100-teleop-v1").link.channel.intrinsic_delay_s + 8 * 13 / 1400
    assert len(crossed) > 40 and crossed == pytest.approx([expected] * len(crossed), abs=1e-7)
    assert modelled.metrics["inputs"]["link_model"] == f"{study / 'my_links.py'}:constant"
    assert modelled.metrics["inputs"]["link_model_args"] == {"bitrate_bps": 1400.0}
    assert "link_model" not in keyed.metrics["inputs"]


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as handle:
        return list(csv.DictReader(handle))


def test_a_sweep_over_a_scenario_of_ones_own_runs_its_pilot_and_model_in_its_workers(
    study: Path, tmp_path: Path
) -> None:
    """A sweep file in another folder sets the pilot and the link model by paths of its own
    folder; its spawned workers import them, and each row is the run of that point made here,
    outside the sweep (a second method)."""
    elsewhere = tmp_path / "sweeps"
    (elsewhere / "lib").mkdir(parents=True)
    (elsewhere / "lib" / "links.py").write_text(LINKS)
    (elsewhere / "lib" / "pilots.py").write_text(PILOTS)
    sweep_file = elsewhere / "rate.toml"
    sweep_file.write_text(
        textwrap.dedent(
            f"""\
            schema = 1
            id = "rate-v1"
            description = "bit rate under my pilot"
            scenario = "{study / "step.toml"}"
            seeds = 1
            metrics = ["command_lag_s.mean"]
            [set]
            "pilot.factory" = "lib/pilots.py:StepPilot"
            "link.model" = "lib/links.py:constant"
            "duration_s" = 20.0
            [grid]
            "link.model_args.bitrate_bps" = [1400.0, 700.0]
            """
        )
    )
    out = tmp_path / "out"
    summary = run_sweep(load_sweep(str(sweep_file)), out, workers=2)
    assert summary.failed == () and summary.ran == 2
    rows = _rows(out / "results.csv")
    lags = [float(row["command_lag_s.mean"]) for row in rows]
    for rate, lag in zip((1400.0, 700.0), lags, strict=True):
        overrides = [
            f"pilot.factory={elsewhere / 'lib' / 'pilots.py'}:StepPilot",
            f"link.model={elsewhere / 'lib' / 'links.py'}:constant",
            f"link.model_args={{bitrate_bps={rate}}}",
            "duration_s=20.0",
        ]
        direct = run_scenario(load_scenario(str(study / "step.toml"), overrides), seed=0)
        assert lag == direct.metrics["command_lag_s"]["mean"]
    assert lags[1] - lags[0] == pytest.approx(8 * 13 / 700 - 8 * 13 / 1400, abs=2e-3)


def test_the_live_console_links_through_the_scenarios_model(study: Path) -> None:
    """``testbed live`` on the scenario flies over the model it names, not the preset's."""
    link = 'model = "my_links.py:constant"\nmodel_args = { bitrate_bps = 700.0 }'
    (study / "live.toml").write_text(_scenario_text("", link))
    session = LiveSession(load_scenario(str(study / "live.toml")), Hub(), pilot=None)
    try:
        assert session.medium is not None
        assert type(session.medium.model).__name__ == "ConstantRate"
        assert session.medium.model.airtime_s(13, 0.0) == 8 * 13 / 700
    finally:
        session.vehicle.close()


CASES = {
    "nofile.py:StepPilot": "pilot.factory: no such file: /",
    "broken.py:StepPilot": "pilot.factory: importing broken.py failed: SyntaxError",
    "my_pilots.py:Missing": "pilot.factory: my_pilots.py has no 'Missing'",
    "my_pilots.py:np": "pilot.factory: 'np' in my_pilots.py is not callable",
    "no_such_module_anywhere:StepPilot": "ModuleNotFoundError",
    "my_pilots": "pilot.factory: expected 'FILE.py:NAME' or 'MODULE:NAME'",
}


@pytest.mark.parametrize(
    ("override", "message"),
    [
        *[(f"pilot.factory={target}", message) for target, message in CASES.items()],
        (
            "pilot.args={at_s=15.0, speed=1}",
            "StepPilot: got an unexpected",
        ),
        (
            "pilot.args={}",
            "pilot.args: my_pilots.py:StepPilot: missing a required",
        ),
        ("pilot.args={at_s=15.0, rng=1}", "pilot.args.rng: the run gives rng"),
        ("pilot.kind=scripted", "pilot.factory: only used when kind = 'python'"),
        (
            "link.model=my_links.py:ConstantRate",
            "link.model_args: my_links.py:ConstantRate: miss",
        ),
        ("link.model_args={bitrate_bps=1.0}", "link.model_args: only used with link.model"),
        ("pilot.factory=my_pilots.py:not_a_pilot", "pilot.args: my_pilots.py:not_a_pilot: got an"),
    ],
)
def test_a_wrong_name_or_argument_is_one_line_naming_the_key_and_exit_2(
    study: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    override: str,
    message: str,
) -> None:
    monkeypatch.chdir(study)
    (study / "broken.py").write_text("def broken(:\n")
    code = main(["run", "step.toml", "--set", override, "--out", str(study / "out"), "--no-plots"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("testbed: error: --set: ")
    assert message in err
    assert not (study / "out").exists()


def test_a_missing_file_is_named_where_it_was_looked_for_and_a_modules_own_missing_file_is_its(
    study: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A ``--set`` path is the working directory's, and the line names that resolved path (the
    pilot beside the scenario is not found from elsewhere); a module that exists but opens a
    missing data file as it is imported is its import failing, not a missing module file."""
    (study / "calibrated.py").write_text('open("calibration.json")\n')
    elsewhere = study.parent / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    cases = {
        "my_pilots.py:StepPilot": f"pilot.factory: no such file: {elsewhere / 'my_pilots.py'}\n",
        f"{study / 'calibrated.py'}:StepPilot": (
            f"pilot.factory: importing {study / 'calibrated.py'} failed: FileNotFoundError: "
            "[Errno 2] No such file or directory: 'calibration.json'\n"
        ),
    }
    for target, message in cases.items():
        scenario = str(study / "step.toml")
        code = main(["run", scenario, "--set", f"pilot.factory={target}", "--no-plots"])
        assert (code, capsys.readouterr().err) == (2, f"testbed: error: --set: {message}")


def test_what_the_factory_makes_is_checked_before_the_run_one_line_exit_2(
    study: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A factory that raises, or makes no pilot or no link model, stops the run before its
    first frame with one line naming the scenario file and the key."""
    monkeypatch.chdir(study)
    cases = [
        (
            ["pilot.factory=my_pilots.py:failing"],  # the scenario's pilot.args, named
            "pilot.factory (called with pilot.args = {'at_s': 15.0}): RuntimeError: no pilot at "
            "15.0",
        ),
        (
            ["pilot.factory=my_pilots.py:not_a_pilot", "pilot.args={}"],
            "pilot.factory: my_pilots.py:not_a_pilot made a int, not a pilot",
        ),
        (["link.model=my_pilots.py:failing"], "link.model: RuntimeError: no pilot at LinkConfig("),
        (
            ["link.model=my_pilots.py:StepPilot", "link.model_args={}"],
            "link.model: my_pilots.py:StepPilot made a StepPilot without airtime_s and error_model",
        ),
    ]
    for overrides, message in cases:
        args = [item for o in overrides for item in ("--set", o)]
        code = main(["run", "step.toml", *args, "--out", str(study / "out"), "--no-plots"])
        err = capsys.readouterr().err
        assert code == 2, err
        assert err.count("\n") == 1 and message in err, err
        assert not (study / "out").exists()


def test_the_readmes_scenario_tables_run_with_the_docs_link_model(tmp_path: Path) -> None:
    """The README's ``[pilot]``/``[link]`` tables as written, with docs/channel.md's
    ``halved_after`` (its example up to the probe) and a StepPilot taking the README's args:
    after 50 s each order's air time doubles (8·13/1900 s more on the way up)."""
    root = Path(__file__).resolve().parents[2]
    readme = (root / "README.md").read_text(encoding="utf-8")
    heading = "### Your own pilot, link model or control law in a scenario file"
    section = readme.split(heading, 1)[1]
    tables = section.split("```toml\n", 1)[1].split("```", 1)[0]
    channel = (root / "docs" / "channel.md").read_text(encoding="utf-8")
    example = channel.split("### A link model of your own", 1)[1].split("```python\n", 1)[1]
    (tmp_path / "my_links.py").write_text(example.split("\nconfig = ", 1)[0])
    no_default = PILOTS.replace("surge=0.5)", "surge)")  # the README's args must give it
    (tmp_path / "my_pilots.py").write_text(no_default)
    header = 'schema = 1\nid = "readme-v1"\ndescription = "the README\'s tables"\n'
    (tmp_path / "readme.toml").write_text(header + "duration_s = 80.0\n" + tables)
    # its pilot flies 0.5 stick ahead from 15 s: past the S100's range by 50 s, so no limit here
    result = run_scenario(load_scenario(str(tmp_path / "readme.toml"), ["link.max_range_m=inf"]))
    crossings = order_crossings(result.recorder.trace)
    delay = result.scenario.link.channel.intrinsic_delay_s
    air_s = [8 * size / 1900 for _, _, size in crossings]  # the preset's rate
    before = [took - air for (t_s, took, _), air in zip(crossings, air_s, strict=True) if t_s < 50]
    after = [took - air for (t_s, took, _), air in zip(crossings, air_s, strict=True) if t_s >= 50]
    assert before == pytest.approx([delay] * len(before), abs=1e-7)
    halved = [delay + air for (t_s, _, _), air in zip(crossings, air_s, strict=True) if t_s >= 50]
    assert len(after) > 20 and after == pytest.approx(halved, abs=1e-7)
    assert set(np.unique(result.recorder.series()["cmd_x"])) == {0.0, 0.5}


def test_a_hil_run_flies_the_scenarios_pilot_and_a_failing_factory_closes_the_ports(
    study: Path,
) -> None:
    """``testbed hil`` (run_hil) over emulated EvoLogics modems, both nodes here: the file's
    pilot steers (every order the vehicle took holds the step's stick, 0.5 as the order's
    signed byte carries it: round(0.5 · 127) / 127); a factory that raises is one line naming
    the key, and both ports are closed."""
    from testbed.channel import load_link_config
    from testbed.emulator.ptys import ModemEmulator
    from testbed.hil import PortSettings, open_endpoint
    from testbed.run.realtime import run_hil

    config = load_link_config("s2c", ["intrinsic_delay_s=0.05"])
    short = ["metrics.settle_s=1", "link.ipg=fixed", "link.ipg_s=0.3", "pilot.args={at_s=1.0}"]
    with ModemEmulator(config, seed=0, modem="evologics") as emulator:
        path_a, path_b = emulator.paths
        endpoints = {
            "operator": open_endpoint(PortSettings(path_a, "evologics", "operator")),
            "vehicle": open_endpoint(PortSettings(path_b, "evologics", "vehicle")),
        }
        scenario = load_scenario(str(study / "step.toml"), short)
        result = run_hil(scenario, endpoints, duration_s=4.0, modem="evologics")
        series = result.recorder.series()
        taken = series["rx_x"][series["rx_x"] != 0.0]
        assert len(taken) > 0 and set(np.unique(taken)) == {64 / 127}  # 0.5 on the wire's int8
        assert set(np.unique(series["cmd_x"])) == {0.0, 0.5}
        assert result.metrics["signal_lag_reference"] == "operator samples"

        endpoints = {
            "operator": open_endpoint(PortSettings(path_a, "evologics", "operator")),
            "vehicle": open_endpoint(PortSettings(path_b, "evologics", "vehicle")),
        }
        factory = f"pilot.factory={study / 'my_pilots.py'}:failing"
        failing = load_scenario(str(study / "step.toml"), [*short, factory])
        with pytest.raises(
            ConfigError,
            match=r"--set: pilot\.args, pilot\.factory \(called with pilot\.args = .*\): Runtime",
        ):
            run_hil(failing, endpoints, duration_s=4.0, modem="evologics")
        alive = [t.name for t in threading.enumerate() if t.name.startswith("serial:")]
        assert alive == []  # each port's reader and writer threads stopped: the ports closed
