"""``testbed.run.realtime``: the nodes in real time over serial ports, end to end over the emulator.

One real-time window of about 20 s runs three things at once (the default run's only long
test, shared by the tests below through a module fixture):

* in this process, ``run_hil`` with both nodes on the two ports of a modem emulator (s100
  preset, BER 0), the operator's port unplugged from 8 s to 10 s (a port factory that fails),
  and line noise sent when it comes back;
* in two child processes, ``testbed hil vehicle`` and ``testbed hil operator`` on the two ports
  of a second emulator (two computers);
* in a third child, ``testbed hil --operator-port … --vehicle-port …`` on a third emulator
  (the one-computer CLI path).

The run in this process starts once every child has said its port is open (a 2-core machine
importing numpy and pybullet in three children would otherwise starve its first seconds).

Truth is the channel model's closed form: a frame written on an emulator port arrives after
the idle gap that closes the burst (3 ms), the intrinsic delay and the airtime of the frame and
its CR LF (REFERENCE §1.10: every S100 packet ends in CR LF). Fast unit tests of the frame
ledger and the modem shape use a plain simpy environment and fake endpoints.
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

import numpy as np
import pytest
import serial
import simpy

import testbed
from testbed.channel import Delivery, EventKind, LinkConfig, Trace, load_link_config
from testbed.emulator.ptys import ModemEmulator
from testbed.hil import PortSettings, open_endpoint
from testbed.protocol import Frame, encode_frame
from testbed.run.realtime import FrameLedger, HilModem, run_hil
from testbed.run.runner import RunResult, write_outputs
from testbed.run.scenario import load_scenario

IDLE_S = 0.003
"""Emulator idle gap that closes a burst [s] (its default, set explicitly)."""
DURATION_S = 20.0
PAIR_DURATION_S = 12.0
UNPLUG_S = (8.0, 10.0)
"""Operator port unplugged [s after the run is started]."""
CRLF = 2
"""The S100 adapter's CR LF after each frame [B]."""


# -- fast unit tests --------------------------------------------------------------------------


def test_ledger_numbers_frames_in_send_order_and_counts_skipped_ones_lost() -> None:
    ledger = FrameLedger()
    ids = [ledger.record_sent("operator", bytes([k]), 0.1 * k) for k in range(3)]
    ids.append(ledger.record_sent("vehicle", b"reply", 0.5))
    assert ids == [0, 1, 2, 3]  # one sequence for both senders, like the medium's
    assert ledger.match("operator", b"\x01") == (1, 0.1 * 1)  # frame 0 was lost
    assert ledger.match("operator", b"\x01") is None  # already matched
    assert ledger.match("operator", b"nothing sent") is None
    assert ledger.match("vehicle", b"reply") == (3, 0.5)
    assert (ledger.matched["operator"], ledger.lost["operator"]) == (1, 1)
    assert ledger.settled("operator") == 2  # frame 2 may still be on its way
    assert ledger.settled("vehicle") == 1


def test_ledger_forgets_beyond_its_horizon_as_lost() -> None:
    ledger = FrameLedger(horizon=4)
    for k in range(6):
        ledger.record_sent("operator", bytes([k]), float(k))
    assert ledger.lost["operator"] == 2
    assert ledger.match("operator", b"\x00") is None
    assert ledger.match("operator", b"\x05") == (5, 5.0)
    assert ledger.settled("operator") == 6


@dataclass
class FakeEndpoint:
    """The part of a LinkEndpoint a HilModem uses: a wire to another fake, no threads."""

    sent: list[bytes]
    peer: FakeEndpoint | None = None
    accept: bool = True

    def send(self, frame: bytes) -> bool:
        if not self.accept:
            return False
        self.sent.append(frame)
        return True

    def deliver(self, handler: Callable[[Frame], None]) -> int:
        assert self.peer is not None
        frames = [Frame(payload) for payload in _payloads(self.peer.sent)]
        self.peer.sent.clear()
        for frame in frames:
            handler(frame)
        return len(frames)


def _payloads(frames: list[bytes]) -> list[bytes]:
    return [frame[4:-2] for frame in frames]  # WAFrame: 3 preamble + length … CRC-16


def _pair(trace: Trace, outages: list[tuple[float, float]]) -> tuple[HilModem, HilModem]:
    env = simpy.Environment()
    wire_a, wire_b = FakeEndpoint([]), FakeEndpoint([])
    wire_a.peer, wire_b.peer = wire_b, wire_a
    ledger = FrameLedger()
    ends: Any = (wire_a, wire_b)  # fakes standing in for LinkEndpoints
    operator = HilModem(env, "operator", "vehicle", ends[0], trace=trace, ledger=ledger)
    vehicle = HilModem(
        env, "vehicle", "operator", ends[1], trace=trace, ledger=ledger, outages=outages
    )
    return operator, vehicle


def test_modem_hands_each_frame_to_the_node_with_the_senders_frame_id() -> None:
    trace = Trace()
    operator, vehicle = _pair(trace, [])
    got: list[Delivery] = []
    vehicle.on_receive = got.append
    frames = [encode_frame(b"order %d" % k) for k in range(3)]
    for frame in frames:
        assert operator.send(frame)
    sent_ids = [0, 1, 2]
    assert operator.last_frame_id == 2
    assert vehicle.poll() == 3
    assert [d.data for d in got] == frames  # whole frames, byte for byte
    assert [d.frame_id for d in got] == sent_ids
    assert all(d.src == "operator" and (d.part, d.parts) == (0, 1) for d in got)
    kinds = [(e.kind, e.src, e.dst) for e in trace.events]
    assert kinds.count((EventKind.ENQUEUE, "operator", "*")) == 3
    assert kinds.count((EventKind.TX_START, "operator", "*")) == 3
    assert kinds.count((EventKind.DELIVER, "operator", "vehicle")) == 3


def test_modem_refuses_and_discards_in_an_outage_and_reports_drops() -> None:
    trace = Trace()
    operator, vehicle = _pair(trace, [(0.0, 1.0)])
    got: list[Delivery] = []
    vehicle.on_receive = got.append
    operator.send(encode_frame(b"x"))  # the operator has no outage window: it goes out
    assert vehicle.poll() == 1 and got == []  # …and the vehicle discards it in its window
    assert vehicle.send(encode_frame(b"y")) is False
    assert (vehicle.outage_refused, vehicle.outage_discarded) == (1, 1)
    assert len(trace.of_kind(EventKind.OUTAGE)) == 2
    fake: Any = operator.endpoint
    fake.accept = False
    assert operator.send(encode_frame(b"z")) is False
    assert len(trace.of_kind(EventKind.DROP)) == 1


def test_run_hil_rejects_bad_arguments_and_closes_what_it_was_given() -> None:
    scenario = load_scenario("s100-teleop-v1")
    closed: list[str] = []

    class Closing:
        def close(self) -> None:
            closed.append("x")

    with pytest.raises(ValueError, match="keyed"):
        run_hil(scenario, {})
    fake: Any = Closing()
    with pytest.raises(ValueError, match="keyed"):
        run_hil(scenario, {"rov": fake})
    with pytest.raises(ValueError, match="settle_s"):
        run_hil(scenario, {"vehicle": fake}, duration_s=5.0)
    with pytest.raises(ValueError, match="poll_s"):
        run_hil(scenario, {"vehicle": fake}, poll_s=0.0)
    assert len(closed) == 3


# -- the real-time window -----------------------------------------------------------------------


class UnpluggedPort:
    """A pyserial port that fails (as an unplugged USB modem does) inside a monotonic window."""

    def __init__(self, url: str, window: tuple[float, float]) -> None:
        self._window = window
        self._port = serial.Serial(url, timeout=0.05, write_timeout=2.0)

    @staticmethod
    def check(window: tuple[float, float]) -> None:
        if window[0] <= time.monotonic() < window[1]:
            raise serial.SerialException("device disconnected")

    def read(self, size: int = 1) -> bytes:
        self.check(self._window)
        return bytes(self._port.read(size))

    def write(self, data: bytes) -> int | None:
        self.check(self._window)
        written: int | None = self._port.write(data)
        return written

    @property
    def in_waiting(self) -> int:
        self.check(self._window)
        return int(self._port.in_waiting)

    def close(self) -> None:
        self._port.close()


NOISE = b"\x00\xffline noise\x00"
"""What the operator's modem blurts out when it is plugged back in (no 0x55, no ``+++``)."""


def _unplugged_factory(url: str, window: tuple[float, float]) -> Callable[[], UnpluggedPort]:
    opened: list[UnpluggedPort] = []

    def factory() -> UnpluggedPort:
        UnpluggedPort.check(window)
        port = UnpluggedPort(url, window)
        if opened:  # plugged back in: line noise goes out before any frame
            port.write(NOISE)
        opened.append(port)
        return port

    return factory


def _cli(args: list[str], cwd: Path) -> subprocess.Popen[str]:
    """``python -m testbed ARGS`` in a child process, on this checkout's package."""
    env = dict(os.environ, PYTHONPATH=str(Path(testbed.__file__).resolve().parents[1]))
    return subprocess.Popen(
        [sys.executable, "-m", "testbed", *args],
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


@dataclass
class Window:
    """What the real-time window produced."""

    config: LinkConfig
    single: RunResult
    single_dir: Path
    unplug_env_s: tuple[float, float]
    pair_dirs: dict[str, Path]
    cli_dir: Path
    outputs: dict[str, tuple[int, str, str]]


@pytest.fixture(scope="module")
def window(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Window]:
    root = tmp_path_factory.mktemp("hil")
    config = load_link_config("s100", ["ber=0"])
    scenario = load_scenario("s100-teleop-v1")
    with (
        ModemEmulator(config, seed=0, idle_s=IDLE_S) as single,
        ModemEmulator(config, seed=1, idle_s=IDLE_S) as pair,
        ModemEmulator(config, seed=2, idle_s=IDLE_S) as third,
    ):
        common = ["--modem", "s100", "--no-plots", "--duration", str(PAIR_DURATION_S)]
        vehicle_args = ["hil", "vehicle", "--port", pair.paths[1], "--out", "vehicle"]
        operator_args = ["hil", "operator", "--port", pair.paths[0], "--out", "operator"]
        one_computer = ["hil", "--operator-port", third.paths[0], "--vehicle-port"]
        one_computer += [third.paths[1], "--set", "metrics.settle_s=1", "--duration", "3"]
        children = {
            "vehicle": _cli([*vehicle_args, *common], root),
            "operator": _cli([*operator_args, *common], root),
            "cli": _cli([*one_computer, "--out", "cli"], root),
        }
        try:
            for child in children.values():  # each says when its port is open: importing
                assert child.stderr is not None  # numpy and pybullet is over by then
                child.stderr.readline()
            t0 = time.monotonic()
            unplug = (t0 + UNPLUG_S[0], t0 + UNPLUG_S[1])
            operator = open_endpoint(
                PortSettings(single.paths[0], "s100", "operator"),
                port_factory=_unplugged_factory(single.paths[0], unplug),
                backoff_initial_s=0.05,
                backoff_max_s=0.25,
            )
            vehicle = open_endpoint(PortSettings(single.paths[1], "s100", "vehicle"))
            start = time.monotonic()  # the run's clock starts within the loading time after
            result = run_hil(
                scenario,
                {"operator": operator, "vehicle": vehicle},
                duration_s=DURATION_S,
                modem="s100",
            )
            single_dir = root / "single"
            write_outputs(result, single_dir, plots=False)
        finally:
            outputs = {}
            for name, child in children.items():
                out, err = child.communicate(timeout=60)
                outputs[name] = (child.returncode, out, err)
        assert single.error is None and pair.error is None and third.error is None
    yield Window(
        config,
        result,
        single_dir,
        (UNPLUG_S[0] - (start - t0), UNPLUG_S[1] - (start - t0)),
        {"vehicle": root / "vehicle", "operator": root / "operator"},
        root / "cli",
        outputs,
    )


def _read(path: Path) -> dict[str, Any]:
    data: dict[str, Any] = json.loads((path / "metrics.json").read_text(encoding="utf-8"))
    return data


def test_orders_reach_the_vehicle_and_state_returns(window: Window) -> None:
    metrics = window.single.metrics
    up, down = metrics["link"]["uplink"], metrics["link"]["downlink"]
    # One order per 0.594 s IPG over 20 s, less the ≈ 2.5 s the port was away.
    assert up["frames_delivered"] >= 25
    assert down["frames_delivered"] >= 25
    assert up["frames_corrupted"] == down["frames_corrupted"] == 0
    assert metrics["frames_rejected"] == {"uplink": 0, "downlink": 0}
    assert metrics["odometry_age_s"]["mean"] < 1.0
    series = window.single.recorder.series()
    assert series["armed"][-1] == 1.0  # the arm request travelled as an order
    assert math.isnan(up["frames_collided"])
    written = _read(window.single_dir)
    assert written["hil"]["mode"] == "both"
    assert written["link"]["uplink"]["frames_collided"] is None  # only the simulator knows
    assert {p.name for p in window.single_dir.iterdir()} >= {
        "metrics.json",
        "events.csv",
        "series.csv",
    }


def test_command_lag_is_the_emulated_links_latency(window: Window) -> None:
    """Lag = idle gap + intrinsic delay + airtime(frame + CR LF) + the wait for the vehicle's
    next control frame (≤ 1/100 s + one 1/240-s physics step) + two 1-ms polls and the host.
    Lower bound: the link part alone, less 2 ms for the real-time clock running behind the
    wall clock when busy. Upper bound for the median: plus a full frame wait and 3 ms of
    polls and host; p95: 40 ms more, the scheduling delays seen on a loaded, shared 2-core
    machine (still well under a second intrinsic delay or one inter-packet gap)."""
    recorder = window.single.recorder
    sizes = {
        e.size_bytes
        for e in recorder.trace.of_kind(EventKind.ENQUEUE)
        if e.frame_id in recorder.uplink_commands
    }
    assert sizes == {13}  # the paper's move order in a WAFrame
    config = window.config
    link_s = IDLE_S + config.intrinsic_delay_s + config.airtime_s(13 + CRLF)  # 151.4 ms
    frame_wait_s = 1 / 100 + 1 / 240
    lags = np.array(
        [
            applied - recorder.commands_sampled[seq]
            for seq, applied in recorder.commands_applied.items()
            if seq in recorder.commands_sampled
        ]
    )
    assert lags.size >= 20
    assert lags.min() >= link_s - 0.002
    assert link_s <= np.median(lags) <= link_s + frame_wait_s + 0.003
    assert np.percentile(lags, 95) <= link_s + frame_wait_s + 0.003 + 0.040
    assert window.single.metrics["command_lag_s"]["n"] == lags.size


def test_round_trip_is_both_directions_of_the_link(window: Window) -> None:
    """Order out and reply back, the vehicle answering at once: two idle gaps, two intrinsic
    delays, both airtimes; the median within 6 ms (polls and host both ways), p95 within the
    same 40 ms scheduling allowance as the command lag."""
    config = window.config
    order, reply = 13 + CRLF, 20 + CRLF  # move order; state reply without image chunk
    model_s = 2 * (IDLE_S + config.intrinsic_delay_s) + config.airtime_s(order + reply)
    rtt = window.single.metrics["hil"]["round_trip_s"]
    assert rtt["n"] >= 25
    assert model_s - 0.002 <= rtt["p50"] <= model_s + 0.006
    assert rtt["p95"] <= model_s + 0.040


def test_added_latency_is_under_a_millisecond_at_the_median(window: Window) -> None:
    hil = window.single.metrics["hil"]
    added = hil["added_latency_ms"]
    up, down = window.single.metrics["link"]["uplink"], window.single.metrics["link"]["downlink"]
    assert added["n"] == up["frames_delivered"] + down["frames_delivered"]
    assert 0.0 < added["p50"] < 1.0  # issue 7: aim median under 1 ms
    assert added["p95"] < 5.0
    ends = hil["endpoints"]
    assert ends["vehicle"]["frames_in"] == up["frames_delivered"]
    assert ends["operator"]["bytes_in"] == ends["operator"]["adapter"]["bytes_in"] > 0
    assert ends["vehicle"]["adapter"]["terminators"] == up["frames_delivered"]
    assert ends["operator"]["garbage_bytes"] == 0


def test_garbage_on_the_line_is_counted_not_fatal(window: Window) -> None:
    hil = window.single.metrics["hil"]
    # The noise the operator's modem sent when plugged back in crossed the link: the
    # vehicle's decoder skipped it, and the orders behind it still decoded.
    assert hil["endpoints"]["vehicle"]["garbage_bytes"] == len(NOISE)
    assert hil["garbage_bytes"] == len(NOISE)
    assert hil["endpoints"]["vehicle"]["corrupt_frames"] == 0


def test_port_vanishes_and_returns_while_the_run_goes_on(window: Window) -> None:
    metrics = window.single.metrics
    recorder = window.single.recorder
    operator = metrics["hil"]["endpoints"]["operator"]
    assert operator["port_errors"] >= 1
    assert operator["reopens"] >= 1 and metrics["hil"]["reopens"] >= 1
    assert operator["reopen_failures"] >= 1  # the port stayed away for a while
    assert "device disconnected" in operator["last_error"]
    assert operator["frames_dropped"] >= 2  # orders sent while it was away
    assert metrics["hil"]["endpoints"]["vehicle"]["reopens"] == 0
    # The vehicle's failsafe held after 1 s without orders, and let go when they came back.
    start_s, end_s = window.unplug_env_s
    failsafe = [(e.t_s, e.detail) for e in recorder.events if e.kind == "failsafe"]
    holds = [t for t, level in failsafe if level == "HOLD"]
    # The last order before the unplug arrived up to one IPG (0.6 s) before it or one lag
    # (0.2 s) after; the run's clock started up to 0.5 s (loading the vehicle) after `start`.
    assert holds and start_s - 0.5 + 0.4 <= holds[0] <= start_s + 1.0 + 0.2
    assert any(level == "NOMINAL" and t > holds[0] for t, level in failsafe)
    assert metrics["events"]["failsafe"] >= 2
    assert max(recorder.commands_applied.values()) > end_s + 1.0  # orders flow again
    assert metrics["link"]["uplink"]["per"] > 0.0  # the orders lost count


def test_two_computers_each_write_what_they_observe(window: Window) -> None:
    for name in ("vehicle", "operator"):
        code, out, err = window.outputs[name]
        assert code == 0, err
        assert f"({name}, s100)" in out
    vehicle = _read(window.pair_dirs["vehicle"])
    operator = _read(window.pair_dirs["operator"])
    assert vehicle["hil"]["mode"] == "vehicle" and operator["hil"]["mode"] == "operator"
    received = vehicle["link"]["uplink"]["frames_delivered"]
    assert received >= 12  # ≈ 20 orders in 12 s, less the children's start-up skew
    assert vehicle["link"]["downlink"]["frames_sent"] == received  # one reply per order
    assert vehicle["link"]["uplink"]["frames_sent"] is None  # sent on the other computer
    assert operator["link"]["downlink"]["frames_delivered"] >= 12
    assert operator["link"]["uplink"]["frames_sent"] >= received
    assert vehicle["command_lag_s"]["n"] == operator["command_lag_s"]["n"] == 0  # two clocks
    assert operator["energy_wh"] is None and vehicle["energy_wh"] > 0.0
    rows = (window.pair_dirs["vehicle"] / "series.csv").read_text().splitlines()
    assert rows[-1].split(",")[-2] == "1"  # armed: the operator's arm order got there
    assert operator["hil"]["round_trip_s"]["n"] >= 12


def test_cli_one_computer_run(window: Window) -> None:
    code, out, err = window.outputs["cli"]
    assert code == 0, err
    assert "(both, s100)" in out and "added latency p50" in out
    metrics = _read(window.cli_dir)
    assert metrics["hil"]["mode"] == "both"
    assert metrics["link"]["uplink"]["frames_delivered"] >= 3
    assert metrics["link"]["downlink"]["frames_delivered"] >= 3
    assert (window.cli_dir / "events.csv").is_file()
