"""``testbed live`` over HIL ports: the console's session with its frames through the PTY modem
emulator (the simulated S100 behind two pseudo-terminals), as ``testbed hil`` runs them."""

from __future__ import annotations

import json
import select
import signal
import subprocess
import sys
import time
import urllib.request
from pathlib import Path
from typing import Any

import pytest
from websockets.sync.client import connect

from testbed.channel import load_link_config
from testbed.emulator.ptys import ModemEmulator
from tests.processes import default_sigint

_DEADLINE_S = 60.0
"""Failure bound of the wait [s of wall clock]; the model needs a few 0.594-s gaps."""


def _state(url: str) -> dict[str, Any]:
    with urllib.request.urlopen(url + "state", timeout=10) as response:
        return json.loads(response.read())["state"] or {}  # type: ignore[no-any-return]


def test_a_live_session_runs_over_hil_ports(tmp_path: Path) -> None:
    try:
        emulator = ModemEmulator(load_link_config("s100", ["ber=0"]), seed=0)
    except OSError as err:  # pragma: no cover - no PTYs here
        pytest.skip(f"no pseudo-terminals: {err}")
    with emulator:
        a, b = emulator.paths
        out = tmp_path / "out"
        command = [sys.executable, "-m", "testbed", "live", "s100-teleop-v1", "--port", "0"]
        command += ["--operator-port", a, "--vehicle-port", b, "--no-plots", "--out", str(out)]
        proc = subprocess.Popen(
            command,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            preexec_fn=default_sigint,  # it must take the test's Ctrl-C however pytest started
        )
        try:
            assert proc.stdout is not None
            ready, _, _ = select.select([proc.stdout], [], [], 4 * _DEADLINE_S)
            line = proc.stdout.readline() if ready else ""
            assert line.startswith("testbed live: console on "), line
            url = line.split()[-1]
            deadline = time.monotonic() + _DEADLINE_S
            state: dict[str, Any] = {}
            while time.monotonic() < deadline:
                state = _state(url)
                operator = state.get("operator") or {}
                if state and state["link"]["downlink"]["delivered"] >= 3 and operator.get("armed"):
                    break
                time.sleep(0.1)
            else:
                raise AssertionError(f"no replies over the ports: {state}")
            assert state["link"]["simulated"] is False
            with connect(url.replace("http://", "ws://") + "ws") as ws:  # the pilot's seat
                ws.send(json.dumps({"t": "outage", "duration_s": 3}))
                while time.monotonic() < deadline:
                    if any(e[2] == "link_refused" for e in _state(url)["events"]):
                        break
                    time.sleep(0.05)
                else:
                    raise AssertionError("the outage was not refused on HIL ports")
            proc.send_signal(signal.SIGINT)
            assert proc.wait(timeout=300) == 130  # Ctrl-C; the timeout bounds progress, not latency
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["live"]["session"] == "live" and metrics["hil"]["mode"] == "both"
    assert metrics["link"]["downlink"]["frames_delivered"] >= 3
