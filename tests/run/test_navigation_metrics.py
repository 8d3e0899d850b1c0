"""The ``"navigation"`` key of ``metrics.json`` and the summary line on gate rejections.

A review flew heavy-waypoint-v1 on 5-Hz, 2-cm motion-capture fixes without an accelerometer at
the default process noise: the filter's χ² gate rejected a quarter of the (good) fixes, the
mission failed, and nothing in the output said so.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from testbed.cli.run_summary import format_summary, format_trial, gate_rejections
from testbed.run.runner import run_scenario
from testbed.run.scenario import load_scenario
from testbed.vehicle import localization
from testbed.vehicle.localization import KalmanLocalizer

SLOW_FIXES = "vehicle.navigation={motion_capture={rate_hz=5.0, noise_m=0.02, latency_s=0.0}}"


def test_a_gated_run_reports_the_filters_own_counters(monkeypatch: pytest.MonkeyPatch) -> None:
    made: list[KalmanLocalizer] = []

    class Kept(KalmanLocalizer):
        def __init__(self, *args: object, **kwargs: object) -> None:
            super().__init__(*args, **kwargs)  # type: ignore[arg-type]
            made.append(self)

    monkeypatch.setattr(localization, "KalmanLocalizer", Kept)
    scenario = load_scenario("heavy-waypoint-v1", ["trials=1", "duration_s=12.0", SLOW_FIXES])
    metrics = run_scenario(scenario).metrics
    (localizer,) = made
    own = localizer.navigator.counters
    reported = metrics["navigation"]
    assert reported["filter"]["rejected"] == own.rejected > 0
    assert reported["filter"] == {
        "accepted": own.accepted,
        "rejected": own.rejected,
        "invalid": own.invalid,
        "stale": own.stale,
        "rollbacks": own.rollbacks,
        "reacquired": own.reacquired,
    }
    by_source = reported["by_source"]
    assert by_source["mocap"]["rejected"] == own.rejected  # the depth sensor is never gated here
    assert sum(c["accepted"] for c in by_source.values()) == own.accepted
    assert reported["delivered"]["mocap"] == sum(by_source["mocap"].values())
    assert reported["gate_probability"] == scenario.vehicle.navigation.filter.gate_probability  # type: ignore[union-attr]
    line = gate_rejections(metrics)
    assert line is not None
    assert f"gate rejected {own.rejected} of " in line and "accel_noise_m2_s3" in line
    assert line in format_summary(metrics, Path("out"))
    assert f"; navigation gate rejected {own.rejected} of " in format_trial(1, metrics)


def test_no_line_without_rejections_or_a_filter() -> None:
    counts = {"accepted": 5, "rejected": 0, "invalid": 0, "stale": 0, "rollbacks": 0}
    assert gate_rejections({"navigation": {"filter": {**counts, "reacquired": 0}}}) is None
    assert gate_rejections({"navigation": {"filter": None, "by_source": None}}) is None
    assert gate_rejections({}) is None


def test_rejections_by_chance_are_counted_without_advice() -> None:
    # a packaged trial: 1 of 6998 good 100-Hz fixes, as a 0.9999 gate rejects by chance
    def metrics(rejected: int) -> dict[str, object]:
        counts = {"accepted": 13997, "rejected": rejected, "invalid": 0, "stale": 0}
        return {
            "navigation": {
                "filter": {**counts, "rollbacks": 0, "reacquired": 0},
                "by_source": {"mocap": {"accepted": 6997, "rejected": rejected}},
                "gate_probability": 0.9999,
            }
        }

    line = gate_rejections(metrics(1))
    expected = "navigation filter's χ² gate rejected 1 of 13998 measurements (mocap 1/6998)"
    assert line == f"{expected}, re-acquired 0"
    assert "accel_noise_m2_s3" in (gate_rejections(metrics(15)) or "")


def test_a_dvl_that_never_delivers_is_named_with_what_it_lost() -> None:
    """A DVL fitted beside motion capture that lost every sample (dropouts certain; or the
    bottom out of its lock window) used to leave no trace: no ``dvl`` key at all, no line.
    At 5 Hz over 20 s it samples 100 times (closed form), all lost either way."""
    rate_hz, duration_s = 5.0, 20.0
    common = ["trials=1", f"duration_s={duration_s}"]
    for dvl, lost in (
        ("dropout_probability=1.0", {"unlocked": 0, "dropouts": 100}),
        ("bottom_depth_m=3.0, max_altitude_m=1.0", {"unlocked": 100, "dropouts": 0}),
    ):
        navigation = f"vehicle.navigation={{dvl={{rate_hz={rate_hz}, {dvl}}}, motion_capture={{}}}}"
        metrics = run_scenario(
            load_scenario("heavy-station-keeping-v1", [*common, navigation])
        ).metrics
        reported = metrics["navigation"]
        assert reported["delivered"]["dvl"] == 0 and reported["lost"] == {"dvl": lost}
        assert sum(lost.values()) == round(rate_hz * duration_s)
        line = (
            f"  warning: navigation source dvl delivered nothing: {lost['unlocked']} samples "
            f"without bottom lock, {lost['dropouts']} dropped\n"
        )
        assert line in format_summary(metrics, Path("out"))


def test_a_dvl_bottom_above_the_vehicles_start_is_refused() -> None:
    from testbed.config import ConfigError

    navigation = "vehicle.navigation={dvl={bottom_depth_m=0.5}, motion_capture={}}"
    with pytest.raises(ConfigError, match=r"dvl\.bottom_depth_m: the bottom \(0\.5 m\) must lie"):
        load_scenario("heavy-station-keeping-v1", [navigation])
