"""Global position targets through the sans-IO endpoint, pymavlink as the ground station, in
simulated time: SET_POSITION_TARGET_GLOBAL_INT (GUIDED's position, ALT_HOLD's depth) and
MAV_CMD_DO_REPOSITION (COMMAND_INT and COMMAND_LONG), with ArduSub's answers.

The ground station's side is independent of the endpoint: it takes the vehicle's position from
GLOBAL_POSITION_INT and puts the target a few metres north and east of it on the WGS-84 sphere
(flat earth at that latitude), as a map click would; the vehicle's physics truth must then move
by those metres (within the GUIDED loop's 5-cm arrival tolerance plus the 1e-7° quantisation)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.common.components import PositionSetpoint
from tests.mavlink.gcs import SimGcs

WGS84_M = 6378137.0
POSITION_ONLY = 0b1101_1111_1000  # x, y, z used; velocity, acceleration, yaw ignored
ACCELERATION = 0b1100_0011_1000  # x, y, z and the acceleration used
Z_IGNORE = 0b100
TOLERANCE_M = 0.05 + 0.02  # the GUIDED loop's arrival + 1e-7° of latitude (1.1 cm) twice
ACCEPTED, DENIED, FAILED = mav.MAV_RESULT_ACCEPTED, mav.MAV_RESULT_DENIED, mav.MAV_RESULT_FAILED


def offset_e7(gcs: SimGcs, north_m: float, east_m: float) -> tuple[int, int]:
    """(lat, lon) [1e-7 deg] ``north_m``, ``east_m`` from the reported GLOBAL_POSITION_INT."""
    where = gcs.last("GLOBAL_POSITION_INT")
    lat = where.lat * 1e-7
    lat_t = lat + math.degrees(north_m / WGS84_M)
    lon_t = where.lon * 1e-7 + math.degrees(east_m / (WGS84_M * math.cos(math.radians(lat))))
    return round(lat_t * 1e7), round(lon_t * 1e7)


def armed_in(gcs: SimGcs, mode: int) -> None:
    gcs.send(gcs.heartbeat(), gcs.arm(), gcs.set_mode(2))
    gcs.run(1.0, gcs.flying())
    gcs.send(gcs.set_mode(mode))
    gcs.run(1.01, gcs.flying())
    assert gcs.last("HEARTBEAT").custom_mode == mode


def target_position(gcs: SimGcs) -> tuple[float, float, float] | None:
    """Where GUIDED's position setpoint is (None: none)."""
    setpoint = gcs.vehicle.world.get(gcs.vehicle.operator_entity, PositionSetpoint)
    return None if setpoint is None else setpoint.position_ned_m


def global_target(
    gcs: SimGcs, frame: int, lat_e7: int, lon_e7: int, alt_m: float, mask: int = POSITION_ONLY
) -> Any:
    return gcs.mav.set_position_target_global_int_encode(
        0, 1, 1, frame, mask, lat_e7, lon_e7, alt_m, 0, 0, 0, 0, 0, 0, 0, 0
    )


def reposition_int(
    gcs: SimGcs, lat_e7: int, lon_e7: int, alt_m: float, flags: float = 0.0, frame: int = 6
) -> Any:
    """COMMAND_INT DO_REPOSITION (frame 6: MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, QGC's)."""
    return gcs.mav.command_int_encode(
        1,
        1,
        frame,
        mav.MAV_CMD_DO_REPOSITION,
        0,
        0,
        -1.0,
        flags,
        0,
        math.nan,
        lat_e7,
        lon_e7,
        alt_m,
    )


def reposition_acks(gcs: SimGcs) -> list[int]:
    return [m.result for m in gcs.of("COMMAND_ACK") if m.command == mav.MAV_CMD_DO_REPOSITION]


def fly_and_measure(gcs: SimGcs, seconds: float) -> tuple[float, float, float]:
    start = tuple(gcs.vehicle.truth.position_ned_m)
    gcs.run(seconds, gcs.flying())
    p = gcs.vehicle.truth.position_ned_m
    return p[0] - start[0], p[1] - start[1], p[2]


@pytest.mark.parametrize(
    "frame",
    [mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, mav.MAV_FRAME_GLOBAL_INT, mav.MAV_FRAME_GLOBAL],
)
def test_a_global_target_is_flown_to_in_guided(gcs: SimGcs, frame: int) -> None:
    armed_in(gcs, 4)
    lat, lon = offset_e7(gcs, 3.0, 2.0)
    heading = gcs.last("ATTITUDE").yaw
    gcs.send(global_target(gcs, frame, lat, lon, -1.5))  # 1.5 m below the surface home
    north, east, depth = fly_and_measure(gcs, 25.0)
    # the reported position was up to a frame old and 5 mm noisy: the truth moved the offset
    assert math.hypot(north - 3.0, east - 2.0) < TOLERANCE_M
    assert depth == pytest.approx(1.5, abs=0.05)
    assert abs(math.remainder(gcs.last("ATTITUDE").yaw - heading, math.tau)) < math.radians(3)
    assert gcs.endpoint.rejected.get("unsupported_frame", 0) == 0


def test_alt_hold_takes_only_the_depth_of_a_global_target(gcs: SimGcs) -> None:
    armed_in(gcs, 2)
    lat, lon = offset_e7(gcs, 3.0, 0.0)
    gcs.send(global_target(gcs, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, lat, lon, -2.0))
    north, east, depth = fly_and_measure(gcs, 12.0)
    assert depth == pytest.approx(2.0, abs=0.05)
    assert math.hypot(north, east) < 1.0  # not flown 3 m north: no position loop in ALT_HOLD
    assert gcs.vehicle.world.get(gcs.vehicle.operator_entity, PositionSetpoint) is None
    gcs.send(global_target(gcs, 6, lat, lon, -1.0, mask=POSITION_ONLY | Z_IGNORE))
    gcs.run(0.1, gcs.flying())  # z ignored: nothing for ALT_HOLD, counted
    assert gcs.endpoint.rejected["not_guided"] == 1


def test_global_targets_ardusub_ignores_are_counted_not_flown(gcs: SimGcs) -> None:
    gcs.send(gcs.heartbeat(), gcs.arm())
    gcs.run(0.5, gcs.flying())
    lat, lon = offset_e7(gcs, 3.0, 0.0)
    gcs.send(global_target(gcs, 6, lat, lon, -1.0))  # MANUAL: ignored
    gcs.run(0.05, gcs.flying())
    armed_in(gcs, 4)
    entered = target_position(gcs)  # GUIDED's entry holds where the vehicle was
    assert entered is not None
    gcs.send(
        global_target(gcs, mav.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT, lat, lon, 1.0),  # no terrain
        global_target(gcs, mav.MAV_FRAME_LOCAL_NED, lat, lon, -1.0),  # not global
        global_target(gcs, 6, lat, lon, -1.0, mask=ACCELERATION),  # no acceleration control
        global_target(gcs, 6, lat, lon, math.nan),
        global_target(gcs, 6, 910_000_000, lon, -1.0),  # 91°N
        global_target(gcs, 6, lat, -1_800_000_001, -1.0),
        global_target(gcs, 6, 800_000_000, lon, -1.0),  # a real place, 4000 km away
    )
    gcs.run(0.1, gcs.flying())
    rejected = gcs.endpoint.rejected
    counts = [rejected[k] for k in ("not_guided", "unsupported_frame", "unsupported_target")]
    assert counts == [1, 2, 1]
    assert rejected["bad_field"] == 4
    assert target_position(gcs) == entered


def test_a_global_position_target_is_any_velocity_bit_and_any_acceleration_bit(
    gcs: SimGcs,
) -> None:
    """ArduSub's position-only test, as SET_POSITION_TARGET_LOCAL_NED's: any velocity bit and
    any acceleration bit set, no position bit (no acceleration bit: nothing ArduSub flies)."""
    armed_in(gcs, 4)
    lat, lon = offset_e7(gcs, 2.0, 0.0)
    gcs.send(global_target(gcs, 6, lat, lon, -1.0, mask=0b1100_0011_0000))  # VZ, no AX..AZ
    gcs.run(0.1, gcs.flying())
    assert gcs.endpoint.rejected["unsupported_target"] == 1
    gcs.send(global_target(gcs, 6, lat, lon, -1.0, mask=0b100_1000))  # VX, AX only
    north, east, depth = fly_and_measure(gcs, 15.0)
    assert math.hypot(north - 2.0, east) < TOLERANCE_M
    assert depth == pytest.approx(1.0, abs=0.05)
    assert gcs.endpoint.rejected["unsupported_target"] == 1


def test_do_reposition_in_guided_is_accepted_and_flown(gcs: SimGcs) -> None:
    armed_in(gcs, 4)
    lat, lon = offset_e7(gcs, -2.0, 1.0)
    gcs.send(reposition_int(gcs, lat, lon, -1.2))
    north, east, depth = fly_and_measure(gcs, 20.0)
    assert reposition_acks(gcs) == [ACCEPTED]
    assert math.hypot(north + 2.0, east - 1.0) < TOLERANCE_M
    assert depth == pytest.approx(1.2, abs=0.05)


def test_do_reposition_changes_to_guided_only_when_asked(gcs: SimGcs) -> None:
    armed_in(gcs, 2)
    lat, lon = offset_e7(gcs, 2.0, 0.0)
    gcs.send(reposition_int(gcs, lat, lon, -1.0))  # ALT_HOLD, no CHANGE_MODE flag
    gcs.run(0.1, gcs.flying())
    assert reposition_acks(gcs) == [DENIED]
    gcs.send(reposition_int(gcs, lat, lon, -1.0, flags=mav.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE))
    north, _, _ = fly_and_measure(gcs, 15.0)
    assert reposition_acks(gcs) == [DENIED, ACCEPTED]
    assert gcs.last("HEARTBEAT").custom_mode == 4
    assert north == pytest.approx(2.0, abs=TOLERANCE_M)


def test_do_reposition_as_command_long_is_in_degrees_above_mean_sea_level(gcs: SimGcs) -> None:
    """ArduPilot takes a COMMAND_LONG's location as MAV_FRAME_GLOBAL, params 5 and 6 in degrees:
    float32, so at 40° N the latitude lands on a 3.8e-6° (0.42 m) grid (why ArduPilot wants
    COMMAND_INT for locations); the vehicle flies to the rounded point."""
    armed_in(gcs, 4)
    lat, lon = offset_e7(gcs, 1.5, -1.5)
    where = gcs.last("GLOBAL_POSITION_INT")
    sent_lat, sent_lon = float(np.float32(lat * 1e-7)), float(np.float32(lon * 1e-7))
    rounding_north = math.radians(sent_lat - lat * 1e-7) * WGS84_M
    cos_lat = math.cos(math.radians(where.lat * 1e-7))
    rounding_east = math.radians(sent_lon - lon * 1e-7) * WGS84_M * cos_lat
    assert abs(rounding_north) < 0.21  # half the grid
    gcs.send(gcs.command(mav.MAV_CMD_DO_REPOSITION, -1, 0, 0, math.nan, sent_lat, sent_lon, -1.3))
    north, east, depth = fly_and_measure(gcs, 15.0)
    assert reposition_acks(gcs) == [ACCEPTED]
    error = math.hypot(north - 1.5 - rounding_north, east + 1.5 - rounding_east)
    assert error < TOLERANCE_M
    assert depth == pytest.approx(1.3, abs=0.05)


def test_do_reposition_answers_as_ardusub(gcs: SimGcs) -> None:
    armed_in(gcs, 4)
    entered = target_position(gcs)
    lat, lon = offset_e7(gcs, 2.0, 0.0)
    gcs.send(
        reposition_int(gcs, lat, lon, -1.0, frame=mav.MAV_FRAME_LOCAL_NED),  # not global
        reposition_int(gcs, 0, 0, -1.0),  # 0, 0: "current position" to Location::sanitize
        reposition_int(gcs, lat, lon, 0.0),  # relative altitude 0: sanitize again
        reposition_int(gcs, 910_000_000, lon, -1.0),  # out of range
        reposition_int(gcs, lat, lon, math.nan),
        reposition_int(
            gcs, lat, lon, 1.0, frame=mav.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT
        ),  # no terrain
    )
    gcs.run(0.1, gcs.flying())
    assert reposition_acks(gcs) == [DENIED, DENIED, DENIED, DENIED, DENIED, FAILED]
    assert target_position(gcs) == entered
    rejected = gcs.endpoint.rejected
    assert (rejected["unsupported_frame"], rejected["bad_field"]) == (2, 4)
    gcs.send(reposition_int(gcs, lat, lon, 0.0, frame=mav.MAV_FRAME_GLOBAL_INT))  # AMSL 0: fine
    gcs.run(0.1, gcs.flying())
    assert reposition_acks(gcs)[-1] == ACCEPTED


def test_do_reposition_refuses_a_relative_altitude_under_a_centimetre(gcs: SimGcs) -> None:
    """ArduPilot's location_from_command_t stores the altitude as int32_t(z * 100) in float32,
    truncated toward zero: under 1 cm either way it is 0 cm, which Location::sanitize takes
    as "the current altitude", so the command is DENIED."""
    armed_in(gcs, 4)
    entered = target_position(gcs)
    lat, lon = offset_e7(gcs, 1.0, 0.0)
    gcs.send(
        reposition_int(gcs, lat, lon, 0.004),
        reposition_int(gcs, lat, lon, -0.009),
        reposition_int(gcs, lat, lon, 0.0099),
    )
    gcs.run(0.1, gcs.flying())
    assert reposition_acks(gcs) == [DENIED, DENIED, DENIED]
    assert target_position(gcs) == entered
    gcs.send(reposition_int(gcs, lat, lon, -0.01))  # 1 cm below home
    gcs.run(0.1, gcs.flying())
    assert reposition_acks(gcs)[-1] == ACCEPTED


def test_do_reposition_is_counted_accepted_only_when_accepted() -> None:
    """The counters say what happened: a refused DO_REPOSITION is counted under its reason,
    not ``accepted`` (as an unsupported command is)."""
    gcs = SimGcs(position_fix=False)
    try:
        armed_in(gcs, 2)
        lat, lon = 399_945_200, -686_000
        counted = [gcs.endpoint.accepted]
        for message in (
            reposition_int(gcs, lat, lon, -1.0),  # ALT_HOLD, no CHANGE_MODE: DENIED
            reposition_int(gcs, lat, lon, -1.0, flags=1),  # no fix for GUIDED: FAILED
            reposition_int(gcs, lat, lon, 0.0, flags=1),  # 0 cm relative: DENIED
        ):
            gcs.send(message)
            gcs.step()  # no sticks: only the command is counted
            counted.append(gcs.endpoint.accepted)
        assert reposition_acks(gcs) == [DENIED, FAILED, DENIED]
        assert counted[1:] == [counted[0]] * 3
        rejected = gcs.endpoint.rejected
        assert (rejected["not_guided"], rejected["mode_refused"], rejected["bad_field"]) == (
            1,
            1,
            1,
        )
    finally:
        gcs.close()
    gcs = SimGcs()
    try:
        armed_in(gcs, 4)
        before = gcs.endpoint.accepted
        gcs.send(reposition_int(gcs, *offset_e7(gcs, 1.0, 0.0), -1.0))
        gcs.step()
        assert reposition_acks(gcs) == [ACCEPTED]
        assert gcs.endpoint.accepted == before + 1
    finally:
        gcs.close()


def test_do_reposition_without_a_position_fix_fails_the_mode_change() -> None:
    gcs = SimGcs(position_fix=False)
    try:
        armed_in(gcs, 2)
        gcs.send(reposition_int(gcs, 399_945_200, -686_000, -1.0, flags=1))
        gcs.run(0.1, gcs.flying())
        assert reposition_acks(gcs) == [FAILED]
        assert any(m.text == "Flight mode change failed" for m in gcs.of("STATUSTEXT"))
    finally:
        gcs.close()


def test_the_capability_is_advertised(gcs: SimGcs) -> None:
    gcs.send(gcs.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION))
    gcs.step()
    capabilities = gcs.last("AUTOPILOT_VERSION").capabilities
    assert capabilities & mav.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
