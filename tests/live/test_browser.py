"""The console in headless Chromium against a real ``testbed live`` process.

One session (one process, one browser) walks through the console: keyboard sticks move the
vehicle, an injected fake gamepad does too, the image appears and sharpens, telemetry and the
link panel update, an ROI drag reaches the vehicle's coder as an ImageSettings order, a click
on the track is a GoTo the vehicle flies, the
outage button triggers the vehicle's failsafe, a second tab is a read-only viewer whose
garbage and floods are counted, and Ctrl-C writes the outputs marked as a live session. A
screenshot of each step goes to the test's ``tmp_path``.

Assertions are on the recorded state (``/state``, then ``metrics.json`` and ``events.csv``),
never on wall-clock speed: each wait is for a condition the model must reach, with a deadline
only as the failure bound (``_DEADLINE_S`` without the link moving, far beyond what the model
needs: the S100 gap is 0.6 s, the failsafe holds after 1 s without orders).

Skipped, with the reason, when Playwright or a Chromium executable is missing.
"""

from __future__ import annotations

import json
import math
import os
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.live.livesession import Live

_FAKE_GAMEPAD = """
window.__pad = { id: "fake pad", index: 0, connected: true, mapping: "standard", timestamp: 0,
  axes: [0, 0, 0, 0], buttons: Array.from({ length: 17 }, () => ({ pressed: false, value: 0 })) };
navigator.getGamepads = () => [window.__pad];
"""


@pytest.fixture
def live(tmp_path: Path, browser_path: str) -> Iterator[Live]:
    del browser_path
    with Live.running(tmp_path / "out") as process:
        yield process


def test_console_flies_the_vehicle_and_shows_the_link(
    live: Live, browser_path: str, tmp_path: Path
) -> None:
    from playwright.sync_api import sync_playwright

    shots = tmp_path / "screenshots"
    shots.mkdir()
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=browser_path, args=["--no-sandbox"])
        page = browser.new_page(viewport={"width": 1500, "height": 900})
        page.add_init_script(_FAKE_GAMEPAD)
        page.goto(live.url)
        page.wait_for_function("document.getElementById('role').textContent === 'pilot'")
        start = live.wait(
            "armed at the operator", lambda s: bool((s["operator"] or {}).get("armed"))
        )
        page.screenshot(path=shots / "01-armed.png")

        # keyboard: W holds the surge stick at +0.5; the vehicle applies it and moves north
        x0 = start["truth"]["pos"][0]
        page.keyboard.down("KeyW")
        live.wait("surge applied", lambda s: s["truth"]["sticks"][0] > 0.4)
        moved = live.wait("moved north", lambda s: s["truth"]["pos"][0] > x0 + 0.05)
        page.screenshot(path=shots / "02-keyboard.png")
        page.keyboard.up("KeyW")
        live.wait("surge released", lambda s: s["truth"]["sticks"][0] == 0.0)

        # fake gamepad: left stick right = yaw right; the heading turns clockwise
        yaw0 = moved["truth"]["rpy"][2]
        page.evaluate("window.__pad.axes[0] = 0.8")
        live.wait("yaw applied", lambda s: s["truth"]["sticks"][5] > 0.5)
        live.wait("turned", lambda s: (s["truth"]["rpy"][2] - yaw0) % 360.0 > 5.0)
        page.screenshot(path=shots / "03-gamepad.png")
        page.evaluate("window.__pad.axes[0] = 0")
        live.wait("yaw released", lambda s: s["truth"]["sticks"][5] == 0.0)

        # gamepad buttons, ArduSub's defaults: Back disarms, Start arms, A manual, X depth hold
        def press(button: int) -> None:
            page.evaluate(f"window.__pad.buttons[{button}].pressed = true")
            page.wait_for_function(f"padButtons[{button}] === true")  # the page sampled it
            page.evaluate(f"window.__pad.buttons[{button}].pressed = false")
            page.wait_for_function(f"padButtons[{button}] === false")

        press(8)
        live.wait("disarmed", lambda s: not s["truth"]["armed"])
        press(9)
        live.wait("armed again", lambda s: s["truth"]["armed"])
        press(0)
        live.wait("manual", lambda s: (s["operator"] or {}).get("mode") == "manual")
        press(2)
        live.wait("depth hold", lambda s: (s["operator"] or {}).get("mode") == "depth_hold")

        # the truth overlay: T shows the physics truth beside what the operator knows
        page.keyboard.press("KeyT")
        assert page.is_checked("#truth")
        page.wait_for_function("document.querySelector('#telemetry span[style]') !== null")

        # the image appears, then sharpens as chunks arrive (seen in the first half of its
        # bytes: one first seen near its budget could never gain 80 more, and the wait would
        # run on while the link does)
        def early_image(s: dict[str, Any]) -> bool:
            image = s["image"] or {}
            return image.get("view") is not None and image["bytes"] <= image["coder"]["budget"] / 2

        first = live.wait("an image early in its transfer", early_image)
        b1, v1 = first["image"]["bytes"], first["image"]["view"]["grey"]
        sharper = live.wait(
            "a sharper image",
            lambda s: s["image"]["bytes"] > b1 + 80 and s["image"]["view"]["grey"] != v1,
        )
        assert sharper["image"]["view"]["w"] == 160
        page.screenshot(path=shots / "04-image.png")

        # telemetry and the link panel follow the state
        sent0 = sharper["link"]["uplink"]["sent"]
        live.wait("more orders", lambda s: s["link"]["uplink"]["sent"] > sent0 + 1)
        page.wait_for_function(
            f"(() => {{ const t = document.getElementById('link').innerText;"
            f" const m = t.match(/sent\\s+(\\d+)/); return m && Number(m[1]) > {sent0}; }})()"
        )
        assert "depth" in page.inner_text("#telemetry")

        # ROI drag on the image → an ImageSettings order → the vehicle's coder takes it
        box = page.locator("#image").bounding_box()
        assert box is not None
        page.mouse.move(box["x"] + 0.25 * box["width"], box["y"] + 0.25 * box["height"])
        page.mouse.down()
        page.mouse.move(box["x"] + 0.75 * box["width"], box["y"] + 0.75 * box["height"], steps=5)
        page.mouse.up()
        coded = live.wait("ROI at the coder", lambda s: s["image"]["coder"]["shift"] == 4)
        x0r, y0r, x1r, y1r = coded["image"]["coder"]["roi"]
        assert 35 <= x0r <= 45 and 25 <= y0r <= 35 and 115 <= x1r <= 125 and 85 <= y1r <= 95
        page.screenshot(path=shots / "05-roi.png")

        # supervised control: a click on the track is a GoTo the vehicle flies in GUIDED
        here = coded["truth"]["pos"]
        track = page.locator("#track").bounding_box()
        assert track is not None
        scale = page.evaluate("view.scale")  # [px/m], the page's own track scale
        page.mouse.click(
            track["x"] + track["width"] / 2 + 0.5 * scale,
            track["y"] + track["height"] / 2 - 1.0 * scale,
        )
        aim = (here[0] + 1.0, here[1] + 0.5)
        guided = live.wait(
            "GoTo at the vehicle",
            lambda s: (
                s["truth"]["target"] is not None and (s["operator"] or {}).get("mode") == "guided"
            ),
        )
        goal = guided["truth"]["target"]
        assert math.dist(goal[:2], aim) < 0.3  # the vehicle moved a little since the click

        def gap(s: dict[str, Any]) -> float:
            return math.dist(s["truth"]["pos"][:2], goal[:2])

        start_gap = gap(guided)
        live.wait("closing on the target", lambda s: gap(s) < start_gap - 0.2)
        page.screenshot(path=shots / "06-goto.png")
        press(2)  # X: depth hold ends GUIDED
        live.wait("depth hold", lambda s: (s["operator"] or {}).get("mode") == "depth_hold")

        # a second tab is a read-only viewer; its garbage and floods are counted, not fatal
        viewer = browser.new_page()
        viewer.goto(live.url)
        viewer.wait_for_function("document.getElementById('role').textContent === 'viewer'")
        viewer.evaluate(
            """() => { const w = new WebSocket(`ws://${location.host}/ws`);
            w.onopen = () => { w.send("{not json"); w.send('{"t": "sticks", "x": 9, "y": 0,'
            + ' "z": 0, "yaw": 0}'); for (let i = 0; i < 400; i++) w.send('{"t": "arm",'
            + ' "armed": false}'); }; }"""
        )
        live.wait(
            "garbage counted",
            lambda s: (
                s["console"]["inputs"]["malformed"] >= 1
                and s["console"]["inputs"]["out_of_range"] >= 1
                and s["console"]["inputs"]["flooded"] >= 1
            ),
        )
        viewer.close()
        assert live.state()["truth"]["armed"], "a viewer's disarm was obeyed"

        # the outage button blacks the link out: the vehicle's failsafe holds
        page.click("#outage")
        blackout = live.wait("outage", lambda s: s["link"]["outage"])
        t_out = min(e[0] for e in blackout["events"] if e[2] == "link_outage")
        hold_s = 1.0  # the vehicle's failsafe.hold_after_s: no order for this long → HOLD

        def failsafe_since_outage(s: dict[str, Any]) -> bool:
            entered = any(
                e[2] == "failsafe" and e[3] != "NOMINAL" and e[0] >= t_out for e in s["events"]
            )
            held = s["truth"]["failsafe"] != "NOMINAL" and s["t"] >= t_out + hold_s
            return entered or held

        live.wait("failsafe after the outage", failsafe_since_outage)
        page.screenshot(path=shots / "07-outage.png")
        browser.close()
    t_closed = live.state()["t"]
    live.wait("the run goes on without a browser", lambda s: s["t"] > t_closed + 1.0)

    assert live.stop() == 130  # Ctrl-C ended it
    metrics = json.loads((live.out / "metrics.json").read_text())
    assert metrics["complete"] is False and metrics["live"]["session"] == "live"
    assert metrics["live"]["inputs"]["accepted"] > 10
    assert metrics["live"]["input_to_intent_ms"]["n"] > 10
    events = (live.out / "events.csv").read_text()
    for needed in ("image_settings_sent", "image_settings", "goto_sent", "link_outage", "failsafe"):
        assert needed in events
    assert len(list(shots.iterdir())) == 7
    if os.environ.get("TESTBED_LIVE_SHOTS"):  # keep the screenshots (docs/live-console.png)
        shutil.copytree(shots, os.environ["TESTBED_LIVE_SHOTS"], dirs_exist_ok=True)
