"""SET_ATTITUDE_TARGET through the sans-IO endpoint, pymavlink as the ground station, in simulated
time, judged by the physics truth: GUIDED flies the attitude and the thrust's climb rate
(ArduSub's ``guided_set_angle``: (thrust − 0.5) × 2 × WPNAV_SPEED_UP/DN, integrated into the
depth target, level and no climb 1 s after the last message, roll and pitch within ANGLE_MAX);
ALT_HOLD flies a throttle-ignored target (ArduSub's ``set_attitude_target_no_gps``, stored in
any mode, whatever the attitude-ignore bit) for 5 s, then its old heading; other modes and masks
ignore it, malformed values are counted, never raised."""

from __future__ import annotations

import math
import time
from typing import Any

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.common.components import AttitudeSetpoint, ControlTargets, PositionSetpoint
from testbed.common.geometry import euler_from_quat, quat_from_euler
from testbed.run.mavlink_gateway import run_gateway
from testbed.run.scenario import load_scenario
from tests.mavlink.gcs import SimGateway, SimGcs
from tests.mavlink.rt_session import GatewaySession

THROTTLE_IGNORE = 64
ATTITUDE_IGNORE = 128
RATES_IGNORED = 7  # body roll, pitch, yaw rates ignored (ArduSub never reads them)
WPNAV_SPEED_DN_M_S = 1.5  # the table's WPNAV_SPEED_DN 150 cm/s (ArduSub's default)
WPNAV_SPEED_UP_M_S = 2.5  # WPNAV_SPEED_UP 250 cm/s


def attitude(
    gcs: SimGcs,
    roll_deg: float = 0.0,
    pitch_deg: float = 0.0,
    yaw_deg: float = 0.0,
    thrust: float = 0.5,
    mask: int = RATES_IGNORED,
    q: tuple[float, ...] | None = None,
) -> Any:
    if q is None:
        q = quat_from_euler(*(math.radians(a) for a in (roll_deg, pitch_deg, yaw_deg)))
    return gcs.mav.set_attitude_target_encode(0, 1, 1, mask, list(q), 0, 0, 0, thrust)


def truth_euler_deg(gcs: SimGcs) -> tuple[float, float, float]:
    roll, pitch, yaw = euler_from_quat(gcs.vehicle.truth.quaternion_wxyz)
    return math.degrees(roll), math.degrees(pitch), math.degrees(yaw)


def stream(gcs: SimGcs, seconds: float, message: Any) -> None:
    """``message`` at 4 Hz for ``seconds`` (with the sticks at 25 Hz)."""
    sticks = gcs.flying()

    def each(k: int) -> list[Any]:
        return [*sticks(k), *([message] if k % 25 == 0 else [])]

    gcs.run(seconds, each)


def test_guided_drops_its_position_target_and_turns_to_the_heading(gcs: SimGcs) -> None:
    gcs.enter_guided()
    ahead = gcs.mav.set_position_target_local_ned_encode(
        0, 1, 1, mav.MAV_FRAME_BODY_OFFSET_NED, 0b1101_1111_1000, 4, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0
    )
    start = tuple(gcs.vehicle.truth.position_ned_m)
    gcs.send(ahead)
    gcs.run(0.5, gcs.flying())
    intents = gcs.vehicle.operator_entity
    assert gcs.vehicle.world.get(intents, PositionSetpoint) is not None
    heading = truth_euler_deg(gcs)[2]
    stream(gcs, 10.0, attitude(gcs, yaw_deg=heading + 60.0))
    assert gcs.vehicle.world.get(intents, PositionSetpoint) is None  # angle control instead
    truth = gcs.vehicle.truth
    p, v = truth.position_ned_m, truth.velocity_m_s
    # it coasts from the half second toward the target (≤ 0.5 m/s) and stops, 4 m short
    assert math.hypot(p[0] - start[0], p[1] - start[1]) < 1.0
    assert math.hypot(v[0], v[1]) < 0.05
    assert abs(p[2] - start[2]) < 0.05  # thrust 0.5: the depth held
    turned = math.remainder(math.radians(truth_euler_deg(gcs)[2] - heading - 60.0), math.tau)
    assert abs(math.degrees(turned)) < 3.0
    assert gcs.endpoint.rejected.get("bad_field", 0) == 0


def test_guided_thrust_is_a_climb_rate_until_a_second_after_the_last_message(
    gcs: SimGcs,
) -> None:
    gcs.enter_guided()
    depth0 = gcs.endpoint.snapshot_now().depth_m  # the depth the target integrates from
    # thrust 0.3: (0.3 − 0.5) × 2 × 1.5 m/s = 0.6 m/s down, from the first message to 1 s after
    # the last (4 Hz for 2 s: the last at 1.75 s)
    stream(gcs, 2.0, attitude(gcs, yaw_deg=truth_euler_deg(gcs)[2], thrust=0.3))
    gcs.run(10.0, gcs.flying())
    descent = 0.4 * WPNAV_SPEED_DN_M_S * (1.75 + 1.0)
    targets = gcs.vehicle.world.get(gcs.vehicle.entity, ControlTargets)
    assert targets is not None
    assert targets.depth_m == pytest.approx(depth0 + descent, abs=0.011)  # one 10-ms frame
    assert gcs.truth_depth_m() == pytest.approx(depth0 + descent, abs=0.05)
    # and up: 0.6 → 0.2 × 2.5 m/s = 0.5 m/s for 1 s + 1 s
    depth1 = targets.depth_m
    stream(gcs, 1.0, attitude(gcs, yaw_deg=truth_euler_deg(gcs)[2], thrust=0.6))
    gcs.run(8.0, gcs.flying())
    rise = 0.1 * 2 * WPNAV_SPEED_UP_M_S * (0.75 + 1.0)
    assert gcs.truth_depth_m() == pytest.approx(depth1 - rise, abs=0.05)


def test_guided_roll_is_limited_to_angle_max_and_levels_after_the_timeout(gcs: SimGcs) -> None:
    gcs.send(gcs.param_set("ANGLE_MAX", 1000))  # 10°
    gcs.enter_guided()
    yaw = truth_euler_deg(gcs)[2]
    stream(gcs, 6.0, attitude(gcs, roll_deg=30.0, yaw_deg=yaw))
    setpoint = gcs.vehicle.world.get(gcs.vehicle.operator_entity, AttitudeSetpoint)
    assert setpoint is not None
    assert math.degrees(euler_from_quat(setpoint.quaternion_wxyz)[0]) == pytest.approx(10.0)
    assert truth_euler_deg(gcs)[0] == pytest.approx(10.0, abs=2.0)
    gcs.run(6.0, gcs.flying())  # no message for > 1 s: level, the heading kept
    roll, _, heading = truth_euler_deg(gcs)
    assert abs(roll) < 2.0
    assert abs(math.remainder(math.radians(heading - yaw), math.tau)) < math.radians(3.0)


def test_alt_hold_flies_a_throttle_ignored_target_for_five_seconds(gcs: SimGcs) -> None:
    gcs.send(gcs.heartbeat(), gcs.arm(), gcs.set_mode(2))
    gcs.run(1.0, gcs.flying())
    depth = gcs.truth_depth_m()
    heading = truth_euler_deg(gcs)[2]
    # the thrust is ignored (bit 64): ALT_HOLD keeps its depth
    stream(gcs, 8.0, attitude(gcs, yaw_deg=heading + 90.0, thrust=1.0, mask=THROTTLE_IGNORE))
    turned = truth_euler_deg(gcs)[2] - heading - 90.0
    assert abs(math.degrees(math.remainder(math.radians(turned), math.tau))) < 3.0
    assert abs(gcs.truth_depth_m() - depth) < 0.05
    gcs.run(4.0, gcs.flying())  # under 5 s since the last: still held
    turned = truth_euler_deg(gcs)[2] - heading - 90.0
    assert abs(math.degrees(math.remainder(math.radians(turned), math.tau))) < 3.0
    gcs.run(8.0, gcs.flying())  # then the heading held before comes back
    back = math.remainder(math.radians(truth_euler_deg(gcs)[2] - heading), math.tau)
    assert abs(math.degrees(back)) < 3.0


def test_a_target_stored_in_manual_is_flown_when_alt_hold_comes_within_five_seconds(
    gcs: SimGcs,
) -> None:
    """ArduSub stores a throttle-ignored target in any mode; ALT_HOLD, entered while the last is
    under 5 s old, flies it, and when it ages out holds the heading it was entered at."""
    gcs.send(gcs.heartbeat(), gcs.arm())
    gcs.run(1.0, gcs.flying())
    world, intents = gcs.vehicle.world, gcs.vehicle.operator_entity
    heading = truth_euler_deg(gcs)[2]
    target = attitude(gcs, yaw_deg=heading + 90.0, mask=THROTTLE_IGNORE)
    stream(gcs, 2.0, target)  # MANUAL holds no attitude: stored, not flown
    assert world.get(intents, AttitudeSetpoint) is None
    assert gcs.endpoint.rejected.get("not_guided", 0) == 0
    entry_heading = truth_euler_deg(gcs)[2]
    gcs.send(gcs.set_mode(2))  # 0.25 s after the last message
    gcs.run(4.5, gcs.flying())  # flown until 5 s after it
    turned = truth_euler_deg(gcs)[2] - entry_heading
    assert math.degrees(math.remainder(math.radians(turned), math.tau)) > 45.0
    gcs.run(10.0, gcs.flying())  # aged out: the heading ALT_HOLD was entered at
    back = math.remainder(math.radians(truth_euler_deg(gcs)[2] - entry_heading), math.tau)
    assert abs(math.degrees(back)) < 3.0


def test_a_stored_target_older_than_five_seconds_is_not_flown(gcs: SimGcs) -> None:
    gcs.send(gcs.heartbeat(), gcs.arm())
    gcs.run(1.0, gcs.flying())
    gcs.send(attitude(gcs, yaw_deg=truth_euler_deg(gcs)[2] + 90.0, mask=THROTTLE_IGNORE))
    gcs.run(5.1, gcs.flying())
    gcs.send(gcs.set_mode(2))
    gcs.run(1.0, gcs.flying())
    assert gcs.vehicle.world.get(gcs.vehicle.operator_entity, AttitudeSetpoint) is None


def test_alt_hold_flies_a_target_with_attitude_ignored_when_throttle_is_ignored_too(
    gcs: SimGcs,
) -> None:
    """ArduSub stores the message on bit 64 before it looks at bit 128: ALT_HOLD flies its
    quaternion; bit 128 alone is ignored."""
    gcs.send(gcs.heartbeat(), gcs.arm(), gcs.set_mode(2))
    gcs.run(1.0, gcs.flying())
    heading = truth_euler_deg(gcs)[2]
    ignored = attitude(gcs, yaw_deg=heading - 90.0, mask=ATTITUDE_IGNORE)
    stream(gcs, 2.0, ignored)
    assert gcs.vehicle.world.get(gcs.vehicle.operator_entity, AttitudeSetpoint) is None
    assert gcs.endpoint.rejected["unsupported_target"] == 8
    both = attitude(gcs, yaw_deg=heading + 60.0, mask=THROTTLE_IGNORE | ATTITUDE_IGNORE)
    stream(gcs, 8.0, both)
    turned = truth_euler_deg(gcs)[2] - heading - 60.0
    assert abs(math.degrees(math.remainder(math.radians(turned), math.tau))) < 3.0


def test_other_modes_masks_and_malformed_values_are_counted_not_acted_on(gcs: SimGcs) -> None:
    gcs.send(gcs.heartbeat(), gcs.arm())
    gcs.run(0.5, gcs.flying())
    world, intents = gcs.vehicle.world, gcs.vehicle.operator_entity
    gcs.send(attitude(gcs, yaw_deg=90.0))  # MANUAL: no mode flies it
    gcs.run(0.1, gcs.flying())
    assert gcs.endpoint.rejected["not_guided"] == 1
    gcs.enter_guided()
    gcs.send(
        attitude(gcs, yaw_deg=90.0, mask=THROTTLE_IGNORE),  # stored for ALT_HOLD, not flown
        attitude(gcs, yaw_deg=90.0, mask=ATTITUDE_IGNORE),
        attitude(gcs, q=(math.nan, 0.0, 0.0, 0.0)),
        attitude(gcs, q=(0.0, 0.0, 0.0, 0.0)),
        attitude(gcs, q=(math.inf, 1.0, 0.0, 0.0)),
        attitude(gcs, thrust=math.nan),
    )
    gcs.run(0.1, gcs.flying())
    rejected = gcs.endpoint.rejected
    assert (rejected["not_guided"], rejected["unsupported_target"], rejected["bad_field"]) == (
        1,
        1,
        4,
    )
    assert world.get(intents, AttitudeSetpoint) is None  # GUIDED does not fly a stored one
    assert gcs.endpoint.attitude_target is None
    assert gcs.endpoint.stored_attitude is not None
    # an unnormalised quaternion is normalised, as the vehicle's attitude hold takes it
    gcs.send(attitude(gcs, q=tuple(2.0 * c for c in quat_from_euler(0.0, 0.0, 1.0))))
    gcs.run(0.1, gcs.flying())
    setpoint = world.get(intents, AttitudeSetpoint)
    assert setpoint is not None
    assert euler_from_quat(setpoint.quaternion_wxyz)[2] == pytest.approx(1.0)
    assert sum(c * c for c in setpoint.quaternion_wxyz) == pytest.approx(1.0)


def test_the_capability_is_advertised(gcs: SimGcs) -> None:
    gcs.send(gcs.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION))
    gcs.step()
    version = gcs.last("AUTOPILOT_VERSION")
    assert version.capabilities & mav.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET


def test_through_the_teleop_gateway_the_heading_crosses_and_the_thrust_is_said_not_to() -> None:
    """s100's teleop codec: the heading travels (a ``KeepHeading``, whole degrees), the
    thrust's depth target and a roll cannot (no such order in the paper's layouts): the vehicle
    turns, keeps its depth and attitude level, and the shore says so once each instead of
    dropping them silently (they used to be)."""
    gateway = SimGateway()
    try:
        gateway.send(gateway.mav.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0))
        gateway.send(gateway.mav.set_mode_encode(1, 1, 2))
        gateway.run(3.0)
        gateway.send(gateway.mav.set_mode_encode(1, 1, 4))
        gateway.run(3.0)
        truth = gateway.vehicle.truth
        depth = float(truth.position_ned_m[2])
        heading = math.degrees(euler_from_quat(truth.quaternion_wxyz)[2])
        q = quat_from_euler(math.radians(10.0), 0.0, math.radians(heading + 60.0))
        for _ in range(8):  # 4 Hz for 2 s, thrust 0.3: 0.6 m/s down, 1.65 m on the shore
            gateway.send(gateway.mav.set_attitude_target_encode(0, 1, 1, 7, list(q), 0, 0, 0, 0.3))
            gateway.run(0.25)
        gateway.run(10.0)
        turned = math.degrees(euler_from_quat(truth.quaternion_wxyz)[2]) - heading - 60.0
        assert abs((turned + 180.0) % 360.0 - 180.0) < 3.0  # KeepHeading: whole degrees
        assert abs(float(truth.position_ned_m[2]) - depth) < 0.05
        assert abs(math.degrees(euler_from_quat(truth.quaternion_wxyz)[0])) < 2.0
        texts = [m.text for m in gateway.messages if m.get_type() == "STATUSTEXT"]
        assert texts.count("Depth targets do not cross the link") == 1
        assert texts.count("Roll, pitch targets do not cross the link") == 1
        assert gateway.endpoint.counters()["setpoints_not_sent"] == ["depth", "roll_pitch"]
    finally:
        gateway.vehicle.close()


def test_through_the_change_set_gateway_the_thrust_crosses() -> None:
    """≈ 8 s real time: ``tether-teleop-v1 --link tether``'s change-set codec replicates the
    shore's depth target, so GUIDED's thrust 0.3 (0.6 m/s down, ArduSub's climb rate) streamed
    for 2 s takes the vehicle down by 0.6 m/s × (the messages' span + the 1-s timeout)."""
    scenario = load_scenario("tether-teleop-v1", ["metrics.settle_s=1"])
    session = GatewaySession(
        lambda links, stop: run_gateway(scenario, links, duration_s=60.0, stop=stop)
    )
    try:
        gcs = session.gcs
        assert gcs.wait_heartbeat(timeout=session.wait_s) is not None
        gcs.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
        session.heartbeat(lambda hb: hb.base_mode & 128)
        gcs.mav.set_mode_send(1, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 2)
        session.heartbeat(lambda hb: hb.custom_mode == 2)
        gcs.mav.set_mode_send(1, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4)
        session.heartbeat(lambda hb: hb.custom_mode == 4)
        session.pump(1.0)
        q = quat_from_euler(0.0, 0.0, session.latest["ATTITUDE"].yaw)
        sent: list[float] = []
        while not sent or sent[-1] - sent[0] < 2.0:
            gcs.mav.set_attitude_target_send(0, 1, 1, RATES_IGNORED, list(q), 0, 0, 0, 0.3)
            sent.append(time.monotonic())
            session.pump(0.25)
        session.pump(6.0)
        result = session.finish()
    finally:
        session.close()
    section = result.metrics["mavlink"]
    assert section["setpoints_not_sent"] == [] and section["link"]["carries_setpoints"]
    series = result.recorder.series()
    guided = series["mode"] == 4.0
    start, end = series["down_m"][guided][0], series["down_m"][-1]
    late_s = section["scheduler_lateness_ms"]["max"] / 1000.0
    descent = 0.4 * WPNAV_SPEED_DN_M_S * (sent[-1] - sent[0] + 1.0)
    # the depth hold's 5 cm, and each end of the span read a gateway period (and late) off
    assert end - start == pytest.approx(descent, abs=0.05 + 0.6 * 2 * (0.01 + late_s))
