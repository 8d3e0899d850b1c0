"""A ground station we did not write: MAVProxy, headless, flies ``testbed mavlink``.

``testbed mavlink --gcs udpout:127.0.0.1:PORT`` runs in one process (SITL's ``--out``), and
``mavproxy.py --master=udpin:127.0.0.1:PORT`` in another with its commands piped into stdin, each
sent once MAVProxy has printed the outcome of the one before: ``rc 5 1500`` (MAVProxy then
repeats its RC override: pilot input, without which ArduSub's FS_PILOT_INPUT disarms 3 s after
boot), ``mode ALT_HOLD``, ``arm throttle``, ``rc 5 1700`` (forward), ``param show FS_GCS*``,
``disarm``. The truth is the vehicle's
own recording (``series.csv`` of the run, ended with SIGINT as Ctrl-C would): armed, moved ahead
under the forward override, disarmed. About 15 s; skipped when MAVProxy is not installed.
"""

from __future__ import annotations

import csv
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
