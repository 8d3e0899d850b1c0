"""The two nodes of a run as simpy processes, and the link adapters that join them.

Each node owns an ECS world (the vehicle's inside :class:`~testbed.vehicle.vehicle.Vehicle`, the
operator's inside :class:`~testbed.operator.station.OperatorStation`) and a modem on the
simulated medium. Bytes are all that cross: a node hands frames to its modem and feeds what its
modem delivers to its own :class:`~testbed.protocol.FrameDecoder`, exactly as it would with a
serial modem. Frames that decode are queued and applied by the node's link system at the start
of its next frame (PRE_UPDATE); outbound data is encoded after the frame (POST_UPDATE) or, on a
token-passing link, when the token says so.

Two codecs (:mod:`testbed.common`): ``teleop`` (the paper's orders and 12-byte state, token
passing: the operator sends one order per inter-packet gap, the vehicle answers each order at
once) and ``changeset`` (every owned, changed replicated component, sent by each node at its own
rate). The :class:`~testbed.run.recorder.Recorder` is told the ground truth the wire does not
carry (when the sticks in a frame were sampled); the nodes never read it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Generator
from typing import Any, Protocol

import numpy as np
import simpy

from testbed.channel import Delivery, IpgPolicy
from testbed.common.changeset import ApplyStatus, ChangeSetReceiver, ChangeSetSender
from testbed.common.components import MovementCommand, Odometry, register_components
from testbed.common.geometry import attitude_error, euler_from_quat
from testbed.common.teleop import TeleopOperatorEnd, TeleopVehicleEnd
from testbed.ecs import ComponentRegistry, Origin, Phase, Side, World
from testbed.operator.station import OperatorStation
from testbed.operator.video import ImageConsole
from testbed.protocol import (
    AssemblyEvent,
    Frame,
    FrameDecoder,
    ImageSettings,
    OperatorMessage,
    VehicleMessage,
    decode_operator_message,
    encode_frame,
    frame_overhead,
)
from testbed.run.image_log import CapturedImage, ReceivedImage
from testbed.run.recorder import Recorder
from testbed.vehicle.components import ControlTargets, FailsafeStatus
from testbed.vehicle.systems import Actuation, Controllers, PlantTruth, SimClock
from testbed.vehicle.vehicle import Vehicle
from testbed.vehicle.video import CodedImage, ImageSource

__all__ = ["LinkModem", "LinkPort", "OperatorNode", "VehicleNode", "make_registry"]

FRAME_OVERHEAD = frame_overhead()
"""Bytes a frame adds to its payload (preamble, length, CRC)."""

_MOVE_CODE = 1
"""Order type code of a ``Move`` (low nibble of an operator payload's byte 1)."""
_ORDER_CODE_MASK = 0x0F


class LinkModem(Protocol):
    """What a node needs of its modem: the simulated :class:`~testbed.channel.Modem`, or a
    serial modem in hardware-in-the-loop runs (:mod:`testbed.run.realtime`)."""

    on_receive: Callable[[Delivery], None] | None
    last_frame_id: int

    def send(self, data: bytes) -> bool:
        """Queue one frame; False if it was dropped."""
        ...


def make_registry() -> ComponentRegistry:
    """The registry of replicated components both nodes use."""
    registry = ComponentRegistry()
    register_components(registry)
    return registry


class LinkPort:
    """A node's end of the link: its modem, its frame decoder and the payloads awaiting a frame.

    Args:
        modem: the node's modem.
        direction: the direction this port *receives* (``"uplink"`` at the vehicle).
        recorder: ground-truth sink.
        on_frame: called at once with each decoded payload and its delivery, if given (token
            passing answers immediately); payloads are queued for the next frame either way.
    """

    def __init__(
        self,
        modem: LinkModem,
        direction: str,
        recorder: Recorder,
        on_frame: Callable[[bytes, Delivery], None] | None = None,
    ) -> None:
        self.modem = modem
        self.decoder = FrameDecoder()
        self.pending: list[tuple[bytes, int]] = []
        self.payload_bytes = 0
        self._direction = direction
        self._recorder = recorder
        self._on_frame = on_frame
        modem.on_receive = self._receive

    def _receive(self, delivery: Delivery) -> None:
        events = self.decoder.feed(delivery.data)
        if delivery.part == delivery.parts - 1 and self.decoder.pending_bytes:
            # The modem delivered a whole transmission: a candidate still incomplete now had a
            # corrupted length byte, and waiting for its claimed length would hold the good
            # frames behind it for many transmissions. Give it up at the packet boundary.
            events += self.decoder.flush()
        for item in events:
            if isinstance(item, Frame):
                self._recorder.frames_decoded[self._direction] += 1
                self.payload_bytes += len(item.payload)
                self.pending.append((item.payload, delivery.frame_id))
                if self._on_frame is not None:
                    self._on_frame(item.payload, delivery)

    def take(self) -> list[tuple[bytes, int]]:
        """The decoded payloads (with their frame ids) since the last call, in order."""
        pending = self.pending
        self.pending = []
        return pending

    def send(self, payload: bytes) -> int:
        """Frame ``payload`` and hand it to the modem; returns the frame id."""
        self.modem.send(encode_frame(payload))
        return self.modem.last_frame_id

    def rejected(self) -> None:
        """Count a payload the codec refused."""
        self._recorder.frames_rejected[self._direction] += 1


class ChangeSetOutbox:
    """What a node sends on a change-set link: the changes since the last send, or, once per
    ``snapshot_period_s``, its whole owned state so a peer that lost a payload resyncs.

    Args:
        sender: the node's change-set sender.
        snapshot_period_s: time between full snapshots [s]; 0 = never.
    """

    def __init__(self, sender: ChangeSetSender, snapshot_period_s: float) -> None:
        self.sender = sender
        self._period_s = snapshot_period_s
        self._next_snapshot_s = snapshot_period_s if snapshot_period_s > 0.0 else math.inf

    def payloads(self, now_s: float) -> list[bytes]:
        """The payloads to send at time ``now_s`` [s]."""
        changes = self.sender.poll()  # moves the poll mark either way
        if now_s < self._next_snapshot_s:
            return changes
        while self._next_snapshot_s <= now_s:
            self._next_snapshot_s += self._period_s
        return self.sender.snapshot()


class VehicleNode:
    """The vehicle node: the vehicle's frames in simpy time, its link systems and recording.

    Args:
        env: simpy environment.
        vehicle_factory: builds the :class:`Vehicle` given its inbound and outbound systems.
        modem: the vehicle's modem.
        codec: ``"teleop"`` or ``"changeset"``.
        token: True on a token-passing link (answer each order at once).
        downlink_rate_hz: change-set send rate (changeset codec only).
        recorder: ground-truth sink.
        commanded: the pilot's true sticks at a time (recording only).
        sample_rate_hz: rate of the recorded series rows [Hz] (energy is integrated every
            frame regardless).
        snapshot_period_s: change-set codec: send the full owned state this often [s] (0:
            never), so an operator that lost a payload resyncs.
        image_source: builds the vehicle's image source from the vehicle (image feedback on
            token-passing teleop links), or None for replies without images.
    """

    def __init__(
        self,
        env: simpy.Environment,
        vehicle_factory: Callable[..., Vehicle],
        modem: LinkModem,
        *,
        codec: str,
        token: bool,
        downlink_rate_hz: float,
        recorder: Recorder,
        commanded: Callable[[float], tuple[float, float, float, float]],
        sample_rate_hz: float = 50.0,
        snapshot_period_s: float = 0.0,
        image_source: Callable[[Vehicle, Callable[[CodedImage], None]], ImageSource] | None = None,
    ) -> None:
        self.env = env
        self._sample_period_s = 1.0 / sample_rate_hz
        self._next_sample_s = 0.0
        self.recorder = recorder
        self._commanded = commanded
        self._codec = codec
        on_frame = self._answer if (codec == "teleop" and token) else None
        self.port = LinkPort(modem, "uplink", recorder, on_frame)
        self.registry = make_registry()
        outbound = (self._publish, self._record)
        self.vehicle = vehicle_factory(inbound=(self._ingest,), outbound=outbound)
        vehicle = self.vehicle
        self.teleop = TeleopVehicleEnd(vehicle.world, vehicle.entity, vehicle.operator_entity)
        sender = ChangeSetSender(vehicle.world, self.registry, Side.VEHICLE)
        self.outbox = ChangeSetOutbox(sender, snapshot_period_s)
        self.receiver = ChangeSetReceiver(vehicle.world, self.registry, Side.VEHICLE)
        self._send_every = max(1, round(vehicle.config.control_rate_hz / downlink_rate_hz))
        self._frame_count = 0
        self._applied_seq = -1
        self._applied_sampled = -math.inf
        self._reply_sampled: dict[int, float] = {}
        self.reply_odometry_s = self._reply_sampled
        self._energy_j = 0.0
        self._last_failsafe = 0
        self.images = None if image_source is None else image_source(vehicle, self._captured)

    # -- process ---------------------------------------------------------------------------

    def run(self) -> Generator[simpy.Event, Any, None]:
        """simpy process: run each vehicle frame at its own instant, physics in between."""
        env = self.env
        vehicle = self.vehicle
        while True:
            t_frame = vehicle.next_frame_s
            if t_frame > env.now:
                yield env.timeout(t_frame - env.now)
            vehicle.advance(t_frame + 0.5 * vehicle.physics.dt_s)

    # -- link systems ----------------------------------------------------------------------

    def _ingest(self, world: World) -> None:
        """PRE_UPDATE: apply the frames that arrived since the last frame."""
        now = world.resource(SimClock).time_s
        if self._codec == "teleop":
            for payload, frame_id in self.port.take():
                if not self.teleop.apply_order(payload, now):
                    self.port.rejected()
                    continue
                truth = self.recorder.uplink_commands.get(frame_id)
                if truth is not None:
                    self._applied(truth[0], truth[1], now)
            return
        for payload, _ in self.port.take():
            if self.receiver.apply(payload).status is not ApplyStatus.APPLIED:
                self.port.rejected()
        for _, command in world.query1(MovementCommand, origin=Origin.REMOTE):  # the mirror's
            self._applied(command.seq, command.sampled_s, now)

    def _applied(self, seq: int, sampled_s: float, now: float) -> None:
        if seq <= self._applied_seq:
            return
        self._applied_seq = seq
        self.recorder.commands_applied.setdefault(seq, now)
        if sampled_s > self._applied_sampled:
            self._applied_sampled = sampled_s
            self.recorder.command_updates.append((now, sampled_s))

    def _publish(self, world: World) -> None:
        """POST_UPDATE: change-set codec — send what changed, at the downlink rate."""
        if self._codec != "changeset":
            return
        self._frame_count += 1
        if self._frame_count % self._send_every:
            return
        for payload in self.outbox.payloads(world.resource(SimClock).time_s):
            self.port.send(payload)

    def _answer(self, payload: bytes, delivery: Delivery) -> None:
        """Token passing: answer an order at once with the state and an image chunk."""
        del delivery
        message = decode_operator_message(payload)
        images = self.images
        chunk = None
        if isinstance(message, OperatorMessage):
            self.teleop.acknowledge(message)
            if images is not None:
                images.on_order(message)
        if images is not None:
            chunk = images.reply_chunk()
        odometry = self.vehicle.world.get(self.vehicle.entity, Odometry)
        frame_id = self.port.send(self.teleop.encode_reply(chunk))
        self._reply_sampled[frame_id] = -math.inf if odometry is None else odometry.sampled_s
        if chunk is not None and chunk.data and images is not None and images.current:
            self.recorder.images.reply_images[frame_id] = images.current.number

    def _captured(self, image: CodedImage) -> None:
        """Recording: the image source captured and coded a new image (stamped with the event
        clock, like every other record; the scene is the plant at its latest physics step)."""
        now = self.env.now
        record = CapturedImage(image.number, now, image.pixels, len(image.encoded))
        self.recorder.images.captured[image.number] = record

    # -- recording -------------------------------------------------------------------------

    def _record(self, world: World) -> None:
        """POST_UPDATE: integrate energy; at the sample rate, one row of ground truth."""
        clock = world.resource(SimClock)
        vehicle = self.vehicle
        actuation = world.resource(Actuation)
        current = vehicle.t200.total_current_floats(actuation.actual_forces_n)
        self._energy_j += current * vehicle.config.supply_voltage_v * clock.dt_s
        now = clock.time_s
        ctl = world.resource(Controllers)
        status = world.get(ctl.vehicle, FailsafeStatus)
        level = 0 if status is None else int(status.level)
        if level != self._last_failsafe:
            self.recorder.event(now, "vehicle", "failsafe", status.level.name if status else "")
            self._last_failsafe = level
        if now < self._next_sample_s - 1e-9:
            return
        self._next_sample_s += self._sample_period_s
        truth = world.resource(PlantTruth)
        sticks = ctl.sticks
        ref = vehicle.reference_velocity(sticks)
        roll, pitch, yaw = euler_from_quat(truth.quaternion_wxyz)
        nu = vehicle.physics.state_floats()[3]
        targets = world.get(ctl.vehicle, ControlTargets)
        if targets is None or not ctl.flags.armed:
            errors = (math.nan, math.nan, math.nan)
            depth_target = math.nan
        else:
            errors = attitude_error(targets.quaternion_wxyz, truth.quaternion_wxyz)
            depth_target = targets.depth_m if ctl.flags.depth_hold else math.nan
        cmd = self._commanded(now)
        deg = 180.0 / math.pi
        position = truth.position_ned_m
        row: tuple[float, ...] = (now, *cmd, sticks[0], sticks[1], sticks[2], sticks[5], *ref)
        row += position
        row += (roll * deg, pitch * deg, yaw * deg, *nu)
        row += (errors[0] * deg, errors[1] * deg, errors[2] * deg, depth_target, current)
        row += (float(ctl.flags.armed), float(level))
        self.recorder.rows.append(row)

    @property
    def energy_wh(self) -> float:
        """Thruster energy so far [Wh] (T200 current of the plant's actual forces × supply)."""
        return self._energy_j / 3600.0


class OperatorNode:
    """The operator node: the station's frames, its link codec and the token master.

    Args:
        env: simpy environment.
        station: the operator's station (world, pilot, plan).
        modem: the operator's modem.
        codec: ``"teleop"`` or ``"changeset"``.
        ipg: the token master's inter-packet-gap policy, or None for free access.
        uplink_rate_hz: frame and send rate without token passing.
        recorder: ground-truth sink.
        reply_odometry_s: the vehicle node's map of reply frame id → true odometry sample time
            (teleop replies carry no time; recording only).
        snapshot_period_s: change-set codec: send the full owned state this often [s] (0:
            never), so a vehicle that lost a payload (an arm request, a setpoint) resyncs.
        console: the operator's image console (image feedback), or None.
    """

    def __init__(
        self,
        env: simpy.Environment,
        station: OperatorStation,
        modem: LinkModem,
        *,
        codec: str,
        ipg: IpgPolicy | None,
        uplink_rate_hz: float,
        recorder: Recorder,
        reply_odometry_s: dict[int, float],
        snapshot_period_s: float = 0.0,
        console: ImageConsole | None = None,
    ) -> None:
        self.env = env
        self.console = console
        self.station = station
        self.recorder = recorder
        self._codec = codec
        self._ipg = ipg
        self._period_s = 1.0 / uplink_rate_hz
        self._reply_odometry_s = reply_odometry_s
        on_frame = self._on_reply if ipg is not None else None
        self.port = LinkPort(modem, "downlink", recorder, on_frame)
        registry = make_registry()
        self.teleop = TeleopOperatorEnd(station.world, station.entity)
        sender = ChangeSetSender(station.world, registry, Side.OPERATOR)
        self.outbox = ChangeSetOutbox(sender, snapshot_period_s)
        self.receiver = ChangeSetReceiver(station.world, registry, Side.OPERATOR)
        self._held_sampled = -math.inf
        station.add_system(Phase.PRE_UPDATE, self._ingest)

    def run(self) -> Generator[simpy.Event, Any, None]:
        """simpy process: token master (one order per IPG) or periodic frames."""
        env = self.env
        while True:
            self.station.frame(env.now)
            if self._codec == "teleop":
                payloads = [self._order()]
                self._send_order(payloads[0])
            else:
                payloads = self.outbox.payloads(env.now)
                for part in payloads:
                    self.port.send(part)
            if self._ipg is None:
                yield env.timeout(self._period_s)
            else:  # the gap follows the size of the frame just sent (telerobotics rules)
                largest = max((len(p) for p in payloads), default=0)
                yield env.timeout(self._ipg.gap_for(bytes(largest + FRAME_OVERHEAD)))

    def _order(self) -> bytes:
        """This gap's order: the image request in its header, coder settings when due."""
        console = self.console
        if console is None:
            return self.teleop.encode_order()
        settings = console.settings_due(self.env.now)
        payload = self.teleop.encode_order(console.request(), settings)
        if settings is not None and payload[1] & _ORDER_CODE_MASK == ImageSettings.CODE:
            console.settings_sent_with(self.teleop.order_seq_bit)
        else:
            console.order_sent()
        return payload

    def _send_order(self, payload: bytes) -> int:
        frame_id = self.port.send(payload)
        command = self.station.latest_command()
        if payload[1] & 0x0F == _MOVE_CODE and command is not None:
            self.recorder.commands_sampled[command.seq] = command.sampled_s
            self.recorder.uplink_commands[frame_id] = (command.seq, command.sampled_s)
        return frame_id

    def _on_reply(self, payload: bytes, delivery: Delivery) -> None:
        """A reply landed: the console refreshes now (one operator frame)."""
        del payload, delivery
        self.station.frame(self.env.now)

    def _ingest(self, world: World) -> None:
        """PRE_UPDATE: apply the vehicle's frames that arrived."""
        now = self.env.now
        if self._codec == "teleop":
            for payload, frame_id in self.port.take():
                message = self.teleop.apply_reply(payload, now)
                if message is None:
                    self.port.rejected()
                    continue
                self._held(now, self._reply_odometry_s.get(frame_id, -math.inf))
                if self.console is not None:
                    self._image_chunk(self.console, message, frame_id, now)
            return
        for payload, _ in self.port.take():
            if self.receiver.apply(payload).status is not ApplyStatus.APPLIED:
                self.port.rejected()
        for _, odometry in world.query1(Odometry, origin=Origin.REMOTE):
            self._held(now, odometry.sampled_s)

    def _image_chunk(
        self, console: ImageConsole, message: VehicleMessage, frame_id: int, now: float
    ) -> None:
        """A reply's image fields into the console; a completed image into the record."""
        log = self.recorder.images
        event = console.on_reply(message)
        if event is AssemblyEvent.COMPLETED and console.completed is not None:
            number = log.reply_images.get(frame_id, -1)
            view = console.completed_view
            pixels = view if view is not None else np.zeros((0, 0), np.uint8)
            log.received.append(ReceivedImage(number, now, pixels, len(console.completed)))

    def _held(self, now: float, sampled_s: float) -> None:
        if sampled_s > self._held_sampled:
            self._held_sampled = sampled_s
            self.recorder.odometry_updates.append((now, sampled_s))
