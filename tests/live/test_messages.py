"""Browser messages are parsed as data: every input is a value or a counted rejection."""

from __future__ import annotations

import json

import pytest
from hypothesis import given
from hypothesis import strategies as st

from testbed.live.messages import (
    MAX_MESSAGE_BYTES,
    Arm,
    GoToPoint,
    ImageRequest,
    InputCounters,
    LatencyReport,
    LinkChange,
    Outage,
    Ping,
    RateLimit,
    Rejected,
    SetMode,
    StickInput,
    parse_message,
)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ('{"t": "sticks", "x": 0.5, "y": -1, "z": 0, "yaw": 1}', StickInput(0.5, -1.0, 0.0, 1.0)),
        ('{"t": "arm", "armed": true}', Arm(True)),
        ('{"t": "mode", "mode": "stabilize"}', SetMode("stabilize")),
        (
            '{"t": "image", "roi": [40, 30, 119, 89], "shift": 4, "budget": 600}',
            ImageRequest((40, 30, 119, 89), 4, 600),
        ),
        ('{"t": "image", "roi": null, "shift": 0, "budget": 1200}', ImageRequest(None, 0, 1200)),
        ('{"t": "link", "ber": 0.0001}', LinkChange("ber", 0.0001)),
        ('{"t": "link", "gap_s": null}', LinkChange("gap_s", None)),
        ('{"t": "link", "distance_m": 500}', LinkChange("distance_m", 500.0)),
        ('{"t": "outage", "duration_s": 3}', Outage(3.0)),
        ('{"t": "goto", "x": 2.5, "y": -1}', GoToPoint(2.5, -1.0)),
        ('{"t": "ping", "c": 1234.5}', Ping(1234.5)),
        ('{"t": "lat", "pixels_ms": 12.5}', LatencyReport(12.5, None)),
    ],
)
def test_valid_messages_parse_to_values(text: str, expected: object) -> None:
    assert parse_message(text) == expected


@pytest.mark.parametrize(
    "text",
    [
        "{not json",
        "[1, 2]",
        '"sticks"',
        "",
        '{"t": "launch_missiles"}',
        '{"x": 1}',
        '{"t": "sticks", "x": "0.5", "y": 0, "z": 0, "yaw": 0}',
        '{"t": "sticks", "x": true, "y": 0, "z": 0, "yaw": 0}',
        '{"t": "sticks", "x": 0, "y": 0, "z": 0}',
        '{"t": "arm", "armed": 1}',
        '{"t": "image", "roi": [1, 2, 3], "shift": 0, "budget": 10}',
        '{"t": "image", "roi": null, "shift": 1.5, "budget": 10}',
        '{"t": "link", "ber": 0.1, "gap_s": 1}',
        '{"t": "link"}',
        "[" * 100_000,
        b"\xff\xfe",
    ],
)
def test_malformed_messages_are_rejected_as_malformed(text: str | bytes) -> None:
    parsed = parse_message(text)
    assert isinstance(parsed, Rejected) and parsed.kind == "malformed"


@pytest.mark.parametrize(
    "text",
    [
        '{"t": "sticks", "x": 1.01, "y": 0, "z": 0, "yaw": 0}',
        '{"t": "sticks", "x": NaN, "y": 0, "z": 0, "yaw": 0}',
        '{"t": "sticks", "x": 0, "y": -Infinity, "z": 0, "yaw": 0}',
        '{"t": "sticks", "x": 0, "y": 0, "z": 1e308, "yaw": 0}',
        # an integer beyond any float: JSON integers are unbounded (float() would overflow)
        '{"t": "sticks", "x": 1' + "0" * 400 + ', "y": 0, "z": 0, "yaw": 0}',
        '{"t": "goto", "x": -1' + "0" * 400 + ', "y": 0}',
        '{"t": "lat", "pixels_ms": 1' + "0" * 400 + ', "rtt_ms": 1}',
        '{"t": "ping", "c": 1' + "0" * 400 + "}",
        '{"t": "mode", "mode": "guided"}',
        '{"t": "image", "roi": [50, 0, 40, 10], "shift": 0, "budget": 10}',
        '{"t": "image", "roi": [0, 0, 2000, 10], "shift": 0, "budget": 10}',
        '{"t": "image", "roi": null, "shift": 16, "budget": 10}',
        '{"t": "image", "roi": null, "shift": 0, "budget": 0}',
        '{"t": "link", "ber": 0.9}',
        '{"t": "link", "gap_s": 0.001}',
        '{"t": "outage", "duration_s": 3600}',
        '{"t": "goto", "x": 400, "y": 0}',
    ],
)
def test_out_of_range_values_are_rejected_as_range(text: str) -> None:
    parsed = parse_message(text)
    assert isinstance(parsed, Rejected) and parsed.kind == "range", parsed


def test_a_message_longer_than_the_limit_is_not_parsed() -> None:
    text = json.dumps({"t": "ping", "c": 1, "pad": "x" * MAX_MESSAGE_BYTES})
    assert parse_message(text) == Rejected("malformed", f"longer than {MAX_MESSAGE_BYTES} B")


@given(st.one_of(st.text(max_size=200), st.binary(max_size=200)))
def test_any_input_is_a_value_never_an_exception(text: str | bytes) -> None:
    parsed = parse_message(text)
    assert parsed is not None


_VALUES = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(),
    st.floats(),
    st.text(max_size=10),
    st.lists(st.integers(), max_size=5),
)


@given(st.dictionaries(st.sampled_from(["t", "x", "y", "z", "yaw", "armed", "roi"]), _VALUES))
def test_any_json_object_is_a_value_never_an_exception(obj: dict[str, object]) -> None:
    obj.setdefault("t", "sticks")
    assert parse_message(json.dumps(obj)) is not None


def test_counters_sort_rejections() -> None:
    counters = InputCounters()
    for text in ("{", '{"t": "mode", "mode": "x"}', '{"t": "arm", "armed": false}'):
        counters.count(parse_message(text))
    assert counters.as_dict() == {
        "accepted": 1,
        "malformed": 1,
        "out_of_range": 1,
        "flooded": 0,
        "not_pilot": 0,
        "bad_requests": 0,
        "foreign_host": 0,
        "foreign_origin": 0,
        "too_many": 0,
    }


def test_the_size_limit_is_in_bytes_not_characters() -> None:
    # 1,400 three-byte characters: 1,4xx characters but over 4,096 bytes of UTF-8
    text = json.dumps({"t": "ping", "c": 1, "pad": "€" * 1400}, ensure_ascii=False)
    assert len(text) < MAX_MESSAGE_BYTES < len(text.encode())
    assert parse_message(text) == Rejected("malformed", f"longer than {MAX_MESSAGE_BYTES} B")
    fits = json.dumps({"t": "ping", "c": 1, "pad": "€" * 1000}, ensure_ascii=False)
    assert len(fits.encode()) <= MAX_MESSAGE_BYTES and not isinstance(parse_message(fits), Rejected)


def test_rate_limit_sheds_a_flood_and_refills() -> None:
    now = [0.0]
    limit = RateLimit(rate_hz=10.0, burst=5, clock_s=lambda: now[0])
    assert sum(limit.allow() for _ in range(100)) == 5
    now[0] = 1.0
    assert sum(limit.allow() for _ in range(100)) == 5  # refilled to the burst, not beyond
    now[0] = 1.25
    assert sum(limit.allow() for _ in range(100)) == 2


def test_rate_limit_refuses_nonsense_settings() -> None:
    with pytest.raises(ValueError):
        RateLimit(rate_hz=0.0)
