"""A pilot's bad stick sample is refused when the pilot is sampled, whatever the codec.

A pilot is local code: a NaN or out-of-range stick is its bug. Before, the teleop codec raised
'x deflection must be finite' while encoding and the change-set codec carried the NaN to the
vehicle, whose stick clip turned it into a full stick (a review flew tether-teleop-v1 at full
surge, ref_u 1.327 m/s, with cmd_x NaN).
"""

from __future__ import annotations

import math

import pytest

from testbed.operator.pilots import PilotSample
from testbed.operator.station import OperatorStation, SessionPlan
from testbed.run.runner import run_scenario
from testbed.run.scenario import load_scenario
from testbed.run.sections import PilotSection


class BadSurge:
    """Centred sticks, then from 1 s a surge stick of ``value``."""

    def __init__(self, value: float) -> None:
        self.value = value

    def sample(self, t_s: float) -> PilotSample:
        surge = self.value if t_s >= 1.0 else 0.0
        return PilotSample((surge, 0.0, 0.0, 0.0, 0.0, 0.0))


@pytest.mark.parametrize(
    ("scenario", "codec"),
    [("tether-teleop-v1", "changeset"), ("s100-teleop-v1", "teleop")],
)
def test_a_nan_stick_stops_the_run_at_sampling_for_both_codecs(
    scenario: str, codec: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    loaded = load_scenario(
        scenario, ["duration_s=3.0", "trials=1", "pilot.start_s=0.5", "metrics.settle_s=0.5"]
    )
    assert loaded.link.codec == codec
    monkeypatch.setattr(PilotSection, "pilot", lambda self: BadSurge(math.nan))
    with pytest.raises(ValueError, match=r"^pilot BadSurge \(.*\): sample\(1\.\d+\): surge stick "):
        run_scenario(loaded)


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf, 1.5, -1.0000001])
def test_the_station_refuses_a_non_finite_or_out_of_range_stick(value: float) -> None:
    station = OperatorStation(BadSurge(value), SessionPlan(arm_at_s=100.0))
    station.frame(0.5)
    with pytest.raises(ValueError, match=r"pilot BadSurge: surge stick .* got "):
        station.frame(1.0)
    command = station.latest_command()
    assert command is not None and command.sticks[0] == 0.0  # the bad sample was not written


def test_full_sticks_and_the_wrong_count_of_sticks() -> None:
    station = OperatorStation(BadSurge(-1.0), SessionPlan(arm_at_s=100.0))
    station.frame(1.0)  # ±1 exactly is a full stick, accepted
    command = station.latest_command()
    assert command is not None and command.sticks[0] == -1.0

    class Five:
        def sample(self, t_s: float) -> PilotSample:
            return PilotSample((0.0,) * 5)  # type: ignore[arg-type]

    with pytest.raises(ValueError, match=r"^pilot Five: 5 sticks sampled, expected 6$"):
        OperatorStation(Five(), SessionPlan(arm_at_s=100.0)).frame(0.0)


def test_a_pilot_without_sample_or_returning_no_pilot_sample_is_named() -> None:
    """A review's two broken pilots: one with no sample method failed only once the simulation
    ran, deep inside simpy, and one returning a bare tuple raised AttributeError 'sticks'."""

    class NoSample:
        pass

    class Bare:
        def sample(self, t_s: float) -> tuple[float, ...]:
            return (0.0,) * 6

    scenario = load_scenario(
        "s100-teleop-v1", ["duration_s=3.0", "pilot.start_s=0.5", "metrics.settle_s=0.5"]
    )
    with pytest.raises(
        TypeError, match=r"^pilot: expected an object with sample\(t_s\) .* NoSample"
    ):
        run_scenario(scenario, pilot=NoSample())  # type: ignore[arg-type]
    expected = r"^pilot .*Bare \(.*\): sample\(0\.0\): got a tuple, not a PilotSample .*$"
    with pytest.raises(TypeError, match=expected):
        run_scenario(scenario, pilot=Bare())  # type: ignore[arg-type]
