"""ArduSub's own rules the endpoint follows (testbed.mavlink.ardusub), worked by hand."""

from __future__ import annotations

import pytest

from testbed.mavlink.ardusub import boot_gain


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
