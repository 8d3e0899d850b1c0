"""HIGH_LATENCY2 and MAV_CMD_CONTROL_HIGH_LATENCY as ArduSub 4.5 runs them, pymavlink on both
links (a normal one and a high-latency one), in simulated time.

Independent truth: ArduPilot 4.5's rules restated here from its source (``GCS_Common.cpp``:
``send_high_latency2``, ``handle_control_high_latency``, HIGH_LATENCY2 at 5000 ms on a
high-latency link instead of the heartbeat; ``GCS_MAVLink.cpp`` ``comm_send_buffer``: nothing
leaves a disabled high-latency link; ArduSub's ``high_latency_*`` overrides and
``send_heartbeat``'s base_mode), and the vehicle's physics truth: each decoded HIGH_LATENCY2
must describe the vehicle at its ``timestamp`` within the field's quantisation (below) plus the
sensors' error (position fix 5 mm 1σ at 20 Hz, depth sensor, IMU).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.common.geometry import euler_from_quat
from testbed.vehicle.guidance import PositionGains
from tests.mavlink.gcs import SimGateway, SimGcs

HL2_INTERVAL_S = 5.0  # ArduPilot: set_mavlink_message_id_interval(HIGH_LATENCY2, 5000)
CONTROL = mav.MAV_CMD_CONTROL_HIGH_LATENCY
ACCEPTED, FAILED = mav.MAV_RESULT_ACCEPTED, mav.MAV_RESULT_FAILED
HOME_DEG = (39.9945, -0.0686)  # HOME_POSITION's, read over the link below
EARTH_RADIUS_M = 6378137.0
# ArduPilot's send_high_latency2 status_map: SYS_STATUS health bit → HL_FAILURE_FLAG
STATUS_MAP = [
    (1 << 5, 1),  # GPS → GPS
    (1 << 4, 2),  # DIFFERENTIAL_PRESSURE
    (1 << 3, 4),  # ABSOLUTE_PRESSURE
    (1 << 1, 8),  # 3D_ACCEL
    (1 << 0, 16),  # 3D_GYRO
    (1 << 2, 32),  # 3D_MAG
    (1 << 22, 64),  # TERRAIN
    (1 << 25, 128),  # BATTERY
    (1 << 16, 256),  # RC_RECEIVER
    (1 << 20, 2048),  # GEOFENCE
    (1 << 21, 4096),  # AHRS → ESTIMATOR
]
# ArduSub's heartbeat base_mode: CUSTOM_MODE 1 | STABILIZE 16 | MANUAL_INPUT 64, GUIDED 8, ARMED 128
BASE_GUIDED_ARMED = 1 | 16 | 64 | 8 | 128


class TwoLinks(SimGcs):
    """:class:`SimGcs` (its link a normal one) with a second, high-latency link: packets for
    it go in before the frame, its replies are decoded after it into ``hl_messages``."""

    def __init__(self) -> None:
        super().__init__()
        self.hl = self.endpoint.open_channel("hl", high_latency=True)
        self.hl_opened_s = self.now_s
        self._hl_decoder = mav.MAVLink(None)
        self._hl_decoder.robust_parsing = True
        self._hl_pending = bytearray()
        self.hl_messages: list[Any] = []
        self.hl_times: list[float] = []  # the time each of hl_messages was decoded at

    def send_hl(self, *messages: Any) -> None:
        for message in messages:
            self._hl_pending += message.pack(self.mav)

    def step(self) -> None:
        data, self._hl_pending = bytes(self._hl_pending), bytearray()
        if data:
            self.endpoint.receive(self.hl, data, self.now_s)
        super().step()
        for packet in self.hl.take():
            for m in self._hl_decoder.parse_buffer(packet) or []:
                if m.get_type() != "BAD_DATA":
                    self.hl_messages.append(m)
                    self.hl_times.append(self.now_s)

    def hl_of(self, kind: str) -> list[Any]:
        return [m for m in self.hl_messages if m.get_type() == kind]


@pytest.fixture
def links() -> Iterator[TwoLinks]:
    station = TwoLinks()
    yield station
    station.close()


def acks(messages: list[Any], command: int = CONTROL) -> list[int]:
    return [m.result for m in messages if m.get_type() == "COMMAND_ACK" and m.command == command]


def texts(messages: list[Any]) -> list[str]:
    return [m.text for m in messages if m.get_type() == "STATUSTEXT"]


def test_silent_until_enabled_then_high_latency2_alone_and_silent_again_once_disabled(
    links: TwoLinks,
) -> None:
    """Disabled at boot, the high-latency link sends nothing (not even the replies to what
    arrives on it, which is acted on); MAV_CMD_CONTROL_HIGH_LATENCY 1 on it is ACKed there
    and then only HIGH_LATENCY2 (every 5 s), replies and STATUSTEXT go out, never a
    HEARTBEAT or a stream; the normal link keeps its 1-Hz heartbeat and gets no
    HIGH_LATENCY2. Disabled again from the normal link, the high-latency link goes silent at
    once; its own disable's ACK is dropped (the link was off before the ACK was written)."""
    read = links.mav.param_request_read_encode(1, 1, b"FS_GCS_ENABLE", -1)
    links.send_hl(links.set_mode(2), read)
    links.run(6.0, links.flying())
    assert links.hl_messages == [] and links.hl.held > 0  # a HIGH_LATENCY2 due at 5 s held too
    assert links.last("HEARTBEAT").custom_mode == 2  # the SET_MODE that came on it acted
    links.send_hl(links.command(CONTROL, 1))
    links.run(11.0, links.flying())
    assert acks(links.hl_messages) == [ACCEPTED]
    assert "High Latency enabled" in texts(links.hl_messages)
    assert "High Latency enabled" in texts(links.messages)  # to every link
    kinds = {m.get_type() for m in links.hl_messages}
    assert kinds == {"COMMAND_ACK", "STATUSTEXT", "HIGH_LATENCY2"}
    assert len(links.hl_of("HIGH_LATENCY2")) == 2  # at 10 s and 15 s (due every 5 s from boot)
    assert not links.of("HIGH_LATENCY2")
    heartbeats = links.of("HEARTBEAT")  # 1 Hz, untouched: every one sent went to this link
    assert len(heartbeats) == links.endpoint.sent["HEARTBEAT"] == pytest.approx(17, abs=1)
    before = len(links.hl_messages)
    links.send(links.command(CONTROL, 0))  # from the normal link: every HL link off
    links.run(11.0, links.flying())
    assert acks(links.messages) == [ACCEPTED]
    assert "High Latency disabled" in texts(links.messages)
    assert len(links.hl_messages) == before  # not even the text
    links.send_hl(links.command(CONTROL, 1))
    links.step()
    links.send_hl(links.command(CONTROL, 0))  # on the link itself: its ACK dropped
    links.run(6.0, links.flying())
    assert acks(links.hl_messages) == [ACCEPTED, ACCEPTED]  # the first enable's, then this one's
    assert links.endpoint.high_latency_enabled is False
    assert links.endpoint.counters()["high_latency"] == {
        "enabled": False,
        "links": 1,
        "held": links.hl.held,
    }


def test_the_text_follows_the_ack_as_ardupilots_queued_statustext(links: TwoLinks) -> None:
    """ArduPilot's ``GCS_MAVLINK::handle_command_int``/``_long`` writes the COMMAND_ACK as
    ``handle_control_high_latency`` returns, while the "High Latency enabled" / "disabled" its
    ``GCS::enable_high_latency_connections`` says is only queued (``GCS::send_textv``) and sent
    by ``GCS::update_send``'s ``service_statustext`` after the links' messages: on each link
    the ACK comes first (it used to follow the text). Enabled from the high-latency link, both
    go out there in that order; disabled from the normal link, only there."""
    links.send_hl(links.command(CONTROL, 1))
    links.step()
    enabled = ("STATUSTEXT", "High Latency enabled")
    assert _kinds(links.hl_messages) == [("COMMAND_ACK", ACCEPTED), enabled]
    assert enabled in _kinds(links.messages)
    links.clear()
    links.send(links.command(CONTROL, 0))
    links.step()
    kinds = _kinds(links.messages)
    assert kinds.index(("COMMAND_ACK", ACCEPTED)) < kinds.index(
        ("STATUSTEXT", "High Latency disabled")
    )
    links.clear()
    links.send(links.command(CONTROL, 1))
    links.step()
    kinds = _kinds(links.messages)
    assert kinds.index(("COMMAND_ACK", ACCEPTED)) < kinds.index(enabled)


def _kinds(messages: list[Any]) -> list[tuple[str, object]]:
    """Each message's type with its ACK result or its text."""
    return [
        (m.get_type(), m.result if m.get_type() == "COMMAND_ACK" else getattr(m, "text", None))
        for m in messages
    ]


@pytest.mark.parametrize(
    ("param1", "result", "enabled"),
    [
        (1.0, ACCEPTED, True),
        (1.0 + 1e-8, ACCEPTED, True),  # is_equal: within a float's epsilon
        (0.0, ACCEPTED, False),
        (1e-8, ACCEPTED, False),
        (0.5, FAILED, None),
        (2.0, FAILED, None),
        (-1.0, FAILED, None),
        (math.nan, FAILED, None),
    ],
)
def test_the_command_is_acked_as_ardupilots(
    links: TwoLinks, param1: float, result: int, enabled: bool | None
) -> None:
    """param1 1 enables, 0 disables (ACCEPTED, whether or not a high-latency link exists: here
    sent on the normal link), anything else is FAILED and changes nothing; COMMAND_INT alike."""
    links.endpoint.high_latency_enabled = not enabled if enabled is not None else True
    before = links.endpoint.high_latency_enabled
    links.send(links.command(CONTROL, param1))
    links.step()
    assert acks(links.messages) == [result]
    assert links.endpoint.high_latency_enabled == (before if enabled is None else enabled)
    as_int = links.mav.command_int_encode(1, 1, 0, CONTROL, 0, 0, param1, 0, 0, 0, 0, 0, 0)
    links.clear()
    links.send(as_int)
    links.step()
    assert acks(links.messages) == [result]
    counted = links.endpoint.rejected["command_refused"]
    assert counted == (2 if result == FAILED else 0)


def test_high_latency2_interval_is_five_seconds_and_settable_as_ardupilots(
    links: TwoLinks,
) -> None:
    """HIGH_LATENCY2 on the high-latency link every 5 s from its start (ArduPilot's 5000 ms,
    first due one interval in); GET_MESSAGE_INTERVAL says 5 000 000 µs there and −1 on the
    normal link; SET_MESSAGE_INTERVAL 0 on the normal link starts it there at its 5-s default,
    2 000 000 µs on the high-latency link makes it 2 s; REQUEST_MESSAGE sends one at once."""
    links.send(links.command(CONTROL, 1))
    links.run(41.0, links.flying())
    times = [m.timestamp / 1000.0 for m in links.hl_of("HIGH_LATENCY2")]
    assert len(times) == 8
    # one interval after the schedule's first run (the first frame, 12.5 ms in)
    assert times[0] == pytest.approx(links.hl_opened_s + HL2_INTERVAL_S, abs=0.02)
    for k, t in enumerate(times):
        assert t == pytest.approx(times[0] + k * HL2_INTERVAL_S, abs=0.011)  # no drift
    get = mav.MAV_CMD_GET_MESSAGE_INTERVAL
    links.send_hl(links.command(get, 235))
    links.send(links.command(get, 235))
    links.step()
    assert [m.interval_us for m in links.hl_of("MESSAGE_INTERVAL")] == [5_000_000]
    assert [m.interval_us for m in links.of("MESSAGE_INTERVAL")] == [-1]
    links.clear()
    links.hl_messages.clear()
    set_interval = mav.MAV_CMD_SET_MESSAGE_INTERVAL
    links.send(links.command(set_interval, 235, 0))
    links.send_hl(links.command(set_interval, 235, 2_000_000))
    links.run(10.005, links.flying())
    assert len(links.of("HIGH_LATENCY2")) == 2  # 5 s after the set, and 10 s
    assert len(links.hl_of("HIGH_LATENCY2")) == 5  # every 2 s
    links.clear()
    links.send(links.command(mav.MAV_CMD_REQUEST_MESSAGE, 235))
    links.step()
    assert len(links.of("HIGH_LATENCY2")) == 1
    assert acks(links.messages, mav.MAV_CMD_REQUEST_MESSAGE) == [ACCEPTED]


def _global_to_local(lat_e7: int, lon_e7: int) -> tuple[float, float]:
    """North, east [m] of a latitude, longitude [1e-7 deg] from the home (flat earth)."""
    lat0, lon0 = HOME_DEG
    north = math.radians(lat_e7 * 1e-7 - lat0) * EARTH_RADIUS_M
    east = math.radians(lon_e7 * 1e-7 - lon0) * EARTH_RADIUS_M * math.cos(math.radians(lat0))
    return north, east


def test_high_latency2_describes_the_vehicle_within_each_fields_quantisation(
    links: TwoLinks,
) -> None:
    """Armed, in GUIDED toward a point 24 m north, 7 m east at 2.5 m deep, heading 100°: each
    HIGH_LATENCY2 (decoded by pymavlink) against the physics truth at its timestamp.

    Quantisation (ArduPilot's integer conversions): latitude, longitude 1e-7° (≤ 1.1 cm);
    altitude and target altitude whole metres truncated toward 0 (−2.4 m → −2); heading and
    target heading 2° steps, floored; target distance 10 m steps; ground speed and speed
    setpoint 0.2 m/s steps, truncated. Tolerances add the sensors' error: 4 cm on position
    (the fix's noise and age), 3 cm on depth, 0.5° on heading, 0.1 m/s on the speed estimate.
    The speed setpoint is the vehicle's own loop's demand (gain 0.8 /s × error, ≤ 0.5 m/s:
    2.5 → 2 far from the target); the fields ArduSub leaves zero are zero; the failure flags
    are ArduPilot's map of SYS_STATUS's health bits, read over the normal link."""
    target_n, target_e, target_d, target_yaw_deg = 24.0, 7.0, 2.5, 100.0
    links.send(links.command(CONTROL, 1), links.command(mav.MAV_CMD_GET_HOME_POSITION))
    links.enter_guided()
    home = links.last("HOME_POSITION")
    assert (home.latitude, home.longitude) == (399945000, -686000)
    position_only_and_yaw = 8 | 16 | 32 | 64 | 128 | 256 | 2048
    links.send(
        links.mav.set_position_target_local_ned_encode(
            0, 1, 1, mav.MAV_FRAME_LOCAL_NED, position_only_and_yaw,
            target_n, target_e, target_d, 0, 0, 0, 0, 0, 0, math.radians(target_yaw_deg), 0,
        )
    )  # fmt: skip
    checked = far = 0
    distances = set()
    start = len(links.hl_messages)
    for _ in range(round(40.0 / 0.01)):
        links.send(*links.flying()(round(links.now_s / 0.01)))
        links.step()
        new = [m for m in links.hl_messages[start:] if m.get_type() == "HIGH_LATENCY2"]
        start = len(links.hl_messages)
        if not new:
            continue
        (hl,) = new
        checked += 1
        truth = links.vehicle.truth
        tn, te, td = (float(v) for v in truth.position_ned_m)
        assert hl.timestamp == pytest.approx(links.now_s * 1000.0, abs=1.0)
        assert (hl.type, hl.autopilot, hl.custom_mode) == (12, 3, 4)
        assert hl.custom0 == BASE_GUIDED_ARMED - 256  # the uint8 base_mode in an int8
        north, east = _global_to_local(hl.latitude, hl.longitude)
        assert north == pytest.approx(tn, abs=0.04) and east == pytest.approx(te, abs=0.04)
        # altitude: −depth truncated toward 0, so −depth ≤ altitude < −depth + 1
        assert -td - 0.03 <= hl.altitude < -td + 1.0 + 0.03
        assert hl.target_altitude == -2  # −2.5 m truncated
        yaw = math.degrees(euler_from_quat(tuple(truth.quaternion_wxyz))[2]) % 360.0
        assert 2 * hl.heading - 0.5 <= yaw < 2 * hl.heading + 2.0 + 0.5
        dn, de = target_n - tn, target_e - te
        bearing = math.degrees(math.atan2(de, dn)) % 360.0
        assert 2 * hl.target_heading - 0.5 <= bearing < 2 * hl.target_heading + 2.0 + 0.5
        distance = math.hypot(dn, de)
        assert 10 * hl.target_distance - 0.05 <= distance < 10 * hl.target_distance + 10.05
        speed = math.hypot(*links.vehicle.truth.velocity_m_s[:2])
        assert hl.groundspeed / 5.0 - 0.1 <= speed < hl.groundspeed / 5.0 + 0.2 + 0.1
        gains = PositionGains()
        if distance > gains.max_speed_m_s / gains.kp_1_s + 0.5 and abs(td - target_d) < 0.1:
            assert hl.airspeed_sp == math.trunc(5.0 * gains.max_speed_m_s)  # 2
            far += 1
        distances.add(hl.target_distance)
        assert hl.throttle == 50  # the heave stick centred: ArduSub's throttle 0.5
        zero = ("airspeed", "windspeed", "wind_heading", "eph", "epv", "climb_rate", "wp_num")
        assert [getattr(hl, name) for name in (*zero, "custom1", "custom2")] == [0] * 9
        assert hl.temperature_air == -128  # INT8_MIN: no airspeed sensor
        status = links.last("SYS_STATUS")
        flags = sum(f for bit, f in STATUS_MAP if not status.onboard_control_sensors_health & bit)
        assert hl.failure_flags == flags == 1 + 2 + 64 + 256  # no GPS, airspeed, terrain, RC
        assert hl.battery == status.battery_remaining and 0 <= hl.battery <= 100
    assert checked == 8 and far >= 4 and distances == {1, 2}  # 25 m, then within 20 m
    assert links.vehicle.truth.position_ned_m[2] == pytest.approx(target_d, abs=0.1)
    assert hl.altitude == -2  # 2.5 m deep
    assert abs(2 * hl.heading - target_yaw_deg) <= 6.0  # heading 100°, held within 5°


def test_outside_guided_the_target_fields_are_zero_and_the_mode_and_arming_are_reported(
    links: TwoLinks,
) -> None:
    """Disarmed in MANUAL (ArduSub's boot state): custom_mode 19, custom0 81; armed in
    ALT_HOLD: 2 and 209 − 256; the target fields zero, as ArduSub's overrides outside AUTO and
    GUIDED."""
    links.send(links.command(CONTROL, 1))
    links.run(5.02, links.flying())
    first = links.hl_of("HIGH_LATENCY2")[-1]
    assert (first.custom_mode, first.custom0) == (19, 81)
    links.send(links.arm(), links.set_mode(2))
    links.run(5.0, links.flying(x=1000))
    second = links.hl_of("HIGH_LATENCY2")[-1]
    assert (second.custom_mode, second.custom0) == (2, 209 - 256)
    targets = (second.target_altitude, second.target_heading, second.target_distance)
    assert targets == (0, 0, 0) and second.airspeed_sp == 0
    assert second.groundspeed > 0  # surging


def test_a_gateway_link_on_a_mavlinkhl_port_sends_high_latency2_alone() -> None:
    """Through the s100 gateway, the second link with SERIAL1_PROTOCOL 43 at boot (ArduPilot's
    ``GCS_MAVLINK::init``: a SerialProtocol_MAVLinkHL port is a high-latency link) is silent
    until MAV_CMD_CONTROL_HIGH_LATENCY 1 (sent on the first link), then carries HIGH_LATENCY2
    alone — not the gateway's 2-Hz NAMED_VALUE_FLOAT LinkAge, which it used to get — while
    the first link keeps its heartbeat, LinkAge and no HIGH_LATENCY2."""
    gateway = SimGateway({"SERIAL1_PROTOCOL": 43})
    try:
        hl = gateway.endpoint.open_channel("hl")
        assert hl.high_latency and not gateway.channel.high_latency
        gateway.run(1.0)
        assert hl.take() == []
        gateway.send(gateway.mav.command_long_encode(1, 1, CONTROL, 0, 1, 0, 0, 0, 0, 0, 0))
        gateway.run(5.5)
        decoder = mav.MAVLink(None)
        on_hl = [m.get_type() for p in hl.take() for m in decoder.parse_buffer(p) or []]
        assert on_hl.count("HIGH_LATENCY2") == 1  # due 5 s after the link opened
        assert set(on_hl) == {"STATUSTEXT", "HIGH_LATENCY2"}  # "High Latency enabled", HL2
        kinds = {m.get_type() for m in gateway.messages}
        assert {"HEARTBEAT", "NAMED_VALUE_FLOAT"} <= kinds and "HIGH_LATENCY2" not in kinds
    finally:
        gateway.vehicle.close()
