"""A ground station we did not write: MAVProxy, headless, flies ``testbed mavlink``.

``testbed mavlink --gcs udpout:127.0.0.1:PORT`` runs in one process (SITL's ``--out``), and
``mavproxy.py --master=udpin:127.0.0.1:PORT`` in another with its commands piped into stdin, each
sent once MAVProxy has printed the outcome of the one before: ``rc 5 1500`` (MAVProxy then
repeats its RC override: pilot input, without which ArduSub's FS_PILOT_INPUT disarms 3 s after
boot), ``mode ALT_HOLD``, ``arm throttle``, ``rc 5 1700`` (forward), ``mode GUIDED``,
``velocity 0.3 0 0``, ``param show FS_GCS*``, ``disarm``. The truth is the vehicle's own
recording (``series.csv`` of the run, ended with SIGINT as Ctrl-C would): armed, moved ahead
under the forward override, 0.9 m along its heading under the velocity target (ArduSub keeps
it 3 s), disarmed. About 30 s; skipped when MAVProxy is not installed.
"""

from __future__ import annotations

import csv
import math
import queue
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from testbed.mavlink import load_params
from tests.processes import default_sigint

pytest.importorskip("MAVProxy")

WAIT_S = 120.0  # progress timeouts, not latency bounds: only a broken endpoint waits this long
# (MAVProxy imports matplotlib and friends: on a loaded 2-core machine its start alone takes tens
# of seconds)
MAVPROXY = Path(sys.executable).with_name("mavproxy.py")
VELOCITY_M_S = 0.3  # MAVProxy's `velocity` command, ahead


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


class _Lines:
    """A process's stdout, line by line, from a thread; ``expect`` waits for a line."""

    def __init__(self, process: subprocess.Popen[str]) -> None:
        self.lines: queue.Queue[str] = queue.Queue()
        self.text: list[str] = []
        assert process.stdout is not None
        stdout = process.stdout
        threading.Thread(target=lambda: [self.lines.put(x) for x in stdout], daemon=True).start()

    def expect(self, *words: str) -> str:
        end = time.monotonic() + WAIT_S
        while time.monotonic() < end:
            try:
                line = self.lines.get(timeout=0.1)
            except queue.Empty:
                continue
            self.text.append(line)
            if any(word in line for word in words):
                return line
        raise AssertionError(f"MAVProxy never printed {words}: {''.join(self.text[-30:])}")


@pytest.mark.skipif(not MAVPROXY.exists(), reason="mavproxy.py is not installed")
def test_mavproxy_arms_flies_forward_and_disarms_the_vehicle(tmp_path: Path) -> None:
    port = _free_udp_port()
    out = tmp_path / "run"
    vehicle = subprocess.Popen(
        [
            *(sys.executable, "-m", "testbed", "mavlink", "--gcs", f"udpout:127.0.0.1:{port}"),
            *("--duration", "3600", "--out", str(out), "--no-plots"),  # the test's SIGINT ends it
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=default_sigint,  # it must take the test's Ctrl-C however pytest was started
    )
    mavproxy = subprocess.Popen(
        [
            *(str(MAVPROXY), f"--master=udpin:127.0.0.1:{port}", "--nowait"),
            *(f"--state-basedir={tmp_path}", f"--logfile={tmp_path / 'mav.tlog'}"),
        ],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        bufsize=1,
    )
    assert mavproxy.stdin is not None
    stdin = mavproxy.stdin

    def send(command: str) -> None:
        stdin.write(command + "\n")
        stdin.flush()

    lines = _Lines(mavproxy)
    try:
        lines.expect("online system 1")
        # MAVFTP refused, the parameter protocol used: the whole table
        lines.expect(f"Received {len(load_params())} parameters")
        send("rc 5 1500")  # pilot input from now on: FS_PILOT_INPUT disarms without it
        send("mode ALT_HOLD")
        lines.expect("DO_SET_MODE: ACCEPTED")
        send("arm throttle")
        lines.expect("ARMED")
        send("rc 5 1700")  # forward, held by MAVProxy's repeated RC override
        time.sleep(4.0)  # let it fly; the recording says whether it moved
        send("rc 5 1500")
        time.sleep(2.0)  # it slows down
        send("mode GUIDED")
        lines.expect("DO_SET_MODE: ACCEPTED")
        send(f"velocity {VELOCITY_M_S} 0 0")  # once: ahead for ArduSub's 3-s timeout
        lines.expect("x:0.3")
        # the 3 s, then the position loop closing on the stopped target: ≈ 0.45 m behind it
        # at 0.3 m/s, closed at its gain, 0.8 /s, to under 1 cm in 5 s
        time.sleep(9.0)
        send("param show FS_GCS*")
        shown = lines.expect("FS_GCS_ENABLE").split()
        assert float(shown[shown.index("FS_GCS_ENABLE") + 1]) == 2.0
        send("disarm")
        lines.expect("DISARMED")
        assert not [line for line in lines.text if "fence breach" in line]  # no fence here
        time.sleep(0.5)  # a few recorded samples disarmed
    finally:
        vehicle.send_signal(signal.SIGINT)  # Ctrl-C: the run keeps what ran
        try:
            send("exit")
            stdin.close()
        except (BrokenPipeError, OSError):
            pass
        try:
            mavproxy.wait(timeout=10.0)
        except subprocess.TimeoutExpired:  # MAVProxy's exit can hang on its threads
            mavproxy.kill()
            mavproxy.wait()
        try:
            _, err = vehicle.communicate(timeout=WAIT_S)
        except subprocess.TimeoutExpired:
            vehicle.kill()  # never leave it running
            vehicle.communicate()
            raise
    assert vehicle.returncode == 130, err

    with (out / "series.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    armed = [float(r["armed"]) for r in rows]
    assert max(armed) == 1.0 and armed[-1] == 0.0  # armed, then disarmed
    forward = [r for r in rows if float(r["rx_x"]) > 0.4 and float(r["armed"]) == 1.0]
    assert forward and max(float(r["u"]) for r in forward) > 0.2  # it moved ahead
    # `velocity 0.3 0 0` (BODY_NED, yaw ignored): 0.3 m/s along the heading for ArduSub's 3 s,
    # from where the vehicle was when it arrived (the first row with the GUIDED target set),
    # within the position loop's 5 cm, the fix's noise and what it coasted in one sample
    guided = [r for r in rows if float(r["mode"]) == 4.0 and float(r["armed"]) == 1.0]
    moving = [r for r in guided if r["target_n"] != "nan"]
    assert moving, "the velocity target never reached the vehicle"
    first, last = moving[0], guided[-1]
    heading = math.radians(float(first["yaw_deg"]))
    ahead = VELOCITY_M_S * 3.0
    north = float(first["north_m"]) + ahead * math.cos(heading)
    east = float(first["east_m"]) + ahead * math.sin(heading)
    coast = math.hypot(float(first["u"]), float(first["v"])) * 0.05  # a 20-Hz sample
    error = math.hypot(float(last["north_m"]) - north, float(last["east_m"]) - east)
    assert error < 0.05 + 0.015 + coast
    assert abs(math.remainder(math.radians(float(last["yaw_deg"])) - heading, math.tau)) < 0.05
