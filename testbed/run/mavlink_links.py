"""The ``mavlink-raw`` link codec: a ground station's MAVLink byte stream through the narrow link.

The baseline the paper's protocol is measured against (scenario ``s100-mavlink-raw-v1``): no
compact orders, no token passing — the MAVLink packets themselves cross the simulated channel,
each node writing into its modem's buffer whenever it has something (free access; a full buffer
tail-drops, half duplex collides).

- Operator (:class:`RawMavlinkOperatorLink`): a scripted ground station with QGroundControl's
  habits (REFERENCE.md §4.4): on the first slot REQUEST_DATA_STREAM at QGC's rates (RAW_SENSORS
  2, EXTENDED_STATUS 2, RC_CHANNELS 2, POSITION 3, EXTRA1 20, EXTRA2 10, EXTRA3 3 Hz); every
  slot (``link.uplink_rate_hz``, 25 Hz as QGC's joystick) a MANUAL_CONTROL of the station's
  sticks; a HEARTBEAT every second; the station's arm and mode requests as COMMAND_LONG 400 and
  SET_MODE, repeated every second until the vehicle's heartbeat shows them (QGC retries an
  unanswered command). The vehicle's telemetry is decoded; the ``time_boot_ms`` of each
  ATTITUDE is the sample time of the state it carries.
- Vehicle (:class:`RawMavlinkVehicleLink`): part 1's ArduSub endpoint
  (:class:`~testbed.mavlink.VehicleEndpoint`) on the vehicle's world; after each frame it
  writes what the endpoint queued (telemetry at the requested rates, replies).

Each MAVLink packet is one write to the modem (one frame, as a ground station sends one
datagram per message); every packet fits a frame's 255-B payload. A byte-counted tail-drop
buffer then starves the larger writes: once the stream of 29-B MANUAL_CONTROL frames keeps it
within 29 B of full, a 51-B COMMAND_LONG never fits.

The sticks are encoded at joystick gain 1 (``JS_GAIN_DEFAULT`` 1 on the vehicle) so every stick
the pilot holds is representable. Ground truth for the recorder: the frame carrying each
MANUAL_CONTROL is tied to the station's command (its sample time); the vehicle reports the
frames whose pilot input it accepted.
"""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.common.components import ArmRequest, ModeRequest
from testbed.mavlink import EndpointOptions, VehicleEndpoint
from testbed.mavlink.ardusub import manual_control_from_sticks
from testbed.operator.station import OperatorStation
from testbed.operator.video import ImageConsole
from testbed.run.links import Ingested, Outgoing
from testbed.vehicle.vehicle import Vehicle
from testbed.vehicle.video import ImageSource

__all__ = ["QGC_STREAM_RATES_HZ", "RawMavlinkOperatorLink", "RawMavlinkVehicleLink"]

QGC_STREAM_RATES_HZ = {1: 2, 2: 2, 3: 2, 6: 3, 10: 20, 11: 10, 12: 3}
"""QGroundControl's REQUEST_DATA_STREAM rates on connect: stream id → Hz (REFERENCE §4.4)."""
_GAIN = 1.0
_RETRY_S = 1.0


class RawMavlinkVehicleLink:
    """The vehicle's end: the ArduSub endpoint on its world, its packets written each frame.

    Args:
        vehicle: the vehicle.
    """

    images: ImageSource | None = None
    reply_image: int | None = None

    def __init__(self, vehicle: Vehicle) -> None:
        options = EndpointOptions(vehicle.config.supply_voltage_v, {"JS_GAIN_DEFAULT": _GAIN})
        self.endpoint = VehicleEndpoint(
            vehicle.world, vehicle.entity, vehicle.operator_entity, options
        )
        self.channel = self.endpoint.open_channel("narrow-link")

    def ingest(self, payloads: list[tuple[bytes, int]], now_s: float) -> Ingested:
        result = Ingested()
        for payload, frame_id in payloads:
            if self.endpoint.receive(self.channel, payload, now_s):
                result.frames.append(frame_id)
        return result

    def outbound(self, now_s: float) -> list[bytes]:
        self.endpoint.update(now_s)
        return self.channel.take()

    def answer(self, payload: bytes) -> bytes | None:
        del payload
        return None


class RawMavlinkOperatorLink:
    """The operator's end: a scripted ground station (module docstring).

    Args:
        station: the operator's station (its pilot's sticks, its arm and mode requests).
    """

    console: ImageConsole | None = None

    def __init__(self, station: OperatorStation) -> None:
        self._station = station
        self._mav = mav.MAVLink(None, srcSystem=255, srcComponent=190)
        self._decoder = mav.MAVLink(None)
        self._decoder.robust_parsing = True
        self._connected = False
        self._next_heartbeat_s = 0.0
        self._next_retry_s = 0.0
        self.vehicle_armed = False
        self.vehicle_mode = 19
        self.telemetry: dict[str, int] = {}
        """Telemetry messages decoded, by type."""

    def _encode(self, message: mav.MAVLink_message) -> bytes:
        return bytes(message.pack(self._mav))

    def slot(self, now_s: float) -> list[Outgoing]:
        packets: list[bytes] = []
        if not self._connected:
            self._connected = True
            for stream, rate in QGC_STREAM_RATES_HZ.items():
                packets.append(
                    self._encode(mav.MAVLink_request_data_stream_message(1, 1, stream, rate, 1))
                )
        if now_s >= self._next_heartbeat_s:
            self._next_heartbeat_s = max(self._next_heartbeat_s + 1.0, now_s)
            hb = mav.MAVLink_heartbeat_message(
                mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, mav.MAV_STATE_ACTIVE, 3
            )
            packets.append(self._encode(hb))
        packets.extend(self._requests(now_s))
        command = self._station.latest_command()
        if command is not None:
            x, y, z, r = manual_control_from_sticks(command.sticks, gain=_GAIN)
            packets.append(self._encode(mav.MAVLink_manual_control_message(1, x, y, z, r, 0)))
        stick = len(packets) - 1 if command is not None else -1
        return [Outgoing(p, command if k == stick else None) for k, p in enumerate(packets)]

    def _requests(self, now_s: float) -> list[bytes]:
        """Arm and mode requests not yet shown by the vehicle's heartbeat, once a second."""
        world = self._station.world
        entity = self._station.entity
        arm = world.get(entity, ArmRequest)
        mode = world.get(entity, ModeRequest)
        out: list[bytes] = []
        if now_s < self._next_retry_s:
            return out
        if mode is not None and int(mode.mode) != self.vehicle_mode:
            number = int(mode.mode)  # ControlMode values are ArduSub's numbers
            out.append(
                self._encode(
                    mav.MAVLink_set_mode_message(1, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, number)
                )
            )
        if arm is not None and arm.armed != self.vehicle_armed:
            params = (1.0 if arm.armed else 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
            out.append(
                self._encode(
                    mav.MAVLink_command_long_message(
                        1, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, *params
                    )
                )
            )
        if out:
            self._next_retry_s = now_s + _RETRY_S
        return out

    def ingest(self, payloads: list[tuple[bytes, int]], now_s: float) -> Ingested:
        del now_s
        result = Ingested()
        for payload, _ in payloads:
            for message in self._decoder.parse_buffer(payload) or []:
                kind = message.get_type()
                if kind == "BAD_DATA":
                    continue
                self.telemetry[kind] = self.telemetry.get(kind, 0) + 1
                if kind == "HEARTBEAT" and message.get_srcSystem() == 1:
                    self.vehicle_armed = bool(message.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED)
                    self.vehicle_mode = int(message.custom_mode)
                elif kind == "ATTITUDE":
                    result.sampled_s.append(message.time_boot_ms / 1000.0)
        return result
