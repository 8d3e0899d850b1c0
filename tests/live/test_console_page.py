"""The console page's own behaviour in headless Chromium against one real ``testbed live``.

One ``testbed live`` process and one browser serve the whole module (each costs seconds);
each test opens its own tab (a fresh browser context) and closes it, so the tests do not
depend on one another's order, and any tab may be the pilot once the previous test's tab has
left (its wait for the seat is a condition, not a sleep). An init script records every message
the page sends on its WebSocket (``window.__sent``), so a test sees what the page asked for.

What the page shows is read from the page; what the session did, from ``/state``. Every wait
is for a condition with a deadline only as the failure bound (``DEADLINE_S``, far beyond what
the model needs on a loaded 2-core machine).
"""

from __future__ import annotations

import contextlib
import json
from collections.abc import Iterator
from typing import Any

import pytest

from tests.live.livesession import DEADLINE_S, Live

_WAIT_MS = DEADLINE_S * 1000.0
"""Failure bound of a wait in the page [ms]."""

_RECORD_SENT = """
window.__sent = [];
const __send = WebSocket.prototype.send;
WebSocket.prototype.send = function (data) {
  window.__sent.push(JSON.parse(String(data))); return __send.call(this, data); };
"""


@pytest.fixture(scope="module")
def live(tmp_path_factory: pytest.TempPathFactory, browser_path: str) -> Iterator[Live]:
    del browser_path
    with Live.running(tmp_path_factory.mktemp("console-page") / "out") as process:
        yield process


@pytest.fixture(scope="module")
def browser(browser_path: str) -> Iterator[Any]:
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        chromium = p.chromium.launch(executable_path=browser_path, args=["--no-sandbox"])
        try:
            yield chromium
        finally:
            chromium.close()


@contextlib.contextmanager
def pilot_tab(browser: Any, live: Live) -> Iterator[Any]:
    """A fresh tab on the console (its own browser context) that holds the pilot's seat."""
    context = browser.new_context(viewport={"width": 1500, "height": 900})
    try:
        page = context.new_page()
        page.set_default_timeout(_WAIT_MS)
        page.add_init_script(_RECORD_SENT)
        page.goto(live.url)
        page.wait_for_function("document.getElementById('role').textContent === 'pilot'")
        yield page
    finally:
        context.close()


@pytest.fixture
def tab(browser: Any, live: Live) -> Iterator[Any]:
    """A fresh tab on the console that holds the pilot's seat."""
    with pilot_tab(browser, live) as page:
        yield page


def _sent(page: Any, kind: str) -> list[dict[str, Any]]:
    sent: list[dict[str, Any]] = page.evaluate("window.__sent")
    return [m for m in sent if m.get("t") == kind]


def _wait_sent_sticks(page: Any, axis: str, value: float) -> None:
    """Until the page has sent a stick message with ``axis`` at ``value``."""
    page.wait_for_function(
        f"window.__sent.some((m) => m.t === 'sticks' && m.{axis} === {json.dumps(value)})"
    )


def test_flying_keys_never_change_the_mode(tab: Any) -> None:
    page = tab
    # a mode picked from the menu is sent once, and the menu lets go of the focus
    page.focus("#mode")
    page.select_option("#mode", "manual")
    assert _sent(page, "mode") == [{"t": "mode", "mode": "manual"}]
    assert page.evaluate("document.activeElement.id") != "mode"
    page.select_option("#mode", "depth_hold")
    assert [m["mode"] for m in _sent(page, "mode")] == ["manual", "depth_hold"]

    # the menu focused again (a click, Tab): the flying keys fly, the menu ignores letters
    page.focus("#mode")
    for key, axis, value in (("KeyS", "x", -0.5), ("KeyD", "y", 0.5), ("KeyA", "y", -0.5)):
        page.keyboard.down(key)
        _wait_sent_sticks(page, axis, value)  # the key was taken, its default action ran
        page.keyboard.up(key)
    page.keyboard.press("KeyM")  # "manual" by type-ahead, were letters let through
    page.keyboard.down("KeyW")
    _wait_sent_sticks(page, "x", 0.5)  # taken after M: M's default action has run
    page.keyboard.up("KeyW")
    assert page.input_value("#mode") == "depth_hold"
    assert [m["mode"] for m in _sent(page, "mode")] == ["manual", "depth_hold"]


def test_the_mode_menu_shows_the_mode_asked_and_the_telemetry_flags_a_vehicle_elsewhere(
    tab: Any, browser: Any, live: Live
) -> None:
    """A page opened (or reloaded) after another asked for a mode shows that mode in its menu,
    not the page's default; a mode asked without the menu (a gamepad button's message) moves the
    menu once the server has it; the telemetry's mode row says the vehicle's mode and, while it
    is not the one asked, both in red."""
    first = tab
    first.evaluate("consoleSend({t: 'mode', mode: 'manual'})")  # as a gamepad's A button does
    try:
        first.wait_for_function("document.getElementById('mode').value === 'manual'")
        live.wait("manual asked", lambda s: s["pilot"]["mode"] == "manual")
        live.wait("manual reported", lambda s: (s["operator"] or {}).get("mode") == "manual")
        first.wait_for_function(f"(({_ROW})(['telemetry', 'mode']) || [''])[0] === 'manual'")
        first.context.close()  # the pilot leaves; a new page takes the seat

        with pilot_tab(browser, live) as page:
            page.wait_for_function("drawn !== null")
            assert page.input_value("#mode") == "manual"  # the page's own default: depth_hold

            # asked, not yet taken: the row holds the vehicle's mode and the one asked, in red
            page.select_option("#mode", "stabilize")
            page.wait_for_function(
                """() => { const cell = [...document.getElementById('telemetry').rows]
                  .find((r) => r.cells[0].textContent === 'mode');
                  return cell && cell.cells[1].innerHTML.includes('class="bad"')
                    && cell.cells[1].textContent === 'manual (asked stabilize)'; }"""
            )
            assert page.input_value("#mode") == "stabilize"
            live.wait("stabilize reported", lambda s: s["operator"]["mode"] == "stabilize")
            page.wait_for_function(f"({_ROW})(['telemetry', 'mode'])[0] === 'stabilize'")
    finally:
        first.context.close()  # (again, if it failed before): the seat is the restorer's
        with pilot_tab(browser, live) as page:
            page.evaluate("consoleSend({t: 'mode', mode: 'depth_hold'})")
            live.wait("depth_hold back", lambda s: s["operator"]["mode"] == "depth_hold")


_ROW = """(args) => { const [table, key] = args;
  const row = [...document.getElementById(table).rows].find((r) => r.cells[0].textContent === key);
  return row ? [...row.cells].slice(1).map((c) => c.textContent) : null; }"""
"""A row of one of the page's tables by its first cell: the other cells' text, or null."""


def test_link_panel_counts_frames_out_of_range(tab: Any, live: Live) -> None:
    page = tab
    legend = page.evaluate("document.getElementById('timeline').nextElementSibling.textContent")
    assert "out of range" in legend, legend
    colours = page.evaluate("KIND_COLOUR")
    assert len(set(colours.values())) == len(colours)  # one colour per fate
    legend_colours = page.evaluate(
        "[...document.querySelectorAll('#legend span')].map((s) => s.style.color)"
    )
    assert len(legend_colours) == len(colours)

    # 2 km away the modems are out of range: the uplink's frames are counted so, on the page too
    page.fill("#distance", "2000")
    page.click("#set-distance")
    try:
        live.wait("out of range", lambda s: s["link"]["uplink"]["out_of_range"] > 0)
        page.wait_for_function(
            f"""() => {{ const row = ({_ROW})(["link", "out of range"]);
            return row !== null && drawn !== null && Number(row[0]) > 0
              && Number(row[0]) === drawn.link.uplink.out_of_range
              && Number(row[1]) === drawn.link.downlink.out_of_range; }}"""
        )
    finally:
        page.click("#reset-distance")
        live.wait("distance reset", lambda s: s["link"]["distance_m"] is None)


def _field_matches(field: str, key: str) -> str:
    """JS: the field shows the drawn state's link value (to its 6 significant digits)."""
    return (
        f"(() => {{ const v = drawn.link.{key}, f = document.getElementById('{field}').value;"
        f" return v === null ? f === '' : f !== '' && Math.abs(Number(f) - v) <= 1e-6 * v; }})()"
    )


def test_link_fields_start_from_the_link_and_refusals_are_shown(tab: Any, live: Live) -> None:
    page = tab
    page.wait_for_function("drawn !== null")  # the first state is drawn: the fields are filled
    ber = page.evaluate("drawn.link.ber")
    assert ber > 0.0  # the scenario's BER: a field left at "0" would make the link error-free
    for field, key in (("ber", "ber"), ("gap", "gap_s"), ("distance", "distance_m")):
        assert page.evaluate(_field_matches(field, key)), (field, page.input_value(f"#{field}"))

    # "set" unedited keeps the link as it is
    page.click("#set-ber")
    page.wait_for_function("window.__sent.some((m) => m.t === 'link')")
    assert _sent(page, "link") == [{"t": "link", "ber": ber}]

    # a BER the server refuses: said in the notes and beside the fields, the field put back
    page.fill("#ber", "0.6")
    page.click("#set-ber")
    page.wait_for_function("document.getElementById('notes').textContent.includes('ber: must')")
    assert "refused" in page.inner_text("#link-refused")
    page.wait_for_function(_field_matches("ber", "ber"))
    assert live.state()["link"]["ber"] == ber

    # a gap of 0 likewise; a blank field is not sent at all
    gap = page.evaluate("drawn.link.gap_s")
    page.fill("#gap", "0")
    page.click("#set-gap")
    page.wait_for_function("document.getElementById('notes').textContent.includes('gap_s: must')")
    page.wait_for_function(_field_matches("gap", "gap_s"))
    page.fill("#gap", "")
    page.click("#set-gap")
    page.wait_for_function("document.getElementById('notes').textContent.includes('no value')")
    page.wait_for_function(_field_matches("gap", "gap_s"))
    assert [m for m in _sent(page, "link") if "gap_s" in m] == [{"t": "link", "gap_s": 0}]
    assert live.state()["link"]["gap_s"] == gap


_CELL_COLOUR = """(key) => { const row = [...document.getElementById('telemetry').rows]
  .find((r) => r.cells[0].textContent === key);
  return row ? getComputedStyle(row.cells[1]).color : null; }"""
"""The computed colour of a telemetry value by its row's name, or null."""


_FLAGGED = "document.getElementById('telemetry').classList.contains('stale')"


def test_stale_telemetry_is_flagged_and_the_failsafe_is_truth_only(tab: Any) -> None:
    page = tab
    page.wait_for_function("drawn !== null && drawn.operator !== null && drawn.operator.age_s < 3")
    fresh = page.evaluate(_CELL_COLOUR, "armed")
    assert "stale" not in page.inner_text("#telemetry")
    # the vehicle's failsafe is physics truth: shown only with the truth overlay, as truth
    assert "failsafe" not in page.inner_text("#telemetry")
    page.keyboard.press("KeyT")
    page.wait_for_function(f"({_ROW})(['telemetry', 'failsafe (truth)']) !== null")
    page.keyboard.press("KeyT")
    page.wait_for_function(
        "![...document.getElementById('telemetry').rows].some((r) =>"
        " r.cells[0].textContent.includes('failsafe'))"
    )

    # a 5-s outage: no reply for over 3 s, so the operator's state is stale, flagged and greyed
    page.evaluate("consoleSend({ t: 'outage', duration_s: 5 })")
    page.wait_for_function(
        f"drawn.operator.age_s > 3 && {_FLAGGED}"
        " && document.getElementById('telemetry').textContent.includes('stale')"
    )
    assert page.evaluate(_CELL_COLOUR, "armed") != fresh
    # replies resume after the outage: no longer stale
    page.wait_for_function(f"drawn.operator.age_s < 3 && !{_FLAGGED}")
    assert page.evaluate(_CELL_COLOUR, "armed") == fresh


def test_a_viewers_controls_look_greyed_and_both_count_connected(tab: Any, browser: Any) -> None:
    pilot = tab
    context = browser.new_context()
    try:
        viewer = context.new_page()
        viewer.set_default_timeout(_WAIT_MS)
        viewer.goto(pilot.url)
        viewer.wait_for_function("document.getElementById('role').textContent === 'viewer'")
        header = "document.querySelector('header').innerText"
        for page in (pilot, viewer):
            page.wait_for_function(f"/connected 2\\b/.test({header})")
            assert "viewers" not in page.evaluate(header)
        opacity = "(id) => getComputedStyle(document.getElementById(id)).opacity"
        for control in ("arm", "mode", "ber", "set-ber"):
            assert viewer.is_disabled(f"#{control}") and pilot.is_enabled(f"#{control}")
            assert float(viewer.evaluate(opacity, control)) < 0.6, control
            assert float(pilot.evaluate(opacity, control)) == 1.0, control
    finally:
        context.close()


def test_a_new_pilot_page_keeps_the_coders_roi_when_it_changes_only_the_budget(
    browser: Any, live: Live
) -> None:
    """A pilot sets an ROI and leaves; the next page (a new seat, a reload) starts from the
    coder's settings in effect, so sending a new budget keeps the ROI and its shift. It sent
    roi null, shift 0 (the page's own empty ROI), erasing the first pilot's region."""
    coder = "document.getElementById('img-coder').textContent"
    with pilot_tab(browser, live) as first:
        first.evaluate("send({t: 'image', roi: [10, 10, 67, 50], shift: 5, budget: 1200})")
        first.wait_for_function(f"{coder}.startsWith('roi 10,10,67,50 shift 5 budget 1200')")
    with pilot_tab(browser, live) as second:
        second.wait_for_function(f"{coder}.startsWith('roi 10,10,67,50 shift 5')")
        second.fill("#budget", "800")
        second.click("#send-image")
        (sent,) = _sent(second, "image")
        assert (sent["roi"], sent["shift"], sent["budget"]) == ([10, 10, 67, 50], 5, 800)
        second.wait_for_function(f"{coder}.startsWith('roi 10,10,67,50 shift 5 budget 800')")
