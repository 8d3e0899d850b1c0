"""The real-time window of tests/run/test_realtime.py: its rig, run once for all its tests.

:func:`run_window` runs, for about 20 s at once:

* in this process, ``run_hil`` with both nodes on the two ports of a modem emulator (s100
  preset, BER 0), the operator's port unplugged from 8 s to 10 s (a port factory that fails,
  :class:`Unplug`), and line noise (:data:`NOISE`) sent when it comes back;
* in two child processes, ``testbed hil vehicle`` and ``testbed hil operator`` on the two ports
  of a second emulator (two computers);
* in a third child, ``testbed hil --operator-port … --vehicle-port …`` on a third emulator
  (the one-computer CLI path);
* in this process, a timing probe (:class:`~tests.run.emulated_link.LinkProbe`) on a fourth
  emulator;
* the four emulators in a child process of their own (:data:`EMULATORS`), as real modems are
  outside the computer, reporting their counters and scheduler lateness when they stop.

The run in this process starts once every child has said its session runs (a 2-core machine
importing numpy and pybullet and loading compiled kernels in three children would otherwise
starve its first seconds). What it produced, with the allowances a loaded host adds
(:meth:`Window.host_s`), is a :class:`Window`.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import serial

import testbed
from testbed.channel import LinkConfig, load_link_config
from testbed.hil import PortSettings, open_endpoint
from testbed.run.outputs import write_run
from testbed.run.realtime import run_hil
from testbed.run.runner import RunResult
from testbed.run.scenario import load_scenario
from tests.run.emulated_link import CRLF, IDLE_S, LinkProbe, crossing_s

DURATION_S = 20.0
PAIR_DURATION_S = 12.0
IPG_S = 0.594
"""The s100 scenario's gap between orders of 13 B [s] (checked against the trace)."""
CLI_DURATION_S = 8.0
"""The one-computer CLI child's run [s]: inside the window, so it costs no time."""
UNPLUG_S = (8.0, 10.0)
"""Operator port unplugged [s after the run is started]."""


class Unplug:
    """When the operator's modem is unplugged, on the monotonic clock [s].

    It is out from ``start_s`` for its planned length, and, if the transport first touches the
    port only after that, for the planned length from that touch: a loaded host can hold the
    transport's threads off the port for longer than the window, and an unplug nobody saw
    would test nothing (no port error, no orders dropped, no line noise). ``end_s`` is then
    moved, so the window recorded is the one the port was really out. No order can cross in
    between: any write would have been the touch."""

    def __init__(self) -> None:
        self.start_s = math.inf
        self.end_s = math.inf
        self.noticed = False

    def place(self, start_s: float, end_s: float) -> None:
        self.start_s, self.end_s = start_s, end_s

    def check(self) -> None:
        """Raise as an unplugged USB modem does, if it is out now."""
        now = time.monotonic()
        if now < self.start_s:
            return
        if not self.noticed:
            self.noticed = True
            if now >= self.end_s:
                self.end_s = now + (self.end_s - self.start_s)
        if now < self.end_s:
            raise serial.SerialException("device disconnected")


class UnpluggedPort:
    """A pyserial port that fails (as an unplugged USB modem does) while ``unplug`` is out."""

    def __init__(self, url: str, unplug: Unplug) -> None:
        self._unplug = unplug
        self._port = serial.Serial(url, timeout=0.05, write_timeout=2.0)

    def read(self, size: int = 1) -> bytes:
        self._unplug.check()
        return bytes(self._port.read(size))

    def write(self, data: bytes) -> int | None:
        self._unplug.check()
        written: int | None = self._port.write(data)
        return written

    @property
    def in_waiting(self) -> int:
        self._unplug.check()
        return int(self._port.in_waiting)

    def close(self) -> None:
        self._port.close()


NOISE = b"\x00\xffline noise\x00"
"""What the operator's modem blurts out when it is plugged back in (no 0x55, no ``+++``)."""


def _unplugged_factory(
    url: str, unplug: Unplug, attempts: list[tuple[float, bool]]
) -> Callable[[], UnpluggedPort]:
    """A port factory for the transport that fails while ``unplug`` is out (placed later);
    each call is appended to ``attempts`` as (monotonic instant, opened)."""
    opened: list[UnpluggedPort] = []

    def factory() -> UnpluggedPort:
        try:
            unplug.check()
        except serial.SerialException:
            attempts.append((time.monotonic(), False))
            raise
        attempts.append((time.monotonic(), True))
        port = UnpluggedPort(url, unplug)
        if opened:  # plugged back in: line noise goes out before any frame
            port.write(NOISE)
        opened.append(port)
        return port

    return factory


def _python(args: list[str], cwd: Path) -> subprocess.Popen[str]:
    """``python ARGS`` in a child process, on this checkout's package."""
    env = dict(os.environ, PYTHONPATH=str(Path(testbed.__file__).resolve().parents[1]))
    return subprocess.Popen(
        [sys.executable, *args],
        cwd=cwd,
        env=env,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


NO_SURFACING = ("vehicle.failsafe.surface_after_s=3600",)
"""The window's runs keep the 1-s hold but never surface: a loaded host can stall the orders
for seconds, and a surfacing vehicle disarms, which would end the run's story (armed, held,
let go) for a reason the tests do not examine. The hold rule is what they check."""


def _cli(args: list[str], cwd: Path) -> subprocess.Popen[str]:
    """``python -m testbed ARGS`` in a child process, on this checkout's package."""
    return _python(["-m", "testbed", *args], cwd)


EMULATORS = """
import dataclasses, json, sys
from testbed.channel import load_link_config
from testbed.emulator.ptys import ModemEmulator

config = load_link_config("s100", ["ber=0"])
emulators = [ModemEmulator(config, seed=seed, idle_s=float(sys.argv[1])) for seed in range(4)]
for emulator in emulators:
    emulator.start()
print(json.dumps([emulator.paths for emulator in emulators]), flush=True)
sys.stdin.read()  # the test closes our stdin once every program has closed its ports
for emulator in emulators:
    emulator.close()
report = [
    {
        "error": None if emulator.error is None else repr(emulator.error),
        "ports": [dataclasses.asdict(counters) for counters in emulator.counters],
        "modems": [dataclasses.asdict(modem.counters) for modem in emulator.modems],
        "scheduler_lateness_ms": emulator.scheduler_lateness_ms,
    }
    for emulator in emulators
]
print(json.dumps(report), flush=True)
"""
"""The four modem emulators (single run, two computers, one-computer CLI, timing probe) in a
process of their own, as real modems are outside the computer: prints their port paths, runs
until its stdin closes, then prints each one's port and modem counters and scheduler lateness
(``ModemEmulator.scheduler_lateness_ms``) as JSON."""


@dataclass
class Window:
    """What the real-time window produced."""

    config: LinkConfig
    single: RunResult
    single_dir: Path
    unplug_env_s: tuple[tuple[float, float], tuple[float, float]]
    """Earliest and latest instants of the unplug's start and of its end on the run's clock
    [s]: the clock started after ``run_hil`` was called and before the run's ``wall_s``
    ended at its return."""
    pair_dirs: dict[str, Path]
    cli_dir: Path
    outputs: dict[str, tuple[int, str, str]]
    emulators: list[dict[str, Any]]
    """Per emulator (single run, two computers, CLI, probe): ``ports`` and ``modems`` counters
    (A then B) and ``scheduler_lateness_ms``."""
    probe: LinkProbe
    port_opens: list[tuple[float, bool]]
    """Each call of the operator port's factory: (monotonic instant, opened)."""
    unplug_monotonic: tuple[float, float]
    """The unplug window on the monotonic clock, as the port was really out (:class:`Unplug`)
    [s]."""
    clock_monotonic: tuple[float, float]
    """Earliest and latest monotonic instant at which the single run's clock started [s]."""

    @property
    def noise_bytes(self) -> int:
        """Line noise the operator's port sent: :data:`NOISE` at each reopen the factory made
        (one, unless a loaded host saw the reopened port fail again) [B]."""
        return len(NOISE) * sum(ok for _, ok in self.port_opens[1:])

    @property
    def noise_lost_bytes(self) -> int:
        """Line noise lost on the air [B]: the single run's emulator lost whole orders, and
        with them the noise of any burst that collided (the noise goes out just before the
        first order on the reopened port, so a collision can take both). The bytes the
        operator's port took in less those the vehicle's gave out are k orders plus b noises,
        b ≤ the noises written; 13·b mod 15 tells b."""
        ports = self.emulators[0]["ports"]
        lost = ports[0]["bytes_in"] - ports[1]["bytes_out"]
        for noises in range(self.noise_bytes // len(NOISE) + 1):
            rest = lost - noises * len(NOISE)
            if rest >= 0 and rest % (13 + CRLF) == 0:
                return noises * len(NOISE)
        raise AssertionError(f"{lost} B lost on the air: not whole orders and noise")

    @property
    def noise_crossed_bytes(self) -> int:
        """Line noise that reached the vehicle's port [B]: written, less lost on the air."""
        return self.noise_bytes - self.noise_lost_bytes

    def lateness_s(self, key: str) -> float:
        """The run's measured scheduler lateness (``hil.scheduler_lateness_ms[key]``) [s]."""
        return max(0.0, float(self.single.metrics["hil"]["scheduler_lateness_ms"][key]) / 1e3)

    def host_s(self, which: str) -> float:
        """What a loaded host adds to one crossing of the link, from this run's measurements
        [s]: ``"p95"`` is the probe's 95th-percentile excess plus the run's p95 lateness (the
        sending step's stamp is that much early); ``"max"`` the longest stall the probe can have
        met (:meth:`LinkProbe.worst_s`) plus the run's largest lateness. A frame exceeds the p95
        allowance with probability ≤ 5 % + 5 % (union bound), so a median of many exceeds it
        never; no frame exceeds the max allowance unless its stall was on a thread the probe's
        path does not share. Each also adds the same statistic of the lateness the run's own
        emulator measured on its two threads (:meth:`emulator_s`): the probe crosses another
        emulator in that process, and a stall can fall between its crossings; and of the run's
        own transport threads (:meth:`transports_s`), which the probe's path does not share."""
        own = self.emulator_s(which) + self.transports_s(which)
        if which == "p95":
            return self.probe.quantile(0.95) + self.lateness_s("p95") + own
        return self.probe.worst_s() + self.lateness_s("max") + own

    def transports_s(self, key: str) -> float:
        """How long the host held up the single run's transport threads [s]: statistic ``key``
        of each endpoint's reader and writer lateness (``thread_lateness_ms``), the largest
        of the operator's and the vehicle's per thread, the reader's plus the writer's (an order
        crosses the operator's writer and the vehicle's reader; a reply the reverse)."""
        endpoints = self.single.metrics["hil"]["endpoints"].values()
        total = 0.0
        for thread in ("reader", "writer"):
            values = [e["thread_lateness_ms"][thread][key] for e in endpoints]
            total += max((v for v in values if v is not None and not math.isnan(v)), default=0)
        return max(0.0, total) / 1e3

    def describe(self) -> str:
        """The measured allowances, for an assertion's message (a failure on a loaded machine
        must say which measurement fell short)."""
        return (
            f"probe p95/worst {self.probe.quantile(0.95):.3f}/{self.probe.worst_s():.3f} s "
            f"({len(self.probe.excess_s)} crossings, {self.probe.lost} lost), run lateness "
            f"p95/max {self.lateness_s('p95'):.3f}/{self.lateness_s('max'):.3f} s, emulator "
            f"p95/max {self.emulator_s('p95'):.3f}/{self.emulator_s('max'):.3f} s, transports "
            f"p95/max {self.transports_s('p95'):.3f}/{self.transports_s('max'):.3f} s"
        )

    def emulator_s(self, key: str, index: int = 0) -> float:
        """Scheduler lateness emulator ``index`` (0: the single run's) measured [s]: its
        reader's (a burst enters the link that late, or is picked up that late when the reader
        is held up: ``reader_stall``) plus its simulation thread's (a delivery is written that
        late), statistic ``key`` of each; 0 for a thread with no sample."""
        late = self.emulators[index]["scheduler_lateness_ms"]
        values = [late[thread][key] for thread in ("reader", "reader_stall", "simulation")]
        return sum(0.0 if v is None or math.isnan(v) else max(0.0, v) for v in values) / 1e3


def run_window(root: Path) -> Iterator[Window]:
    """Run the window in folder ``root`` (the children's outputs go there); yield what it
    produced once every program has stopped."""
    config = load_link_config("s100", ["ber=0"])
    scenario = load_scenario("s100-teleop-v1", NO_SURFACING)
    emulator = _python(["-c", EMULATORS, str(IDLE_S)], root)
    assert emulator.stdout is not None
    single, pair, third, probe_ports = json.loads(emulator.stdout.readline())
    common = ["--modem", "s100", "--no-plots", "--duration", str(PAIR_DURATION_S)]
    common += [f"--set={NO_SURFACING[0]}"]
    vehicle_args = ["hil", "vehicle", "--port", pair[1], "--out", "vehicle"]
    operator_args = ["hil", "operator", "--port", pair[0], "--out", "operator"]
    one_computer = ["hil", "--operator-port", third[0], "--vehicle-port", third[1]]
    one_computer += ["--set", "metrics.settle_s=1", "--duration", str(CLI_DURATION_S)]
    one_computer += [f"--set={NO_SURFACING[0]}"]
    children = {
        "vehicle": _cli([*vehicle_args, *common], root),
        "operator": _cli([*operator_args, *common], root),
        "cli": _cli([*one_computer, "--out", "cli"], root),
    }
    probe = LinkProbe(probe_ports, config)
    try:
        for child in children.values():  # each says when its nodes are built and its clock
            assert child.stderr is not None  # starts: imports and compiled kernels are loaded
            child.stderr.readline()
        # the unplug is placed on the run's clock: armed when the run starts it (a loaded host
        # may take seconds to build the nodes), never before
        unplug = Unplug()

        def arm_unplug() -> None:
            now = time.monotonic()
            unplug.place(now + UNPLUG_S[0], now + UNPLUG_S[1])

        attempts: list[tuple[float, bool]] = []
        operator = open_endpoint(
            PortSettings(single[0], "s100", "operator"),
            port_factory=_unplugged_factory(single[0], unplug, attempts),
            backoff_initial_s=0.05,
            backoff_max_s=0.25,
        )
        vehicle = open_endpoint(PortSettings(single[1], "s100", "vehicle"))
        with probe:
            called = time.monotonic()
            result = run_hil(
                scenario,
                {"operator": operator, "vehicle": vehicle},
                duration_s=DURATION_S,
                modem="s100",
                on_start=arm_unplug,
            )
            clock_started = (called, time.monotonic() - result.metrics["wall_s"])
        single_dir = root / "single"
        write_run(result, single_dir)
    finally:
        outputs = {}
        for name, child in children.items():
            out, err = child.communicate(timeout=60)
            outputs[name] = (child.returncode, out, err)
        out, err = emulator.communicate(timeout=60)  # closes its stdin: it reports and exits
    assert emulator.returncode == 0, err
    reports: list[dict[str, Any]] = json.loads(out.splitlines()[-1])
    assert [report["error"] for report in reports] == [None] * 4
    assert len(probe.excess_s) >= 5  # ≈ 80 on an idle machine; few on a loaded one (its p95 is
    # then close to its max: the allowance only grows)
    yield Window(
        config,
        result,
        single_dir,
        (  # (earliest, latest) of the start, then of the end
            (unplug.start_s - clock_started[1], unplug.start_s - clock_started[0]),
            (unplug.end_s - clock_started[1], unplug.end_s - clock_started[0]),
        ),
        {"vehicle": root / "vehicle", "operator": root / "operator"},
        root / "cli",
        outputs,
        reports,
        probe,
        attempts,
        (unplug.start_s, unplug.end_s),
        clock_started,
    )


def read_metrics(path: Path) -> dict[str, Any]:
    data: dict[str, Any] = json.loads((path / "metrics.json").read_text(encoding="utf-8"))
    return data


def thread_lateness_ms(endpoint: dict[str, Any], thread: str) -> float:
    """An endpoint's largest measured ``thread`` (reader or writer) lateness [ms], 0 if none."""
    value = endpoint["thread_lateness_ms"][thread]["max"]
    return 0.0 if value is None or math.isnan(value) else float(value)


def unhanded_frames(window: Window, bytes_in: int, garbage: int, frames: int, size: int) -> int:
    """Whole frames an endpoint read but its node had not been handed when the run ended (read
    bytes = frames handed over + these + garbage): at most those that can still be on their way
    at the end, one per IPG over a crossing and the worst measured host delay."""
    extra = (bytes_in - garbage) / size - frames
    assert extra.is_integer()
    in_flight = math.ceil((crossing_s(window.config, size) + window.host_s("max")) / IPG_S)
    assert 0 <= extra <= in_flight
    return int(extra)
