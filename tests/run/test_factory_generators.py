"""Generators of the run's seed for link models and control laws of the user's own
(:func:`testbed.run.plugin_calls.factory_generator`): a factory with a parameter named ``rng`` is
given the generator of a fixed child of ``SeedSequence(seed)`` (the docs' rule: 3 for
``link.model``, 4 for ``vehicle.control.depth``, 5 for ``vehicle.control.attitude``), the same
in every run mode, so one seed makes one result and trials of consecutive seeds draw
differently; giving it changes no other draw; an ``rng`` in the arguments is refused.

Truths: ``numpy``'s own ``SeedSequence(seed).spawn(n)[k]`` draws (the documented children),
the bytes of a second run of the same seed, and a run whose factory takes no ``rng``.
"""

from __future__ import annotations

import socket
import textwrap
import threading
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from testbed.cli.main import main
from testbed.config import ConfigError
from testbed.run.runner import run_scenario
from testbed.run.scenario import load_scenario
from testbed.run.trials import run_trials
from testbed.sweep import load_sweep, run_sweep

NOISY = '''
from dataclasses import dataclass

from testbed.channel import StandardLink


class NoisyDepth:
    """A P depth hold, plus a force noise of ``sigma_n`` [N] drawn from its generator at each
    frame it flies (none drawn when ``sigma_n`` is 0)."""

    def __init__(self, rng, kp=40.0, sigma_n=0.0):
        self.rng, self.kp, self.sigma_n = rng, kp, sigma_n

    def reset(self):
        pass

    def update(self, target, depth, imu, dt_s):
        down = self.kp * (target.depth_m - depth.depth_m)
        if self.sigma_n:
            down += self.sigma_n * self.rng.standard_normal()
        w, x, y, z = imu.quaternion_wxyz
        return (
            down * 2.0 * (x * z - w * y),
            down * 2.0 * (y * z + w * x),
            down * (w * w - x * x - y * y + z * z),
        )


class PlainDepth(NoisyDepth):
    """The same P hold, its factory without an ``rng`` parameter."""

    def __init__(self, kp=40.0):
        super().__init__(None, kp)


@dataclass
class Jittery:
    """The preset's link, each transmission's air time stretched by up to ``jitter`` (a
    uniform draw from the model's generator)."""

    base: StandardLink
    rng: object
    jitter: float

    def airtime_s(self, size_bytes, t_s):
        return self.base.airtime_s(size_bytes, t_s) * (1.0 + self.jitter * self.rng.random())

    def error_model(self, rng):
        return self.base.error_model(rng)


def jittery(config, rng, jitter=0.5):
    return Jittery(StandardLink(config), rng, jitter)


def reveal_law(rng):
    raise RuntimeError(f"first draw {rng.random()!r}")


def reveal_model(config, rng):
    raise RuntimeError(f"first draw {rng.random()!r}")
'''

SCENARIO = """\
schema = 1
id = "noisy-v1"
description = "centred sticks in depth hold, a law of one's own"
duration_s = 12.0
[link]
preset = "s100"
ber = 1e-3
[pilot]
kind = "scripted"
[metrics]
settle_s = 2.0
"""

CHILDREN = {"link.model": 3, "vehicle.control.depth": 4, "vehicle.control.attitude": 5}
"""The documented child of ``SeedSequence(seed)`` each factory's generator is."""


def first_draw(seed: int, key: str) -> str:
    """``repr`` of the first ``random()`` of the generator the docs give ``key``'s factory."""
    child = CHILDREN[key]
    return repr(
        np.random.default_rng(np.random.SeedSequence(seed).spawn(child + 1)[child]).random()
    )


@pytest.fixture
def study(tmp_path: Path) -> Path:
    """A folder with the user's noisy law and model and a scenario for them."""
    folder = tmp_path / "study"
    folder.mkdir()
    (folder / "noisy.py").write_text(NOISY)
    (folder / "still.toml").write_text(SCENARIO)
    return folder


def _law(study: Path, name: str, key: str = "depth") -> str:
    return f"vehicle.control.{key}={study / 'noisy.py'}:{name}"


def test_the_documented_children_are_numpys_spawn_and_leave_the_first_two_as_they_were() -> None:
    """The premise of the rule: ``spawn(6)``'s children 0–2 are ``spawn(2)``'s and
    ``spawn(3)``'s (the link's, the vehicle's, a pilot's), so children 3–5 draw beside them."""
    for seed in (0, 7, 2**40):
        six = np.random.SeedSequence(seed).spawn(6)
        for fewer in (2, 3):
            for a, b in zip(six, np.random.SeedSequence(seed).spawn(fewer), strict=False):
                np.testing.assert_array_equal(a.generate_state(8), b.generate_state(8))


def test_a_noisy_law_one_seed_one_result_consecutive_trials_differ(
    study: Path, tmp_path: Path
) -> None:
    """A depth law drawing a force noise from its generator: trials of seeds 7 and 8 differ,
    the same seed writes the same bytes again; the noise is drawn (a law of σ = 0 flies
    otherwise), and a law taking ``rng`` but drawing nothing flies byte for byte as the same
    law whose factory takes none: the link's and the vehicle's draws are unchanged."""
    noisy = [_law(study, "NoisyDepth"), "vehicle.control.depth_args={sigma_n=5.0}", "trials=2"]
    scenario = load_scenario(str(study / "still.toml"), noisy)
    first, again = tmp_path / "first", tmp_path / "again"
    for out in (first, again):
        out.mkdir()
        assert run_trials(scenario, out, seed=7).stopped is None
    one = (first / "trial-1" / "series.csv").read_bytes()
    assert one != (first / "trial-2" / "series.csv").read_bytes()
    for trial in ("trial-1", "trial-2"):
        for name in ("series.csv", "events.csv"):
            assert (first / trial / name).read_bytes() == (again / trial / name).read_bytes()

    def series(*overrides: str) -> dict[str, np.ndarray]:
        return run_scenario(
            load_scenario(str(study / "still.toml"), overrides), seed=7
        ).recorder.series()

    quiet = series(_law(study, "NoisyDepth"))
    plain = series(_law(study, "PlainDepth"))
    loud = series(*noisy[:2])
    for column, values in plain.items():
        np.testing.assert_array_equal(values, quiet[column], column)
    assert not np.array_equal(loud["down_m"], quiet["down_m"])


def test_a_link_model_drawing_air_times_one_seed_one_result_consecutive_seeds_differ(
    study: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``testbed run`` over a model whose air times draw from its generator: seed 7 twice
    writes the same series.csv and events.csv, seed 8 another."""
    monkeypatch.chdir(study)
    model = ["--set", f"link.model={study / 'noisy.py'}:jittery"]

    def run(seed: int, name: str) -> Path:
        out = tmp_path / name
        argv = ["run", "still.toml", *model, "--seed", str(seed), "--out", str(out), "--no-plots"]
        assert main(argv) == 0
        return out

    a, b, c = run(7, "a"), run(7, "b"), run(8, "c")
    for name in ("series.csv", "events.csv"):
        assert (a / name).read_bytes() == (b / name).read_bytes()
    assert (a / "events.csv").read_bytes() != (c / "events.csv").read_bytes()


@pytest.fixture
def udp_link() -> Iterator[object]:
    """A ground-station link (``udpout`` to a socket of the test's own on 127.0.0.1)."""
    from testbed.mavlink.links import UdpLink

    peer = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    peer.bind(("127.0.0.1", 0))
    port = peer.getsockname()[1]
    link = UdpLink(f"udpout:127.0.0.1:{port}", "127.0.0.1", port, listen=False)
    try:
        yield link
    finally:
        link.close()
        peer.close()


LAW_MODES = ["run", "trials", "live", "mavlink", "mavlink-node", "gateway", "hil"]
MODEL_MODES = ["run", "trials", "live", "gateway"]
"""The modes that make a law, and those that make a link model (a simulated link)."""


@pytest.mark.parametrize(
    ("key", "mode"),
    [
        *[(key, mode) for key in CHILDREN if key != "link.model" for mode in LAW_MODES],
        *[("link.model", mode) for mode in MODEL_MODES],
    ],
)
def test_every_run_mode_gives_the_factory_its_child_of_the_runs_seed(
    study: Path, tmp_path: Path, udp_link: object, mode: str, key: str
) -> None:
    """A factory that raises with its generator's first draw: each mode that makes it (the
    link model only where the scenario's link is simulated) shows the draw of the documented
    child of seed 7."""
    import simpy

    from testbed.channel import Trace
    from testbed.live.hub import Hub
    from testbed.live.session import LiveSession
    from testbed.run.mavlink_gateway import run_gateway
    from testbed.run.mavlink_run import MavlinkVehicleNode, run_mavlink
    from testbed.run.recorder import Recorder

    target = f"{study / 'noisy.py'}:{'reveal_model' if key == 'link.model' else 'reveal_law'}"
    scenario = load_scenario(str(study / "still.toml"), [f"{key}={target}"])
    with pytest.raises(ConfigError) as raised:
        if mode == "run":
            run_scenario(scenario, seed=7)
        elif mode == "trials":
            run_trials(scenario, tmp_path, seed=7)
        elif mode == "live":
            LiveSession(scenario, Hub(), seed=7, pilot=None)
        elif mode == "mavlink":
            run_mavlink(scenario, [udp_link], seed=7, duration_s=1.0)  # type: ignore[list-item]
        elif mode == "mavlink-node":
            rng = np.random.default_rng(0)
            MavlinkVehicleNode(simpy.Environment(), scenario, rng, [], Recorder(Trace()), seed=7)
        elif mode == "gateway":
            run_gateway(scenario, [udp_link], seed=7, duration_s=1.0)  # type: ignore[list-item]
        else:
            _run_hil_with_seed_7(scenario)
    assert f"RuntimeError: first draw {first_draw(7, key)}" in str(raised.value)


def _run_hil_with_seed_7(scenario: object) -> None:
    """``run_hil`` of ``scenario`` at seed 7 over emulated EvoLogics modems."""
    from testbed.channel import load_link_config
    from testbed.emulator.ptys import ModemEmulator
    from testbed.hil import PortSettings, open_endpoint
    from testbed.run.realtime import run_hil

    config = load_link_config("s2c")
    with ModemEmulator(config, seed=0, modem="evologics") as emulator:
        path_a, path_b = emulator.paths
        endpoints = {
            "operator": open_endpoint(PortSettings(path_a, "evologics", "operator")),
            "vehicle": open_endpoint(PortSettings(path_b, "evologics", "vehicle")),
        }
        try:
            run_hil(scenario, endpoints, seed=7, duration_s=4.0, modem="evologics")  # type: ignore[arg-type]
        finally:
            alive = [t.name for t in threading.enumerate() if t.name.startswith("serial:")]
            assert alive == []  # the failing factory closed both ports


@pytest.mark.parametrize(
    "argv",
    [
        ["run", "still.toml", "--seed", "7", "--no-plots", "--out", "out"],
        ["live", "still.toml", "--seed", "7", "--out", "out"],
        ["mavlink", "still.toml", "--seed", "7", "--out", "out"],
    ],
    ids=["run", "live", "mavlink"],
)
def test_the_command_lines_checks_make_the_law_of_their_seed(
    study: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    argv: list[str],
) -> None:
    """``testbed run``, and the checks ``testbed live`` and ``testbed mavlink`` make before a
    port opens, call the law's factory with the generator of ``--seed``: one line, exit 2."""
    monkeypatch.chdir(study)
    code = main([*argv, "--set", _law(study, "reveal_law")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert f"RuntimeError: first draw {first_draw(7, 'vehicle.control.depth')}" in err
    assert not (study / "out").exists()


def test_the_link_probe_gives_a_model_its_child_of_seed(
    study: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``testbed link --model`` makes the model with the generator of ``--seed`` as a run does;
    a ``jittery`` probe's latencies are its own per seed."""
    code = main(["link", "--model", f"{study / 'noisy.py'}:reveal_model", "--seed", "7"])
    err = capsys.readouterr().err
    assert code == 2 and f"RuntimeError: first draw {first_draw(7, 'link.model')}" in err
    outputs = []
    for seed in (7, 7, 8):
        argv = ["link", "--model", f"{study / 'noisy.py'}:jittery", "--frames", "50"]
        assert main([*argv, "--seed", str(seed), "--json"]) == 0
        outputs.append(capsys.readouterr().out.split('"wall_s"')[0])
    assert outputs[0] == outputs[1] != outputs[2]


@pytest.mark.parametrize("dask", [None, "local"], ids=["pool", "dask"])
def test_sweep_workers_give_the_factory_its_child_of_each_seed(
    study: Path, tmp_path: Path, dask: str | None
) -> None:
    """A sweep of seeds 7 and 8 on the process pool and on a local Dask cluster: each failed
    run's error shows the draw of its own seed's child."""
    sweep_file = tmp_path / "seeds.toml"
    sweep_file.write_text(
        textwrap.dedent(
            f"""\
            schema = 1
            id = "seeds-v1"
            description = "a law's generator per seed"
            scenario = "{study / "still.toml"}"
            seeds = [7, 8]
            metrics = ["depth_error_m.mean"]
            [set]
            "vehicle.control.depth" = "{study / "noisy.py"}:reveal_law"
            [grid]
            "duration_s" = [12.0]
            """
        )
    )
    summary = run_sweep(load_sweep(str(sweep_file)), tmp_path / "out", workers=2, dask=dask)
    errors = {seed: error for _, seed, _, error in summary.failed}
    assert sorted(errors) == [7, 8]
    for seed, error in errors.items():
        assert f"first draw {first_draw(seed, 'vehicle.control.depth')}" in error


REFUSED = {
    "link.model_args": ("noisy.py:jittery", "{ rng = 1 }"),
    "vehicle.control.depth_args": ("noisy.py:NoisyDepth", "{ rng = 1 }"),
    "vehicle.control.attitude_args": ("noisy.py:PlainDepth", "{ rng = 1, kp = 2.0 }"),
}
"""An arguments key, its factory and arguments that hold ``rng`` (``PlainDepth`` takes
none)."""


@pytest.mark.parametrize("key", sorted(REFUSED))
def test_an_rng_in_a_factorys_arguments_is_one_line_naming_the_key_exit_2(
    study: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], key: str
) -> None:
    """The run gives ``rng``; arguments holding it are refused at load, in a scenario file as
    in ``--set``, whether or not the factory takes one."""
    monkeypatch.chdir(study)
    target, args = REFUSED[key]
    table, args_name = key.rsplit(".", 1)
    name = args_name.removesuffix("_args")
    lines = f'{name} = "{target}"\n{args_name} = {args}\n'
    if table == "link":
        text = SCENARIO.replace("[link]\n", f"[link]\n{lines}")
    else:
        text = SCENARIO.replace("[pilot]", f"[{table}]\n{lines}[pilot]")
    (study / "given.toml").write_text(text)
    overrides = ["--set", f"{table}.{name}={target}", "--set", f"{key}={args}"]
    for argv, where in (
        (["run", "given.toml"], "given.toml"),
        (["run", "still.toml", *overrides], "--set"),
    ):
        code = main([*argv, "--out", str(study / "out"), "--no-plots"])
        err = capsys.readouterr().err
        assert code == 2 and err.count("\n") == 1, err
        assert err.startswith(f"testbed: error: {where}"), err
        assert f"{key}.rng: the run gives rng (its seed's generator)" in err, err
        assert not (study / "out").exists()


def test_an_rng_in_the_link_probes_model_arguments_is_one_line_exit_2(
    study: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["link", "--model", f"{study / 'noisy.py'}:jittery", "--model-args", "{rng=1}"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--model-args.rng: the run gives rng" in err, err
