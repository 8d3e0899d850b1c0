"""ArduSub's own rules the endpoint follows (testbed.mavlink.ardusub), worked by hand."""

from __future__ import annotations

import pytest

from testbed.mavlink.ardusub import boot_gain
from testbed.mavlink.params import Param, ParamTable
from testbed.mavlink.streams import GROUP_PARAMS, STREAM_GROUPS, StreamSchedule


@pytest.mark.parametrize(
    ("default", "low", "high", "steps", "gain"),
    [
        (0.5, 0.25, 1.0, 4, 0.5),  # ArduSub's defaults: the default
        (1.005, 0.25, 1.0, 4, 1.0),  # within 0.01 of the range: clamped into it
        (1.5, 0.25, 1.0, 4, 0.5),  # outside: the step nearest the middle, 0.25 + 1·0.75/3
        (1.5, 0.25, 1.0, 1, 1.0),  # one step: the default clamped
        (0.05, 0.01, 0.08, 4, 0.1),  # then within [0.1, 1]
    ],
)
def test_the_boot_gain_is_init_joysticks(
    default: float, low: float, high: float, steps: int, gain: float
) -> None:
    """ArduSub's Sub::init_joystick (ArduSub/joystick.cpp), worked by hand."""
    assert boot_gain(default, low, high, steps) == pytest.approx(gain)


@pytest.mark.parametrize(
    ("sent", "stored"), [(1.7, 1.0), (1.999, 2.0), (2.0, 2.0), (-1.7, -1.0), (-0.995, -1.0)]
)
def test_an_integer_parameter_takes_a_float_as_ardupilots_param_set(
    sent: float, stored: float
) -> None:
    """GCS_MAVLINK::handle_param_set: 0.01 added away from zero, then the cast truncates (a
    float just under an integer, as a float32 may carry it, is that integer; 1.7 is 1)."""
    table = ParamTable((Param("SOME_INT", "INT16", 0.0),))
    assert table.set("SOME_INT", sent) == 0 and table["SOME_INT"] == stored


def test_message_interval_zero_is_the_groups_stream_rate_as_last_requested() -> None:
    """ArduPilot's set_message_interval(id, 0) takes the default from the message's stream,
    whose rate REQUEST_DATA_STREAM sets: after EXTRA1 (ATTITUDE's group) at 20 Hz, a custom
    interval then 0 is back at 20 Hz (a user review: it went back to the boot 10 Hz)."""
    schedule = StreamSchedule(dict.fromkeys(GROUP_PARAMS, 10.0))
    extra1 = next(group for group, names in STREAM_GROUPS.items() if "ATTITUDE" in names)
    assert schedule.set_group(extra1, 20.0)
    assert schedule.set_interval("ATTITUDE", 500_000)
    assert schedule.interval_us("ATTITUDE") == 500_000
    assert schedule.set_interval("ATTITUDE", 0)
    assert schedule.interval_us("ATTITUDE") == 50_000  # 20 Hz, not the boot 10 Hz
