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

The ``mavlink-hl`` codec is the same with the link a **high-latency** one on both ends
(scenario ``s100-mavlink-hl-v1``; :mod:`testbed.mavlink.high_latency`): the vehicle's endpoint
opens it as ArduSub's SERIALn_PROTOCOL 43 port with its SRn_* streams at 0, so once the ground
station's MAV_CMD_CONTROL_HIGH_LATENCY is ACCEPTED it sends HIGH_LATENCY2 every 5 s, the replies
and STATUSTEXT, and nothing else (before, nothing at all); the ground station does what
QGroundControl does on such a link (no heartbeat, no stream requests, a command sent again only
after 120 s without its ACK) but keeps sending the
pilot's MANUAL_CONTROL, one a slot, at ``link.uplink_rate_hz``
(:class:`~testbed.mavlink.ground_station.ScriptedGroundStation`). The operator's state is
HIGH_LATENCY2's, its sample time the ``timestamp``.

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

from testbed.common.components import ArmRequest, ModeRequest
from testbed.mavlink import VehicleEndpoint
from testbed.mavlink.ground_station import (
    QGC_HIGH_LATENCY_ACK_TIMEOUT_S,
    QGC_STREAM_RATES_HZ,
    ScriptedGroundStation,
)
from testbed.operator.station import OperatorStation
from testbed.operator.video import ImageConsole
from testbed.run.links import Ingested, Outgoing
from testbed.run.mavlink_run import endpoint_options, install_motor_directions
from testbed.vehicle.vehicle import Vehicle
from testbed.vehicle.video import ImageSource

__all__ = [
    "QGC_STREAM_RATES_HZ",
    "HighLatencyOperatorLink",
    "HighLatencyVehicleLink",
    "RawMavlinkOperatorLink",
    "RawMavlinkVehicleLink",
]

_GAIN = 1.0
_RETRY_S = 1.0


class RawMavlinkVehicleLink:
    """The vehicle's end: the ArduSub endpoint on its world, its packets written each frame.

    Args:
        vehicle: the vehicle.
        high_latency: the link is a high-latency one (module docstring).
    """

    images: ImageSource | None = None
    reply_image: int | None = None

    def __init__(self, vehicle: Vehicle, *, high_latency: bool = False) -> None:
        # ArduSub's frame as the direct endpoint presents it (servo numbering, FRAME_CONFIG,
        # MOT_n_DIRECTION, BARO_SPEC_GRAV), the baseline's full joystick gain over them
        boot = {"JS_GAIN_DEFAULT": _GAIN}
        options = endpoint_options(vehicle.config, vehicle.thruster_config, boot)
        self.endpoint = VehicleEndpoint(
            vehicle.world, vehicle.entity, vehicle.operator_entity, options
        )
        install_motor_directions(vehicle, self.endpoint)
        self.channel = self.endpoint.open_channel("narrow-link", high_latency=high_latency)

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
    """The operator's end: a scripted ground station
    (:class:`~testbed.mavlink.ground_station.ScriptedGroundStation`) flying the station's
    pilot, arm and mode requests.

    Args:
        station: the operator's station (its pilot's sticks, its arm and mode requests).
        high_latency: the link is a high-latency one (module docstring).
    """

    console: ImageConsole | None = None

    def __init__(self, station: OperatorStation, *, high_latency: bool = False) -> None:
        self._station = station
        retry_s = QGC_HIGH_LATENCY_ACK_TIMEOUT_S if high_latency else _RETRY_S
        self.gcs = ScriptedGroundStation(gain=_GAIN, retry_s=retry_s, high_latency=high_latency)

    @property
    def vehicle_armed(self) -> bool:
        """Armed, as the vehicle's last heartbeat said."""
        return self.gcs.vehicle_armed

    @property
    def telemetry(self) -> dict[str, int]:
        """Telemetry messages decoded, by type."""
        return self.gcs.telemetry

    def slot(self, now_s: float) -> list[Outgoing]:
        world, entity = self._station.world, self._station.entity
        arm = world.get(entity, ArmRequest)
        mode = world.get(entity, ModeRequest)
        command = self._station.latest_command()
        packets, stick = self.gcs.packets(
            now_s,
            None if command is None else command.sticks,
            None if arm is None else arm.armed,
            None if mode is None else int(mode.mode),  # ControlMode values are ArduSub's
        )
        return [Outgoing(p, command if k == stick else None) for k, p in enumerate(packets)]

    def ingest(self, payloads: list[tuple[bytes, int]], now_s: float) -> Ingested:
        del now_s
        result = Ingested()
        for payload, _ in payloads:
            result.sampled_s.extend(self.gcs.receive(payload))
        return result


class HighLatencyVehicleLink(RawMavlinkVehicleLink):
    """The ``mavlink-hl`` codec's vehicle end: :class:`RawMavlinkVehicleLink` on a
    high-latency link."""

    def __init__(self, vehicle: Vehicle) -> None:
        super().__init__(vehicle, high_latency=True)


class HighLatencyOperatorLink(RawMavlinkOperatorLink):
    """The ``mavlink-hl`` codec's operator end: :class:`RawMavlinkOperatorLink`'s ground
    station on a high-latency link."""

    def __init__(self, station: OperatorStation) -> None:
        super().__init__(station, high_latency=True)
