"""The recorder's files and its memory: events.csv in time order, series.csv round trip, and the
bytes a link event and a series row take (testbed.run.recorder, testbed.channel.trace)."""

from __future__ import annotations

import csv
import math
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from testbed.channel import EventKind, LinkEvent, Trace
from testbed.run.outputs import write_run
from testbed.run.recorder import SERIES_COLUMNS, FloatPairs, Recorder, SeriesRows
from testbed.run.runner import run_scenario
from testbed.run.scenario import load_scenario
from tests.interrupts import interrupt_at_line

K = EventKind
OP, VEH, ALL = "operator", "vehicle", "*"

BYTES_PER_EVENT_BOUND = 24
"""Link events: 21 B of columns each, plus the columns' over-allocation."""
BYTES_PER_SERIES_VALUE_BOUND = 9.0
"""Series rows: one 8-B double per value, plus over-allocation."""


def read_rows(path: Path) -> list[list[str]]:
    with path.open(newline="", encoding="utf-8") as handle:
        return list(csv.reader(handle))


def test_events_csv_is_in_time_order_with_recording_order_breaking_ties(tmp_path: Path) -> None:
    rec = Recorder()
    rec.trace.record(1.0, K.ENQUEUE, OP, ALL, 0, 0, 20)
    rec.trace.record(1.0, K.TX_START, OP, ALL, 0, 0, 20)
    rec.trace.record(1.5, K.TX_END, OP, ALL, 0, 0, 20)  # recorded at its start, a future time
    rec.trace.record(1.2, K.ENQUEUE, VEH, ALL, 1, 0, 30)
    rec.trace.record(1.5, K.DELIVER, OP, VEH, 0, 0, 20)  # same time as the tx_end: after it
    rec.trace.record(1.5, K.CORRUPT, VEH, OP, 1, 2, 30, 7)
    rec.trace.record(0.5, K.DROP, VEH, ALL, 2, 0, 30)  # out of order
    rec.event(1.5, VEH, "failsafe", "HOLD")  # same time as link events: after them
    rec.event(0.0, "scenario", "outage", 'until 2, then "more"')  # quoted by csv
    rec.event(1.5, VEH, "armed")

    path = tmp_path / "events.csv"
    rec.write_events_csv(path)
    rows = read_rows(path)

    assert rows[0] == ["t_s", "source", "kind", "src", "dst", "frame_id", "part", "size_bytes",
                       "bit_errors", "detail"]  # fmt: skip
    assert [r[:3] for r in rows[1:]] == [
        ["0.000000000", "scenario", "outage"],
        ["0.500000000", "link", "drop"],
        ["1.000000000", "link", "enqueue"],
        ["1.000000000", "link", "tx_start"],
        ["1.200000000", "link", "enqueue"],
        ["1.500000000", "link", "tx_end"],
        ["1.500000000", "link", "deliver"],
        ["1.500000000", "link", "corrupt"],
        ["1.500000000", VEH, "failsafe"],
        ["1.500000000", VEH, "armed"],
    ]
    assert rows[8] == ["1.500000000", "link", "corrupt", VEH, OP, "1", "2", "30", "7", ""]
    assert rows[1] == ["0.000000000", "scenario", "outage", "", "", "", "", "", "",
                       "until 2, then \"more\""]  # fmt: skip
    text = path.read_text(encoding="utf-8")
    assert text.splitlines()[1] == '0.000000000,scenario,outage,,,,,,,"until 2, then ""more"""'
    assert text.endswith("\n") and "\r" not in text


def test_events_csv_of_an_empty_recorder_is_its_header(tmp_path: Path) -> None:
    path = tmp_path / "events.csv"
    Recorder().write_events_csv(path)
    assert len(read_rows(path)) == 1


def test_events_csv_across_write_chunks_stays_in_time_order(tmp_path: Path) -> None:
    rec = Recorder()
    rng = np.random.default_rng(3)
    times = np.round(rng.uniform(0.0, 10.0, 40_000), 3)  # many equal times
    for i, t_s in enumerate(times.tolist()):
        rec.trace.record(t_s, K.DELIVER, OP, VEH, i, 0, 20)
    for t_s in (0.0, 5.0, 10.0, 11.0):
        rec.event(t_s, VEH, "mark")
    path = tmp_path / "events.csv"
    rec.write_events_csv(path)
    rows = read_rows(path)[1:]
    expected = sorted(
        [(t, 0, i, "link") for i, t in enumerate(times.tolist())]
        + [(t, 1, i, VEH) for i, t in enumerate((0.0, 5.0, 10.0, 11.0))]
    )
    assert [(r[1], r[5]) for r in rows] == [
        (source, str(i) if source == "link" else "") for _, _, i, source in expected
    ]


def test_series_csv_round_trips(tmp_path: Path) -> None:
    rec = Recorder()
    rng = np.random.default_rng(1)
    table = rng.normal(0.0, 100.0, (50, len(SERIES_COLUMNS)))
    table[3, 5] = math.nan
    for row in table:
        rec.rows.append(tuple(row.tolist()))
    path = tmp_path / "series.csv"
    rec.write_series_csv(path)
    rows = read_rows(path)
    assert rows[0] == list(SERIES_COLUMNS)
    back = np.array(rows[1:], dtype=float)
    assert np.allclose(back, table, rtol=1e-5, equal_nan=True)  # 6 significant digits
    assert [",".join(f"{v:.6g}" for v in row) for row in table.tolist()] == [
        ",".join(r) for r in rows[1:]
    ]
    series = rec.series()
    assert np.array_equal(series["t_s"], table[:, 0])
    assert np.array_equal(np.asarray(rec.rows), table, equal_nan=True)


def test_series_rows_give_back_their_tuples_and_refuse_a_wrong_width() -> None:
    rows = SeriesRows(3, [(1.0, 2.0, 3.0)])
    rows.append((4.0, 5.0, 6.0))
    assert list(rows) == [(1.0, 2.0, 3.0), (4.0, 5.0, 6.0)] and len(rows) == 2
    with pytest.raises(ValueError, match="3 values"):
        rows.append((1.0, 2.0))


def test_a_recorder_with_a_plain_list_of_rows_writes_the_same_file(tmp_path: Path) -> None:
    table = [tuple(float(k + i) for k in range(len(SERIES_COLUMNS))) for i in range(5)]
    compact, plain = Recorder(), Recorder(rows=list(table))
    for row in table:
        compact.rows.append(row)
    compact.write_series_csv(tmp_path / "a.csv")
    plain.write_series_csv(tmp_path / "b.csv")
    assert (tmp_path / "a.csv").read_bytes() == (tmp_path / "b.csv").read_bytes()
    assert np.array_equal(compact.series()["cmd_x"], plain.series()["cmd_x"])


def test_trace_events_view_builds_the_recorded_events() -> None:
    trace = Trace()
    events = [LinkEvent(0.1 * i, K.DELIVER, OP, VEH, i, i % 3, 20 + i, i % 2) for i in range(9999)]
    for event in events:
        trace.record(*event)
    assert trace.events == events and list(trace) == events and len(trace.events) == 9999
    assert trace.events[-1] == events[-1] and trace.events[4096:4100] == events[4096:4100]
    assert trace.events[::1000] == events[::1000]
    assert trace.events[5].kind is K.DELIVER


def test_link_events_take_under_the_bound_per_event() -> None:
    n = 250_000  # 22.10 B an event here, 22.20 B at 10^6 (the columns' over-allocation)
    tracemalloc.start()
    try:
        before, _ = tracemalloc.get_traced_memory()
        trace = Trace()
        record = trace.record
        for i in range(n):
            record(i * 1e-3, K.DELIVER, OP, VEH, i, 0, 60)
        trace.columns()  # the last pending events moved to the columns
        after, _ = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert len(trace) == n
    assert trace.nbytes == 21 * n  # frame ids below 2**31, sizes below 2**15
    assert (after - before) / n < BYTES_PER_EVENT_BOUND


def test_series_rows_take_under_the_bound_per_value() -> None:
    n = 100_000
    width = len(SERIES_COLUMNS)
    row = tuple(float(k) for k in range(width))
    tracemalloc.start()
    try:
        before, _ = tracemalloc.get_traced_memory()
        rows = SeriesRows()
        for _ in range(n):
            rows.append(row)
        after, _ = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert rows.nbytes == 8 * width * n
    assert (after - before) / (n * width) < BYTES_PER_SERIES_VALUE_BOUND


def test_trace_columns_widen_for_values_that_do_not_fit() -> None:
    trace = Trace()
    events = [LinkEvent(0.0, K.DELIVER, OP, VEH, 0, 0, 20)]
    events += [LinkEvent(1.0, K.CORRUPT, OP, VEH, -1, 1, 40_000, 70_000)]  # past int16
    events += [LinkEvent(2.0, K.DELIVER, OP, VEH, 2**40, 2**33, 20)]  # past int32
    events += [LinkEvent(3.0, K.ENQUEUE, f"node{i}", ALL, i, 0, 20) for i in range(300)]
    for event in events:
        trace.record(*event)
    assert list(trace) == events
    columns = trace.columns()
    assert columns.frame_id.dtype == np.int64 and columns.src.dtype == np.uint16
    with pytest.raises(OverflowError):
        Trace.of([LinkEvent(0.0, K.DELIVER, OP, VEH, 2**63, 0, 20)]).columns()


def test_float_pairs_give_back_their_tuples() -> None:
    pairs = FloatPairs([(1.0, 2.0)])
    for i in range(10_000):
        pairs.append((float(i), i + 0.5))
    assert len(pairs) == 10_001 and pairs[0] == (1.0, 2.0) and pairs[-1] == (9999.0, 9999.5)
    assert list(pairs)[1:3] == [(0.0, 0.5), (1.0, 1.5)] == pairs[1:3]
    assert pairs == [(1.0, 2.0), *((float(i), i + 0.5) for i in range(10_000))]
    assert Recorder().command_updates == []


def test_an_interrupt_anywhere_in_appending_a_pair_keeps_the_pairs_whole() -> None:
    # the command and odometry updates are flat float pairs: an interrupt while one is added
    # leaves it wholly in or wholly out, never one value of it
    k = 1
    while True:
        pairs = FloatPairs([(0.0, -1.0), (1.0, 0.5)])
        with interrupt_at_line(k, FloatPairs.append) as seen:
            pairs.append((2.0, 1.5))
        assert list(pairs) in ([(0.0, -1.0), (1.0, 0.5)], [(0.0, -1.0), (1.0, 0.5), (2.0, 1.5)])
        pairs.append((3.0, 2.5))
        assert list(pairs)[-1] == (3.0, 2.5)
        if not seen["raised"]:
            break
        k += 1
    assert k > 1


def test_the_event_file_tells_when_the_vehicle_armed_and_changed_mode() -> None:
    """The vehicle's arming and modes in effect are events, at the frame they took effect: on
    s100-teleop-v1 the session plan's arm and DEPTH_HOLD requests (sent at operator.arm_at_s)
    take effect when the order carrying them arrives, after the link's intrinsic delay and the
    order's air time (13 B at 1900 bit/s), in the next vehicle frame."""
    scenario = load_scenario("s100-teleop-v1", ["duration_s=10", "metrics.settle_s=1"])
    result = run_scenario(scenario)
    story = [(e.t_s, e.kind, e.detail) for e in result.recorder.events if e.node == "vehicle"]
    assert [kind for _, kind, _ in story] == ["mode", "arm", "mode"]
    assert story[0][2] == "MANUAL" and story[2][2] == "DEPTH_HOLD"
    channel = scenario.link.channel
    crossing = channel.intrinsic_delay_s + 8 * 13 / channel.bitrate_bps
    arm_at = scenario.operator.arm_at_s
    sent = min(
        e.t_s
        for e in result.recorder.trace.events
        if e.kind is EventKind.TX_START and e.src == "operator" and e.t_s >= arm_at
    )
    assert story[1][0] == story[2][0]
    assert sent + crossing <= story[1][0] <= sent + crossing + 0.01 + 1e-9


def test_the_mode_column_is_manual_until_the_operators_mode_arrives_then_depth_hold() -> None:
    """s100-teleop-v1's operator arms in depth hold at 1 s: the vehicle boots in MANUAL (19,
    ArduSub's number) and the column turns to DEPTH_HOLD (2) once, when the first order has
    crossed the link (its frame takes > 0.3 s at 1900 bit/s), and stays there; in
    s100-outage-v1 the failsafe column is HOLD (1) from the first row 1 s (the failsafe's
    staleness timeout) after the last order the vehicle took before the outage, until the
    first order after it."""
    result = run_scenario(load_scenario("s100-teleop-v1", ["duration_s=20", "metrics.settle_s=5"]))
    series = result.recorder.series()
    t, mode = series["t_s"], series["mode"]
    (changes,) = np.nonzero(np.diff(mode))
    assert len(changes) == 1 and mode[0] == 19.0 and mode[-1] == 2.0
    assert 1.3 < t[changes[0] + 1] < 2.0
    outage = run_scenario(load_scenario("s100-outage-v1", ["duration_s=70", "metrics.settle_s=5"]))
    series = outage.recorder.series()
    held = series["t_s"][series["failsafe"] == 1.0]
    assert set(np.unique(series["failsafe"])) == {0.0, 1.0}
    taken = [frame_s for frame_s, _ in outage.recorder.command_updates]
    before = max(t_s for t_s in taken if t_s < 60.0)  # the outage: 60–62 s
    after = min(t_s for t_s in taken if t_s > 60.0)
    row_s = 1.0 / outage.scenario.metrics.sample_rate_hz
    assert before + 1.0 <= held[0] < before + 1.0 + row_s + 0.011  # + a 100-Hz frame
    assert held[-1] < after <= held[-1] + row_s
    assert len(held) == round((after - held[0]) / row_s)  # no gap inside


def test_a_go_to_in_guided_is_the_series_target_as_the_position_loop_flies_it() -> None:
    """Without an autonomy's pose target the target_* columns were NaN even while the vehicle
    flew an operator's go-to in GUIDED (the live console's click): they now hold the
    PositionSetpoint the position loop takes, its heading in degrees (NaN when it sets none),
    and stay NaN outside GUIDED."""
    from testbed.common.components import ArmRequest, ControlMode, ModeRequest
    from testbed.common.components import PositionSetpoint as GoTo
    from testbed.ecs import Phase
    from testbed.operator.pilots import PilotSample
    from testbed.run.observer import VehicleObserver
    from testbed.vehicle.vehicle import Vehicle

    class Centred:
        def sample(self, t_s: float) -> PilotSample:
            return PilotSample((0.0,) * 6)

    scenario = load_scenario("s100-teleop-v1", ["vehicle.sensors.position.noise_m=0"])
    with Vehicle(scenario.vehicle, np.random.default_rng(0)) as vehicle:
        recorder = Recorder(trace=Trace())
        observer = VehicleObserver(recorder, Centred(), vehicle.reference_velocity, 20.0)
        vehicle.schedule.add(Phase.POST_UPDATE, observer, name="record_vehicle")
        world, intents = vehicle.world, vehicle.operator_entity
        world.set(intents, ArmRequest(True, 1))
        world.set(intents, ModeRequest(ControlMode.DEPTH_HOLD))
        world.set(intents, GoTo((2.0, 1.0, 1.2), 0.5, True))
        vehicle.advance(1.0)  # not GUIDED: no target
        world.set(intents, ModeRequest(ControlMode.GUIDED))
        vehicle.advance(2.0)
        world.set(intents, GoTo((-1.0, 0.5, 1.0)))  # no heading of its own
        vehicle.advance(3.0)
    series = recorder.series()
    t = series["t_s"]
    columns = [series[c] for c in ("target_n", "target_e", "target_d", "target_yaw_deg")]
    first, second = (t > 1.05) & (t < 2.0), t > 2.05
    assert all(np.isnan(c[t < 0.95]).all() for c in columns)
    assert [np.unique(c[first]).tolist() for c in columns] == [
        [2.0],
        [1.0],
        [1.2],
        [pytest.approx(math.degrees(0.5))],
    ]
    assert [np.unique(c[second]).tolist() for c in columns[:3]] == [[-1.0], [0.5], [1.0]]
    assert np.isnan(columns[3][second]).all()


def test_events_csv_ends_at_the_run_end_with_a_transmission_still_on_the_air(
    tmp_path: Path,
) -> None:
    """m64's 8-B packets take 1 s each: a 40-s run ends with the reply's packet of 39.2–40.2 s
    on the air. Its end is traced as it starts (t = 40.2 s), but the run never got there: the
    file stops at the run's end (a link-model researcher's review found rows after it)."""
    scenario = load_scenario("m64-teleop-v1", ["duration_s=40", "link.ber=0"])
    result = run_scenario(scenario)
    ends = [e.t_s for e in result.recorder.trace.of_kind(EventKind.TX_END)]
    assert max(ends) > 40.0  # the case: traced, beyond the end
    write_run(result, tmp_path)
    with (tmp_path / "events.csv").open(newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    assert max(float(row["t_s"]) for row in rows) <= 40.0
    written = sum(1 for row in rows if row["kind"] == "tx_end")
    assert written == sum(1 for t in ends if t <= 40.0)


@pytest.mark.parametrize(
    ("mode", "attitude_held", "depth_held"),
    [("manual", False, False), ("stabilize", True, False), ("depth_hold", True, True)],
)
def test_the_error_columns_are_against_what_a_hold_flies(
    mode: str, attitude_held: bool, depth_held: bool
) -> None:
    """Armed, the attitude error columns and the depth target are recorded only while the hold
    of that axis flies (ArduSub's MANUAL flies no attitude target: an error against the
    targets kept from arming measured nothing); ``attitude_error_deg`` and ``depth_error_m``
    are then null, not a figure of a target nobody flew."""
    scenario = load_scenario("s100-teleop-v1", ["duration_s=20", f"operator.mode={mode!r}"])
    result = run_scenario(scenario)
    series = result.recorder.series()
    armed = series["armed"] == 1.0
    assert armed.sum() > 0
    for axis in ("roll", "pitch", "yaw"):
        column = series[f"err_{axis}_deg"][armed]
        assert np.isfinite(column).all() if attitude_held else np.isnan(column).all(), axis
        std = result.metrics["attitude_error_deg"][axis]["std"]
        assert math.isfinite(std) is attitude_held
    depth = series["depth_target_m"][armed]
    assert np.isfinite(depth).all() if depth_held else np.isnan(depth).all()
    assert math.isfinite(result.metrics["depth_error_m"]["mean"]) is depth_held
