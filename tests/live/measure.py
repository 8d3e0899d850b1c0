"""Measure the live console's latencies (the README's and docs/live.md's figures).

Usage: ``.venv/bin/python -m tests.live.measure [SCENARIO ...] [--seconds 40]`` (default:
``s100-video-v1`` and ``tether-teleop-v1``). For each scenario: start ``testbed live``, open
the console in headless Chromium, pulse the W key (surge) on a seeded random pattern for
``--seconds`` after the settling time, end with Ctrl-C and print, from ``metrics.json``:

* input → intent: the server's receive → the sample taken in by the operator's thread (p50,
  p95) plus half the browser's WebSocket round trip (the browser → server leg);
* state → pixels: the state sampled → drawn in the page (clock offset from pings);
* command lag: operator sampling → vehicle application (``command_lag_s``), and the end-to-end
  lag a pilot feels: a stick change taken in → applied at the vehicle
  (``live.stick_to_vehicle_ms``: the wait for the operator's next slot, the link, the vehicle's
  next frame).
"""

from __future__ import annotations

import argparse
import json
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from tests.processes import default_sigint


def measure(scenario: str, seconds: float, browser_path: str) -> dict[str, Any]:
    """One session of ``scenario``; returns its ``metrics.json``."""
    from playwright.sync_api import sync_playwright

    out = Path(tempfile.mkdtemp(prefix="live-measure-")) / "out"
    command = [sys.executable, "-m", "testbed", "live", scenario, "--port", "0"]
    proc = subprocess.Popen(
        [*command, "--no-plots", "--out", str(out)],
        stdout=subprocess.PIPE,
        text=True,
        preexec_fn=default_sigint,  # it must take our Ctrl-C however we were started
    )
    assert proc.stdout is not None
    url = proc.stdout.readline().split()[-1]
    rng = random.Random(0)
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=browser_path, args=["--no-sandbox"])
        page = browser.new_page()
        page.goto(url)
        time.sleep(11.0)  # the scenario's settling time (metrics.settle_s = 10 s)
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            page.keyboard.down("KeyW")
            time.sleep(rng.uniform(0.7, 2.5))
            page.keyboard.up("KeyW")
            time.sleep(rng.uniform(0.7, 2.5))
        time.sleep(2.5)  # the browser's last latency report
        browser.close()
    proc.send_signal(signal.SIGINT)
    proc.wait(timeout=120)
    metrics: dict[str, Any] = json.loads((out / "metrics.json").read_text())
    shutil.rmtree(out.parent, ignore_errors=True)
    return metrics


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenarios", nargs="*", default=["s100-video-v1", "tether-teleop-v1"])
    parser.add_argument("--seconds", type=float, default=40.0)
    args = parser.parse_args()
    browser_path = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser_path is None:
        raise SystemExit("no chromium")
    for scenario in args.scenarios:
        m = measure(scenario, args.seconds, browser_path)
        live = m["live"]
        queue, rtt = live["input_to_intent_ms"], live["browser_round_trip_ms"]
        half = (rtt["p50"] or 0.0) / 2
        print(
            f"{scenario}: input→intent p50 {queue['p50'] + half:.2f} ms "
            f"(queue p50 {queue['p50']:.2f} p95 {queue['p95']:.2f}, RTT p50 {rtt['p50']:.2f}); "
            f"state→pixels p50 {live['state_to_pixels_ms']['p50']:.1f} ms "
            f"p95 {live['state_to_pixels_ms']['p95']:.1f}; "
            f"command lag mean {1e3 * m['command_lag_s']['mean']:.0f} ms "
            f"p95 {1e3 * m['command_lag_s']['p95']:.0f}; "
            f"stick change→applied p50 {live['stick_to_vehicle_ms']['p50']:.0f} ms "
            f"p95 {live['stick_to_vehicle_ms']['p95']:.0f} (n {live['stick_to_vehicle_ms']['n']}); "
            f"lateness p95 {live['scheduler_lateness_ms']['p95']:.2f} ms"
        )


if __name__ == "__main__":
    main()
