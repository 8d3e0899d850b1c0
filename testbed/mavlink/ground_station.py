"""A scripted ground station with QGroundControl's habits, sans-IO (bytes in, bytes out).

What the raw-MAVLink baseline (``testbed.run.mavlink_links``, scenario ``s100-mavlink-raw-v1``)
puts on the operator's side of the narrow link (REFERENCE.md §4.4): on its first slot
REQUEST_DATA_STREAM at QGC's rates (:data:`QGC_STREAM_RATES_HZ`); every slot a MANUAL_CONTROL of
the pilot's sticks; a HEARTBEAT every second; arm and mode requests as COMMAND_LONG 400 and
SET_MODE, repeated every ``retry_s`` until the vehicle's heartbeat shows them (QGC retries an
unanswered command). It decodes the vehicle's telemetry: the ``time_boot_ms`` of each ATTITUDE
is the sample time [s] of the state it carries. Packets are pymavlink's ardupilotmega dialect,
MAVLink 2, system 255 component 190 (QGC's).

On a **high-latency link** (``high_latency=True``) it does what QGroundControl does there
(``VehicleLinkManager``: MAV_CMD_CONTROL_HIGH_LATENCY 1 when the link becomes the vehicle's
primary one; ``MultiVehicleManager::_sendGCSHeartbeat`` skips high-latency links; no stream
requests): on its first slot COMMAND_LONG CONTROL_HIGH_LATENCY (param1 1), sent again every
``retry_s`` until the vehicle ACKs it ACCEPTED; no HEARTBEAT, no REQUEST_DATA_STREAM. QGC waits
:data:`QGC_HIGH_LATENCY_ACK_TIMEOUT_S` for a command's ACK on such a link before it sends the
command again (``Vehicle``: ``_mavCommandAckTimeoutMSecsHighLatency``), the ``retry_s`` the
``mavlink-hl`` codec gives it. The vehicle's state comes in HIGH_LATENCY2 (armed in
``custom0``'s base_mode bit 128, the mode in ``custom_mode``, its sample time the
``timestamp``). An arm or mode request goes again when a HIGH_LATENCY2 sampled after it was
sent shows the vehicle otherwise (the operator, seeing it, asks again; QGC itself would wait its
120 s), or after ``retry_s``; one ACKed ACCEPTED is not sent again (QGC's command protocol stops
at the ACK) before such a HIGH_LATENCY2. Unlike QGC, whose ``sendJoystickDataThreadSafe`` sends
no joystick on a high-latency link, it still sends the pilot's sticks as MANUAL_CONTROL each
slot, so the same pilot flies over each link; the slot rate is the scenario's
``link.uplink_rate_hz``.
"""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.mavlink.ardusub import manual_control_from_sticks

__all__ = ["QGC_HIGH_LATENCY_ACK_TIMEOUT_S", "QGC_STREAM_RATES_HZ", "ScriptedGroundStation"]

QGC_STREAM_RATES_HZ = {1: 2, 2: 2, 3: 2, 6: 3, 10: 20, 11: 10, 12: 3}
"""QGroundControl's REQUEST_DATA_STREAM rates on connect: stream id → Hz (REFERENCE §4.4)."""
QGC_HIGH_LATENCY_ACK_TIMEOUT_S = 120.0
"""How long QGroundControl waits for a command's ACK on a high-latency link before sending it
again [s] (``_mavCommandAckTimeoutMSecsHighLatency``, 120 000 ms; 3 s on other links)."""


class ScriptedGroundStation:
    """The ground station's state and its packets (module docstring).

    Args:
        gain: the joystick gain the sticks are encoded at (the vehicle's ``JS_GAIN_DEFAULT``).
        retry_s: how often an unanswered arm or mode request is sent again [s].
        high_latency: the link is a high-latency one (module docstring).
    """

    def __init__(
        self, gain: float = 1.0, retry_s: float = 1.0, *, high_latency: bool = False
    ) -> None:
        self._gain = gain
        self._retry_s = retry_s
        self.high_latency = high_latency
        self.high_latency_acked = False
        """The vehicle ACKed MAV_CMD_CONTROL_HIGH_LATENCY ACCEPTED (high-latency link)."""
        self._acked_arm: bool | None = None
        self._acked_mode: int | None = None
        self._last_arm: bool | None = None
        self._last_mode: int | None = None
        self._next_hl_s = 0.0
        self._requested_s = -1.0
        self._mav = mav.MAVLink(None, srcSystem=255, srcComponent=190)
        self._decoder = mav.MAVLink(None)
        self._decoder.robust_parsing = True
        self._connected = False
        self._next_heartbeat_s = 0.0
        self._next_retry_s = 0.0
        self.vehicle_armed = False
        """Armed, as the vehicle's last heartbeat said."""
        self.vehicle_mode = 19
        """The vehicle's custom mode (ArduSub's number) in its last heartbeat."""
        self.telemetry: dict[str, int] = {}
        """Messages decoded, by type."""

    def _encode(self, message: mav.MAVLink_message) -> bytes:
        return bytes(message.pack(self._mav))

    def packets(
        self,
        now_s: float,
        sticks: tuple[float, float, float, float, float, float] | None,
        armed: bool | None,
        mode: int | None,
    ) -> tuple[list[bytes], int]:
        """What the station writes in the slot at ``now_s`` [s].

        Args:
            now_s: the slot's time [s].
            sticks: the pilot's (6,) sticks in [−1, 1], or None (no MANUAL_CONTROL).
            armed: the arm state the pilot asks for, or None.
            mode: the ArduSub mode number the pilot asks for, or None.

        Returns:
            The packets, one MAVLink message each, and the index of the MANUAL_CONTROL among
            them (−1 without sticks).
        """
        out: list[bytes] = []
        if self.high_latency:
            out.extend(self._high_latency_request(now_s))
        elif not self._connected:
            self._connected = True
            for stream, rate in QGC_STREAM_RATES_HZ.items():
                out.append(
                    self._encode(mav.MAVLink_request_data_stream_message(1, 1, stream, rate, 1))
                )
        if not self.high_latency and now_s >= self._next_heartbeat_s:
            self._next_heartbeat_s = max(self._next_heartbeat_s + 1.0, now_s)
            out.append(
                self._encode(
                    mav.MAVLink_heartbeat_message(
                        mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, mav.MAV_STATE_ACTIVE, 3
                    )
                )
            )
        out.extend(self._requests(now_s, armed, mode))
        if sticks is None:
            return out, -1
        x, y, z, r = manual_control_from_sticks(sticks, gain=self._gain)
        out.append(self._encode(mav.MAVLink_manual_control_message(1, x, y, z, r, 0)))
        return out, len(out) - 1

    def _high_latency_request(self, now_s: float) -> list[bytes]:
        """MAV_CMD_CONTROL_HIGH_LATENCY 1 until ACKed, every ``retry_s``."""
        if self.high_latency_acked or now_s < self._next_hl_s:
            return []
        self._next_hl_s = now_s + self._retry_s
        params = (1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        command = mav.MAV_CMD_CONTROL_HIGH_LATENCY
        return [self._encode(mav.MAVLink_command_long_message(1, 1, command, 0, *params))]

    def _requests(self, now_s: float, armed: bool | None, mode: int | None) -> list[bytes]:
        """Arm and mode requests not yet shown by the vehicle's heartbeat (nor, on a
        high-latency link, ACKed), every ``retry_s``."""
        out: list[bytes] = []
        if now_s < self._next_retry_s:
            return out
        if mode is not None and mode != self.vehicle_mode and mode != self._acked_mode:
            flag = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            out.append(self._encode(mav.MAVLink_set_mode_message(1, flag, mode)))
            self._last_mode = mode
        if armed is not None and armed != self.vehicle_armed and armed != self._acked_arm:
            params = (1.0 if armed else 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
            self._last_arm = armed
            arm = mav.MAV_CMD_COMPONENT_ARM_DISARM
            out.append(self._encode(mav.MAVLink_command_long_message(1, 1, arm, 0, *params)))
        if out:
            self._next_retry_s = now_s + self._retry_s
            self._requested_s = now_s
        return out

    def receive(self, payload: bytes) -> list[float]:
        """Decode what the vehicle sent (garbage is skipped); the sample times [s] of the
        states in it (ATTITUDE's ``time_boot_ms``, HIGH_LATENCY2's ``timestamp``)."""
        sampled: list[float] = []
        for message in self._decoder.parse_buffer(payload) or []:
            kind = message.get_type()
            if kind == "BAD_DATA":
                continue
            self.telemetry[kind] = self.telemetry.get(kind, 0) + 1
            if kind == "HEARTBEAT" and message.get_srcSystem() == 1:
                self.vehicle_armed = bool(message.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED)
                self.vehicle_mode = int(message.custom_mode)
            elif kind == "ATTITUDE":
                sampled.append(message.time_boot_ms / 1000.0)
            elif kind == "HIGH_LATENCY2" and message.get_srcSystem() == 1:
                base_mode = int(message.custom0) & 0xFF  # ArduPilot's base_mode in an int8
                self.vehicle_armed = bool(base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED)
                self.vehicle_mode = int(message.custom_mode)
                sampled_s = message.timestamp / 1000.0
                if sampled_s > self._requested_s:  # the state after the last request: it counts
                    self._acked_arm = self._acked_mode = None
                    self._next_retry_s = 0.0
                sampled.append(sampled_s)
            elif kind == "COMMAND_ACK" and self.high_latency:
                self._on_ack(message)
        return sampled

    def _on_ack(self, message: mav.MAVLink_message) -> None:
        """A high-latency link's COMMAND_ACK: an accepted request is not sent again."""
        if message.result != mav.MAV_RESULT_ACCEPTED:
            return
        if message.command == mav.MAV_CMD_CONTROL_HIGH_LATENCY:
            self.high_latency_acked = True
        elif message.command == mav.MAV_CMD_COMPONENT_ARM_DISARM:
            self._acked_arm = self._last_arm
        elif message.command == mav.MAVLINK_MSG_ID_SET_MODE:
            self._acked_mode = self._last_mode
