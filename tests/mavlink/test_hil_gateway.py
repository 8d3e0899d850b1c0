"""``testbed mavlink --operator-port … --vehicle-port …``: the gateway through two (emulated)
HIL modems, end to end in real time. pymavlink's ``mavutil`` here arms, flies forward and
disarms the vehicle; the CLI runs in a child process on the two ports of an s100 PTY modem
emulator (``testbed.emulator.ptys.ModemEmulator``, BER 0) in a child of its own, as real modems
are outside the computer.

Truth: the emulator's counters (every order the gateway wrote is one burst on port A and one
delivery on port B, every reply the reverse; token passing never collides) and the channel
model's closed forms: an order crosses in the idle gap that closes its burst (3 ms) + the
intrinsic delay + the airtime of its 13-B frame and CR LF (REFERENCE §1.10), a reply likewise
with its 20 B. Command-lag bounds are that plus at most one stick interval, one gateway period,
one vehicle frame and one modem poll, plus the lateness measured in the same window (the run's
and the emulator's threads, and the worst round trip's excess over the model), never a fixed
allowance. Measured 2026-12-02 (2-core machine, load
1–5): 17 orders and 17 replies in ≈ 10 s; round trip p50 336 ms (model 334 ms), max 376 ms;
command lag p50 190 ms, max 230 ms (n 16) against the bounds 151 ms .. 406 ms (the upper one
with that load's lateness). About 14 s of wall time.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

import testbed
from testbed.channel import load_link_config
from testbed.run.hil_modem import POLL_S
from testbed.run.mavlink_gateway import GATEWAY_PERIOD_S
from tests.mavlink.rt_session import GatewaySession
from tests.processes import default_sigint

S100 = load_link_config("s100", ["ber=0"])
IDLE_S = 0.003  # the emulator's burst-closing idle gap (its default)
CRLF = 2
D_UP_S = IDLE_S + S100.intrinsic_delay_s + S100.airtime_s(13 + CRLF)
D_DOWN_S = IDLE_S + S100.intrinsic_delay_s + S100.airtime_s(20 + CRLF)
FRAME_S = 0.01
START_S = 120.0  # a cold child (imports, kernels) on a loaded 2-core machine; polled
EMULATOR = """
import dataclasses, json, sys
from testbed.channel import load_link_config
from testbed.emulator.ptys import ModemEmulator

emulator = ModemEmulator(load_link_config("s100", ["ber=0"]), seed=0)
emulator.start()
print(json.dumps(emulator.paths), flush=True)
sys.stdin.read()  # closed by the test once the session has closed its ports
emulator.close()
print(json.dumps({
    "error": None if emulator.error is None else repr(emulator.error),
    "ports": [dataclasses.asdict(c) for c in emulator.counters],
    "modems": [dataclasses.asdict(modem.counters) for modem in emulator.modems],
    "scheduler_lateness_ms": emulator.scheduler_lateness_ms,
}), flush=True)
"""


def _python(args: list[str]) -> subprocess.Popen[str]:
    env = dict(os.environ, PYTHONPATH=str(Path(testbed.__file__).resolve().parents[1]))
    return subprocess.Popen(
        [sys.executable, *args],
        env=env,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=default_sigint,
    )


class _Cli:
    """``testbed mavlink`` on the emulator's ports in a child process, as GatewaySession's run:
    started when the session starts, Ctrl-C once the session is finished (it keeps what ran)."""

    def __init__(self, ports: list[str], out: Path) -> None:
        self.ports = ports
        self.out = out
        self.code: int | None = None
        self.stderr = ""

    def __call__(self, links: list[Any], stop: threading.Event) -> Any:
        url = links[0].url  # udpout:127.0.0.1:PORT, the session's ground station
        links[0].close()  # the child sends there itself
        proc = _python(
            [
                "-m",
                "testbed",
                "mavlink",
                "--operator-port",
                self.ports[0],
                "--vehicle-port",
                self.ports[1],
                "--gcs",
                url,
                "--duration",
                "600",
                "--out",
                str(self.out),
                "--no-plots",
                "--set",
                "metrics.settle_s=1",
            ]
        )
        stop.wait()
        proc.send_signal(signal.SIGINT)
        _, self.stderr = proc.communicate(timeout=START_S)
        self.code = proc.returncode
        return self


@pytest.fixture
def emulator() -> Iterator[tuple[subprocess.Popen[str], list[str]]]:
    proc = _python(["-c", EMULATOR])
    try:
        assert proc.stdout is not None
        yield proc, json.loads(proc.stdout.readline())
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()


def test_a_ground_station_arms_flies_and_disarms_through_the_hil_modems(
    emulator: tuple[subprocess.Popen[str], list[str]], tmp_path: Path
) -> None:
    proc, ports = emulator
    cli = _Cli(ports, tmp_path / "out")
    session = GatewaySession(cli)
    try:
        gcs = session.gcs
        hb = gcs.wait_heartbeat(timeout=START_S)
        assert hb is not None, f"the CLI never came up: {session.error!r}"
        session.pump(1.0)
        gcs.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
        assert session.ack(400) == mav.MAV_RESULT_ACCEPTED
        session.heartbeat(lambda hb: hb.base_mode & 128)  # the vehicle's state says armed
        banner = [m.text for _, m in session.seen.get("STATUSTEXT", [])]
        assert any(text.startswith("Gateway s100") for text in banner), banner
        start = session.until(lambda: session.latest.get("LOCAL_POSITION_NED"))
        session.sticks = (1000, 0, 500, 0)  # forward
        session.pump(5.0)
        # and on until the ground station sees the vehicle 0.5 m ahead (a loaded host can hold
        # the orders back: a progress wait, not a fixed time)
        session.until(lambda: session.latest["LOCAL_POSITION_NED"].x - start.x > 0.5)
        session.sticks = (0, 0, 500, 0)
        gcs.mav.command_long_send(1, 1, 400, 0, 0, 0, 0, 0, 0, 0, 0)
        assert session.ack(400) == mav.MAV_RESULT_ACCEPTED
        session.heartbeat(lambda hb: not hb.base_mode & 128)
        stick_gap_s = session.max_stick_gap_s()
        session.finish()
    finally:
        session.close()
    assert cli.code == 130, cli.stderr  # Ctrl-C: one line, what ran kept
    assert proc.stdin is not None
    time.sleep(2 * D_UP_S)  # a frame the CLI wrote just before it ended has landed: the model
    proc.stdin.close()
    report = json.loads(proc.stdout.readline()) if proc.stdout else {}
    proc.wait(timeout=START_S)
    assert report["error"] is None

    out = tmp_path / "out"
    m = json.loads((out / "metrics.json").read_text())
    section = m["mavlink"]
    assert section["gateway"] is True
    assert section["link"]["name"] == "s100"

    # counts: every burst the operator's port took was delivered on the vehicle's and the
    # reverse (BER 0), none dropped, one reply per order; at most the last of each in flight
    # when the session ended — less those the emulator counts as collided (token passing keeps
    # the two sides apart by its margin, which a loaded host can overrun by delaying a reply;
    # none collide on an idle machine)
    a, b = report["ports"]
    collided_at_a, collided_at_b = (modem["rx_collided"] for modem in report["modems"])
    assert a["bursts"] >= 10 and b["bursts"] >= 10
    assert a["bursts"] - 1 - collided_at_b <= b["deliveries"] <= a["bursts"]
    assert b["bursts"] - 1 - collided_at_a <= a["deliveries"] <= b["bursts"]
    assert a["bursts_dropped"] == b["bursts_dropped"] == 0
    assert abs(a["bursts"] - b["bursts"]) <= 1 + collided_at_a + collided_at_b

    # recorded state: it armed, moved ahead under the forward stick, and ended disarmed
    series = np.genfromtxt(out / "series.csv", delimiter=",", names=True)
    forward = series["rx_x"] > 0.4
    assert forward.any() and series["u"][forward].max() > 0.2
    assert series["armed"].max() == 1.0 and series["armed"][-1] == 0.0

    # command lag (stick read at the gateway → the vehicle frame applying it): one crossing of
    # the emulated link at least; at most that plus a stick interval to the slot, a gateway
    # period, a vehicle frame, a modem poll and the lateness measured in the same window (the
    # gateway's scheduler, the modem poll's, the emulator's simulation and reader threads)
    emu = report["scheduler_lateness_ms"]
    late_ms = (
        section["scheduler_lateness_ms"]["max"]
        + m["hil"]["scheduler_lateness_ms"]["max"]
        + emu["simulation"]["max"]
        + emu["reader"]["max"]
        + emu["reader_stall"]["max"]
    )
    late_s = late_ms / 1000.0
    # and what the host added to a crossing: how long it held up the transports' writer and
    # reader threads (each endpoint measures its own), plus the PTYs' share, no more than the
    # worst order-to-reply round trip took over its own model (both crossings and the poll)
    threads = [e["thread_lateness_ms"] for e in m["hil"]["endpoints"].values()]
    held_ms = sum(max(t[role]["max"] for t in threads) for role in ("reader", "writer"))
    round_trip = m["hil"]["round_trip_s"]
    host_s = max(0.0, round_trip["max"] - (D_UP_S + D_DOWN_S)) + held_ms / 1000.0
    lag = m["command_lag_s"]
    high = D_UP_S + stick_gap_s + GATEWAY_PERIOD_S + FRAME_S + POLL_S + late_s + host_s
    assert lag["n"] >= 5
    # pairs need a reply within one gap of its order: a loaded host pairs fewer of a session
    # (2 of a session beside two busy loops, 2026-12-07), so one pair is what is required; the
    # bound on it is the model's (both crossings), which no load can shorten
    assert round_trip["n"] >= 1 and round_trip["p50"] >= D_UP_S + D_DOWN_S - 0.001, round_trip
    assert D_UP_S - 0.001 <= lag["p50"] <= lag["max"] <= high, (lag, D_UP_S, high)
