"""The ArduSub-compatible vehicle endpoint: a sans-IO MAVLink core that pilots an ECS world.

:class:`VehicleEndpoint` is fed bytes and the time (:meth:`~VehicleEndpoint.receive`) and asked
for what is due (:meth:`~VehicleEndpoint.update`); each
:class:`~testbed.mavlink.channel.Channel` (one per ground-station link) holds its own parser,
stream rates and outbox of encoded packets. What it sends and on which link (opening the
channels, queuing on them, the STATUSTEXTs held to the end of an update) is its base class,
:class:`~testbed.mavlink.outbound.Outbound`. It has no socket and no clock of its own; what it
is told of the vehicle is its :class:`~testbed.mavlink.options.EndpointOptions`.

It is a **pilot** of the world it is given, not a second control stack: it writes only the
operator-owned components (:class:`~testbed.common.components.MovementCommand`,
``ArmRequest``, ``ModeRequest``, ``DepthSetpoint``) on the ``intents`` entity and reads the
vehicle-owned ones on the ``vehicle`` entity (:mod:`testbed.mavlink.telemetry`). On the vehicle
those are the vehicle's own entities; a shore-side gateway gives it the operator station's world
(intents it owns, the vehicle state it mirrors) and the same handling serves the ground station.

What it speaks (ArduSub 4.5 as seen by QGroundControl and MAVProxy, REFERENCE.md §4): system
1 component 1, MAVLink 2; HEARTBEAT at 1 Hz per link; AUTOPILOT_VERSION on REQUEST_MESSAGE or
REQUEST_AUTOPILOT_CAPABILITIES; the parameter protocol over :class:`~.params.ParamTable`;
MISSION_COUNT 0; REQUEST_DATA_STREAM and SET/GET_MESSAGE_INTERVAL; TIMESYNC; arming
(COMMAND_LONG 400), modes by SET_MODE or DO_SET_MODE with COMMAND_ACK (MANUAL, STABILIZE,
ALT_HOLD fly; GUIDED with a position estimate, flown to SET_POSITION_TARGET_*'s position,
fixed or moving at its velocity, or SET_ATTITUDE_TARGET's attitude and climb rate; every other
mode is refused with MAV_RESULT_FAILED — the simulator has no position-hold, auto or surface
mode); MANUAL_CONTROL and RC_CHANNELS_OVERRIDE with ArduSub's scaling, gated on SYSID_MYGCS
and SYSID_THISMAV (what fails the gate is dropped silently and counted;
:mod:`testbed.mavlink.pilot_input`); the pilot-input and GCS failsafes of the FS_* parameters
(:mod:`testbed.mavlink.failsafe`); HIGH_LATENCY2 on a high-latency link
(:mod:`testbed.mavlink.high_latency`).

Remote garbage is counted, never raised (:attr:`VehicleEndpoint.rejected` by reason); outboxes
are bounded (:data:`~testbed.mavlink.channel.OUTBOX_LIMIT`).
"""

from __future__ import annotations

import dataclasses
import math
from collections import Counter
from collections.abc import Callable

from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.common.components import (
    Armed,
    ArmRequest,
    ControlMode,
    DepthSetpoint,
    ModeRequest,
    MovementCommand,
    PositionReading,
    PositionSetpoint,
)
from testbed.ecs import Entity, World
from testbed.mavlink import commands, guided, guided_yaw, high_latency, param_protocol, pilot_input
from testbed.mavlink.ardusub import RcInput, boot_gain, sticks_from_rc
from testbed.mavlink.attitude_target import (
    AttitudeTarget,
    StoredAttitude,
    on_set_attitude_target,
    update_attitude_target,
)
from testbed.mavlink.channel import Channel
from testbed.mavlink.failsafe import FailsafeMonitor
from testbed.mavlink.motor_test import MotorTest, update_motor_test
from testbed.mavlink.options import EndpointOptions
from testbed.mavlink.outbound import Outbound
from testbed.mavlink.params import ParamTable
from testbed.mavlink.telemetry import BUILDERS
from testbed.mavlink.vehicle_snapshot import VehicleSnapshot, VelocityEstimator, read_vehicle

__all__ = ["POSITION_FIX_TIMEOUT_S", "Handler", "VehicleEndpoint"]

POSITION_FIX_TIMEOUT_S = 1.0
"""A position fix older than this [s] is no position estimate (GUIDED refused)."""


Handler = Callable[["VehicleEndpoint", "Channel", mav.MAVLink_message, float, float], None]
"""A message handler: (endpoint, channel, message, now [s], arrival [s])."""


class VehicleEndpoint(Outbound):
    """The MAVLink face of one vehicle (module docstring); what it sends, and on which link,
    is its base class's (:class:`~testbed.mavlink.outbound.Outbound`: ``channels``,
    ``queue``, ``statustext``, ``sent``, ``high_latency_enabled``).

    Args:
        world: the world it pilots.
        vehicle: the entity holding the vehicle-owned state.
        intents: the entity it writes the operator-owned intents on.
        options: presentation options.

    Attributes:
        params: the live parameter table.
        received: parsed messages by type.
        accepted: messages acted on.
        rejected: what was dropped, by reason (wire errors, gating, bad fields, unhandled, and
            the base class's full outboxes).
        pilot_inputs: MANUAL_CONTROL / RC_CHANNELS_OVERRIDE packets accepted
            (:mod:`~testbed.mavlink.pilot_input`).
        rc: the RC inputs the pilot's packets set; ``gain`` the joystick gain.
        buttons_held: the buttons of the last MANUAL_CONTROL (a button acts when pressed).
        attitude_target: GUIDED's angle control a SET_ATTITUDE_TARGET started
            (:mod:`~testbed.mavlink.attitude_target`), None when there is none.
        stored_attitude: the last throttle-ignored SET_ATTITUDE_TARGET, which ALT_HOLD flies
            while it is fresh (ArduSub's ``set_attitude_target_no_gps``), or None.
        motor_test: the DO_MOTOR_TEST state (:mod:`~testbed.mavlink.motor_test`).
        moving_target: GUIDED's position target moving at a velocity
            (:class:`~testbed.mavlink.guided.MovingTarget`), None when there is none.
        auto_yaw: ArduSub's auto-yaw state, GUIDED's heading
            (:class:`~testbed.mavlink.guided_yaw.AutoYaw`).
    """

    def __init__(
        self, world: World, vehicle: Entity, intents: Entity, options: EndpointOptions
    ) -> None:
        self.world = world
        self.vehicle = vehicle
        self.intents = intents
        self.options = options
        super().__init__(ParamTable(overrides=options.param_overrides))
        self.received: Counter[str] = Counter()
        self.accepted = 0
        self.pilot_inputs = 0
        self.rc = RcInput()
        p = self.params
        self.gain = boot_gain(
            p["JS_GAIN_DEFAULT"], p["JS_GAIN_MIN"], p["JS_GAIN_MAX"], int(p["JS_GAIN_STEPS"])
        )
        self.failsafe = FailsafeMonitor()
        self._velocity = VelocityEstimator()
        self._seq = 0
        self._arm_seq = 0
        self._arm_acknowledged: bool | None = None  # an arm/disarm not yet applied
        self.buttons_held = 0
        self._consumed_ah = 0.0
        self._last_update_s: float | None = None
        self._snapshot: VehicleSnapshot | None = None
        self.attitude_target: AttitudeTarget | None = None
        self.stored_attitude: StoredAttitude | None = None
        self.motor_test = MotorTest()
        self.moving_target: guided.MovingTarget | None = None
        self.auto_yaw = guided_yaw.AutoYaw()
        cls = type(self)
        self._handlers: dict[str, Handler] = {
            "HEARTBEAT": cls._on_heartbeat,
            "MANUAL_CONTROL": pilot_input.on_manual_control,
            "RC_CHANNELS_OVERRIDE": pilot_input.on_rc_channels_override,
            "COMMAND_LONG": commands.on_command_long,
            "COMMAND_INT": commands.on_command_int,
            "SET_MODE": commands.on_set_mode,
            "PARAM_REQUEST_LIST": param_protocol.on_param_request_list,
            "PARAM_REQUEST_READ": param_protocol.on_param_request_read,
            "PARAM_SET": param_protocol.on_param_set,
            "MISSION_REQUEST_LIST": commands.on_mission_request_list,
            "MISSION_COUNT": commands.on_mission_upload,
            "MISSION_CLEAR_ALL": commands.on_mission_upload,
            "REQUEST_DATA_STREAM": commands.on_request_data_stream,
            "TIMESYNC": commands.on_timesync,
            "SET_POSITION_TARGET_LOCAL_NED": guided.on_set_position_target_local_ned,
            "SET_POSITION_TARGET_GLOBAL_INT": guided.on_set_position_target_global_int,
            "SET_ATTITUDE_TARGET": on_set_attitude_target,
            "FILE_TRANSFER_PROTOCOL": commands.on_file_transfer_protocol,
        }

    # ------------------------------------------------------------------- capabilities

    @property
    def can_test_motors(self) -> bool:
        """Whether DO_MOTOR_TEST can reach the thrusters (here, on the vehicle's own node)."""
        return True

    @property
    def flies_moving_targets(self) -> bool:
        """Whether GUIDED's velocity targets are flown (here: the target moves each update, on
        the vehicle's own node)."""
        return True

    @property
    def gcs_system_id(self) -> int:
        """SYSID_MYGCS: the only system whose pilot input is accepted."""
        return int(self.params["SYSID_MYGCS"])

    def setpoint_not_sent(self, kind: str, text: str) -> None:
        """A target of ``kind`` the vehicle is not given: ``text`` said once (a gateway also
        notes the kind, :class:`~testbed.mavlink.shore.ShoreEndpoint`)."""
        self.statustext_once(mav.MAV_SEVERITY_WARNING, text)

    # ------------------------------------------------------------------------ receive

    def receive(
        self,
        channel: Channel,
        data: bytes,
        now_s: float,
        arrived_s: float | None = None,
        *,
        end: bool = False,
    ) -> int:
        """Parse ``data`` from ``channel`` and act on every message in it.

        Args:
            channel: the link it came on.
            data: any bytes (pieces of packets continue across calls).
            now_s: the world's time [s].
            arrived_s: when the bytes arrived, on the world's clock [s] (the sample time of the
                pilot input they carry); default ``now_s``.
            end: ``data`` ends a datagram or a client's stream
                (:attr:`~testbed.hil.Received.end`): a packet still incomplete is dropped and
                counted (``truncated``), not continued by the next call.

        Returns:
            Pilot-input packets accepted from ``data``.
        """
        decoded = channel.wire.decode(data, end)
        self.rejected.update(decoded.bad)
        before = self.pilot_inputs
        arrived = now_s if arrived_s is None else arrived_s
        for message in decoded.messages:
            kind = message.get_type()
            self.received[kind] += 1
            handler = self._handlers.get(kind)
            if handler is None:
                self.rejected["unhandled"] += 1
                continue
            try:
                handler(self, channel, message, now_s, arrived)
            except (ValueError, OverflowError, TypeError):  # a field pymavlink let through
                self.rejected["bad_field"] += 1
        return self.pilot_inputs - before

    def reject(self, reason: str) -> None:
        """Count a dropped message."""
        self.rejected[reason] += 1

    def for_us(self, target_system: int, target_component: int | None = None) -> bool:
        """Whether a target (0 = broadcast) names this vehicle's autopilot; counts misses."""
        ok = target_system in (0, self.system_id) and target_component in (None, 0, 1)
        if not ok:
            self.rejected["wrong_target"] += 1
        return ok

    def _on_heartbeat(
        self, channel: Channel, message: mav.MAVLink_message, now_s: float, arrived_s: float
    ) -> None:
        del channel, arrived_s
        self.accepted += 1
        if message.get_srcSystem() == self.gcs_system_id:
            self.gcs_seen(now_s)

    def gcs_seen(self, now_s: float) -> None:
        """A heartbeat or pilot input from SYSID_MYGCS at ``now_s`` [s]: the GCS failsafe's
        timer refreshed (and its clearing announced)."""
        if self.failsafe.gcs_seen(now_s):
            self.statustext(mav.MAV_SEVERITY_INFO, "GCS heartbeat regained")

    # ----------------------------------------------------------------------- intents

    def write(self, component: object) -> None:
        """Write an operator-owned component on the intents entity."""
        self.world.set(self.intents, component, origin=self.options.origin)

    def write_sticks(self, sampled_s: float) -> None:
        """Write the RC inputs as the next MovementCommand, sampled at ``sampled_s`` [s]."""
        self._seq += 1
        self.write(MovementCommand(self._seq, sampled_s, sticks_from_rc(self.rc.channels)))

    def request_arm(self, armed: bool, now_s: float) -> None:
        """Ask the vehicle to arm or disarm (a new request each time); :attr:`armed` says so
        at once."""
        self._arm_seq += 1
        self.write(ArmRequest(armed, self._arm_seq))
        self._arm_acknowledged = armed
        del now_s  # ArduSub's pilot-input timer runs from the last input, not from arming

    @property
    def armed(self) -> bool:
        """Armed as the next command finds it. ArduSub arms and disarms inside the command's
        handler (``init_arm_motors``, ``motors.armed(true)``), so a command after an accepted
        arm finds the motors armed; here the vehicle applies the request at its next frame,
        so until the :meth:`update` after that frame this is the request's state, then the
        vehicle's :class:`Armed` (on a shore gateway, the state mirrored from its replies)."""
        if self._arm_acknowledged is not None:
            return self._arm_acknowledged
        armed = self.world.get(self.vehicle, Armed)
        return armed is not None and armed.armed

    def set_mode(self, custom_mode: int) -> int:
        """Ask for ArduSub mode ``custom_mode`` under ArduSub's policy
        (:func:`~testbed.mavlink.commands.set_mode`); the MAV_RESULT."""
        return commands.set_mode(self, custom_mode)

    def request_mode(self, mode: ControlMode) -> None:
        """Ask the vehicle for a simulated mode."""
        self.write(ModeRequest(mode))

    @property
    def requested_mode(self) -> ControlMode | None:
        """The mode last asked for on the intents entity (None: none yet), the mode the
        handlers act in (ArduSub's ``control_mode``)."""
        request = self.world.get(self.intents, ModeRequest)
        return None if request is None else request.mode

    def has_position_estimate(self) -> bool:
        """Whether the vehicle has a position estimate now (ArduSub's condition for GUIDED): a
        :class:`PositionReading` on the vehicle entity no older than
        :data:`POSITION_FIX_TIMEOUT_S` at the endpoint's last update."""
        fix = self.world.get(self.vehicle, PositionReading)
        if fix is None:
            return False
        now = self._last_update_s
        return now is None or now - fix.time_s <= POSITION_FIX_TIMEOUT_S

    def request_position(self, position_ned_m: tuple[float, float, float]) -> None:
        """Set GUIDED's target, NED [m], at the heading of the auto-yaw state
        (:func:`~testbed.mavlink.guided_yaw.setpoint_heading`); it ends an attitude target's
        control and a moving target (ArduSub's position submode)."""
        self.attitude_target = None
        self.moving_target = None
        guided_yaw.new_destination(self, position_ned_m)
        yaw = guided_yaw.setpoint_heading(self)
        self.write(PositionSetpoint(position_ned_m, 0.0 if yaw is None else yaw, yaw is not None))

    def release_position(self) -> None:
        """Let go of GUIDED's position target (SET_ATTITUDE_TARGET's angle control): the
        vehicle's position loop stops, depth and heading held."""
        self.moving_target = None
        self.world.remove(self.intents, PositionSetpoint, origin=self.options.origin)

    def request_depth(self, depth_m: float) -> None:
        """Set the depth target [m, positive down]."""
        self.write(DepthSetpoint(depth_m))

    # ------------------------------------------------------------------------ update

    def state_source(self, now_s: float) -> tuple[Entity, float]:
        """The entity holding the vehicle's state and the time [s] that state describes: here
        the vehicle's own entity, now. A shore gateway (:mod:`testbed.mavlink.shore`) returns
        its mirrored copy and the copy's sample time, so the telemetry carries its true age."""
        return self.vehicle, now_s

    def snapshot(self, now_s: float) -> VehicleSnapshot:
        """The vehicle as the telemetry reports it now (the state's own time in ``time_s``,
        the endpoint's clock in ``clock_s``)."""
        capacity_ah = self.params["BATT_CAPACITY"] / 1000.0
        remaining = max(0, min(100, round(100.0 * (1.0 - self._consumed_ah / capacity_ah))))
        entity, state_s = self.state_source(now_s)
        snapshot = read_vehicle(
            self.world,
            entity,
            time_s=state_s,
            velocity=self._velocity,
            voltage_v=self.options.battery_voltage_v,
            remaining_pct=remaining,
            rc_channels=tuple(self.rc.channels),
            gain=self.gain,
            critical=self.failsafe.active,
            servos=self.options.servos,
            clock_s=now_s,
        )
        if math.isnan(snapshot.current_a):  # no thruster currents (a shore gateway)
            snapshot = dataclasses.replace(snapshot, remaining_pct=-1)  # MAVLink: unknown
        self._snapshot = snapshot
        return snapshot

    def snapshot_now(self) -> VehicleSnapshot:
        """The snapshot of the last :meth:`update` (taken now if there was none)."""
        return self._snapshot or self.snapshot(self._last_update_s or 0.0)

    def update(self, now_s: float) -> None:
        """Run the failsafes and queue what is due on every channel at ``now_s`` [s] (after
        the vehicle's frame that applied this frame's intents: its own state holds from here),
        then the STATUSTEXTs said since the last update (:meth:`statustext`)."""
        self.queue_due(now_s)
        self.send_statustexts()

    def queue_due(self, now_s: float) -> None:
        """:meth:`update`'s work before the STATUSTEXTs: the failsafes and what is due."""
        self._arm_acknowledged = None
        snapshot = self.snapshot(now_s)
        known = not math.isnan(snapshot.current_a)
        if known and self._last_update_s is not None and now_s > self._last_update_s:
            self._consumed_ah += snapshot.current_a * (now_s - self._last_update_s) / 3600.0
        self._last_update_s = now_s
        update_attitude_target(self, now_s)
        guided.update_moving_target(self, now_s)
        guided_yaw.update_auto_yaw(self, now_s)
        update_motor_test(self, now_s)
        self.failsafe.check(self, snapshot, now_s)
        if snapshot.critical is not self.failsafe.active:  # it just triggered or cleared
            snapshot = dataclasses.replace(snapshot, critical=self.failsafe.active)
            self._snapshot = snapshot
        heartbeat = None
        for channel in self.channels:  # each link's heartbeat (none on a high-latency one)
            if channel.streams.heartbeat_due(now_s):
                heartbeat = heartbeat or BUILDERS["HEARTBEAT"](snapshot)
                self.queue(channel, heartbeat)
        for channel in self.channels:
            for name in channel.streams.due(now_s):
                self.queue(channel, self.message(name, snapshot))
            param_protocol.send_params(self, channel)

    def message(self, name: str, snapshot: VehicleSnapshot | None = None) -> mav.MAVLink_message:
        """The telemetry message ``name`` (a :data:`~.telemetry.BUILDERS` key,
        ``NAMED_VALUE_FLOAT`` or ``HIGH_LATENCY2``) for ``snapshot`` (default: the last one)."""
        s = snapshot or self._snapshot or self.snapshot(0.0)
        if name == "NAMED_VALUE_FLOAT":
            return mav.MAVLink_named_value_float_message(s.time_boot_ms, b"PilotGain", s.gain)
        if name == "HIGH_LATENCY2":
            return high_latency.high_latency2(self, s)
        return BUILDERS[name](s)

    def counters(self) -> dict[str, object]:
        """Everything counted, for metrics."""
        return {
            "received": dict(sorted(self.received.items())),
            "accepted": self.accepted,
            "rejected": dict(sorted(self.rejected.items())),
            "sent": dict(sorted(self.sent.items())),
            "pilot_inputs": self.pilot_inputs,
            "param_sets": {
                "accepted": self.params.sets_accepted,
                "refused": self.params.sets_refused,
            },
            "failsafes": dict(self.failsafe.triggered),
            "bytes_in": sum(c.wire.bytes_in for c in self.channels),
            "bytes_out": sum(c.wire.bytes_out for c in self.channels),
            "high_latency": {
                "enabled": self.high_latency_enabled,
                "links": sum(c.high_latency for c in self.channels),
                "held": sum(c.held for c in self.channels),
            },
        }
