"""The two nodes of a run as simpy processes, over a modem and through one link codec.

Each node owns an ECS world (the vehicle's inside :class:`~testbed.vehicle.vehicle.Vehicle`, the
operator's inside :class:`~testbed.operator.station.OperatorStation`) and a modem: the
simulated medium's, or a serial modem in real-time runs (:mod:`testbed.run.hil_modem`). Bytes
are all that cross: a node hands frames to its modem and feeds what its modem delivers to its
own :class:`~testbed.protocol.FrameDecoder`, exactly as it would with a serial modem. Frames
that decode are queued and applied by the node's link system at the start of its next frame
(PRE_UPDATE); outbound data is encoded after the frame (POST_UPDATE) or in a MAC slot.

A node holds one link codec (:mod:`testbed.run.links`) and never asks which. Medium access is
:mod:`testbed.channel.mac`'s: the operator sends in a token master's slots (one per
inter-packet gap) or periodically; on a token-passing link the vehicle answers each order at
once through a :class:`~testbed.channel.mac.TokenSlave`.

The :class:`~testbed.run.recorder.Recorder` is told the ground truth the wire does not carry
(when the sticks in a frame were sampled, which reply carried which state); the nodes never
read it. The vehicle's series are recorded by an observer system the runner adds
(:class:`~testbed.run.observer.VehicleObserver`), not by the node.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Generator
from typing import Any, Protocol

import simpy

from testbed.channel import Delivery, IpgPolicy, decode_delivery
from testbed.channel.mac import TokenSlave, run_periodic_sender, run_token_master
from testbed.common.components import Odometry
from testbed.ecs import Phase, World
from testbed.operator.station import OperatorStation
from testbed.operator.video import ImageConsole
from testbed.protocol import Frame, FrameDecoder, encode_frame, frame_overhead
from testbed.run.image_record import CapturedImage, ReceivedImage
from testbed.run.links import OPERATOR_LINKS, VEHICLE_LINKS, Ingested, Outgoing
from testbed.run.recorder import Recorder
from testbed.vehicle.resources import SimClock
from testbed.vehicle.vehicle import Vehicle
from testbed.vehicle.video import CodedImage, ImageSource

__all__ = ["FRAME_OVERHEAD", "LinkModem", "LinkPort", "OperatorNode", "VehicleNode"]

FRAME_OVERHEAD = frame_overhead()
"""Bytes a frame adds to its payload (preamble, length, CRC)."""


class LinkModem(Protocol):
    """What a node needs of its modem: the simulated :class:`~testbed.channel.Modem`, or a
    serial modem in real-time runs (:class:`~testbed.run.hil_modem.HilModem`)."""

    on_receive: Callable[[Delivery], None] | None
    last_frame_id: int

    def send(self, data: bytes) -> bool:
        """Queue one frame; False if it was dropped."""
        ...


class LinkPort:
    """A node's end of the link: its modem, its frame decoder and the payloads awaiting a frame.

    Args:
        modem: the node's modem.
        direction: the direction this port *receives* (``"uplink"`` at the vehicle).
        recorder: ground-truth sink.
        on_frame: called at once with each decoded payload, if given (token passing answers
            immediately); payloads are queued for the next frame either way.
    """

    def __init__(
        self,
        modem: LinkModem,
        direction: str,
        recorder: Recorder,
        on_frame: Callable[[bytes], None] | None = None,
    ) -> None:
        self.modem = modem
        self.decoder = FrameDecoder()
        self.pending: list[tuple[bytes, int]] = []
        self.payload_bytes = 0
        self._direction = direction
        self._sends = "downlink" if direction == "uplink" else "uplink"
        self._recorder = recorder
        self._on_frame = on_frame
        modem.on_receive = self._receive

    def _receive(self, delivery: Delivery) -> None:
        for item in decode_delivery(self.decoder, delivery):
            if isinstance(item, Frame):
                self._recorder.frames_decoded[self._direction] += 1
                self.payload_bytes += len(item.payload)
                self.pending.append((item.payload, delivery.frame_id))
                if self._on_frame is not None:
                    self._on_frame(item.payload)

    def take(self) -> list[tuple[bytes, int]]:
        """The decoded payloads (with their frame ids) since the last call, in order."""
        pending = self.pending
        self.pending = []
        return pending

    def send(self, payload: bytes) -> int:
        """Frame ``payload`` and hand it to the modem; returns the frame id."""
        frame = encode_frame(payload)
        self._recorder.frame_bytes_sent[self._sends] += len(frame)
        self.modem.send(frame)
        return self.modem.last_frame_id

    def rejected(self, count: int = 1) -> None:
        """Count payloads the codec refused."""
        self._recorder.frames_rejected[self._direction] += count


class VehicleNode:
    """The vehicle node: the vehicle's frames in simpy time and its link systems.

    Args:
        env: simpy environment.
        vehicle_factory: builds the :class:`Vehicle` given its inbound and outbound systems.
        modem: the vehicle's modem.
        codec: the link codec's name (``link.codec``: a key of
            :data:`~testbed.run.links.VEHICLE_LINKS`).
        token: True on a token-passing link (answer each order at once).
        downlink_rate_hz: send rate of codecs that send on their own (change-set).
        recorder: ground-truth sink.
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
        snapshot_period_s: float = 0.0,
        image_source: Callable[[Vehicle, Callable[[CodedImage], None]], ImageSource] | None = None,
    ) -> None:
        self.env = env
        self.recorder = recorder
        slave = TokenSlave(self._reply, self._send_reply) if token else None
        self.port = LinkPort(modem, "uplink", recorder, None if slave is None else slave.on_frame)
        self.vehicle = vehicle_factory(inbound=(self._ingest,), outbound=(self._publish,))
        vehicle = self.vehicle
        self.images = None if image_source is None else image_source(vehicle, self._captured)
        self.link = VEHICLE_LINKS[codec](
            vehicle,
            images=self.images,
            downlink_rate_hz=downlink_rate_hz,
            snapshot_period_s=snapshot_period_s,
        )
        self._applied_seq = -1
        self._applied_sampled = -math.inf
        self._reply_sampled: dict[int, float] = {}
        self.reply_odometry_s = self._reply_sampled

    def run(self) -> Generator[simpy.Event, Any, None]:
        """simpy process: run each vehicle frame at its own instant, physics in between."""
        env = self.env
        vehicle = self.vehicle
        while True:
            t_frame = vehicle.next_frame_s
            if t_frame > env.now:
                yield env.timeout(t_frame - env.now)
            vehicle.advance(t_frame + 0.5 * vehicle.physics.dt_s)

    def _ingest(self, world: World) -> None:
        """PRE_UPDATE: apply the frames that arrived since the last frame."""
        now = world.resource(SimClock).time_s
        result = self.link.ingest(self.port.take(), now)
        self.port.rejected(result.rejected)
        for frame_id in result.frames:
            truth = self.recorder.uplink_commands.get(frame_id)
            if truth is not None:
                self._applied(truth[0], truth[1], now)
        for seq, sampled_s in result.commands:
            self._applied(seq, sampled_s, now)

    def _applied(self, seq: int, sampled_s: float, now: float) -> None:
        if seq <= self._applied_seq:
            return
        self._applied_seq = seq
        self.recorder.commands_applied.setdefault(seq, now)
        if sampled_s > self._applied_sampled:
            self._applied_sampled = sampled_s
            self.recorder.command_updates.append((now, sampled_s))

    def _publish(self, world: World) -> None:
        """POST_UPDATE: send what the codec has for this frame."""
        for payload in self.link.outbound(world.resource(SimClock).time_s):
            self.port.send(payload)

    def _reply(self, payload: bytes) -> bytes | None:
        """Token passing: the codec's answer to an order."""
        return self.link.answer(payload)

    def _send_reply(self, payload: bytes) -> None:
        """Send an answer; record the state sample and image it carries (ground truth)."""
        odometry = self.vehicle.world.get(self.vehicle.entity, Odometry)
        frame_id = self.port.send(payload)
        self._reply_sampled[frame_id] = -math.inf if odometry is None else odometry.sampled_s
        if self.link.reply_image is not None:
            self.recorder.images.reply_images[frame_id] = self.link.reply_image

    def _captured(self, image: CodedImage) -> None:
        """Recording: the image source captured and coded a new image (stamped with the event
        clock, like every other record; the scene is the plant at its latest physics step)."""
        record = CapturedImage(
            image.number,
            self.env.now,
            image.pixels,
            len(image.encoded),
            image.settings,
            bytes(image.encoded),
        )
        self.recorder.images.captured[image.number] = record
        self.recorder.event(self.env.now, "vehicle", "image_captured", str(image.number))

    @property
    def energy_wh(self) -> float:
        """Thruster energy so far [Wh] (the vehicle's power meter)."""
        return self.vehicle.power.energy_j / 3600.0


class OperatorNode:
    """The operator node: the station's frames, its link codec and its medium access.

    Args:
        env: simpy environment.
        station: the operator's station (world, pilot, plan).
        modem: the operator's modem.
        codec: the link codec's name (a key of :data:`~testbed.run.links.OPERATOR_LINKS`).
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
        self.station = station
        self.recorder = recorder
        self._ipg = ipg
        self._period_s = 1.0 / uplink_rate_hz
        self._reply_odometry_s = reply_odometry_s
        on_frame = self._on_reply if ipg is not None else None
        self.port = LinkPort(modem, "downlink", recorder, on_frame)
        self.link = OPERATOR_LINKS[codec](
            station, console=console, snapshot_period_s=snapshot_period_s
        )
        self.console = self.link.console
        self._held_sampled = -math.inf
        station.add_system(Phase.PRE_UPDATE, self._ingest)

    def run(self) -> Generator[simpy.Event, Any, None]:
        """simpy process: the token master's slots (one per IPG) or periodic sends."""
        if self._ipg is None:
            return run_periodic_sender(self.env, self._slot, self._period_s)
        return run_token_master(self.env, self._slot, self._ipg)

    def _slot(self) -> int:
        """One send slot: a station frame, then the codec's payloads; the largest frame [B]
        (the telerobotics gap rules size the next gap on it)."""
        now = self.env.now
        self.station.frame(now)
        largest = 0
        for outgoing in self.link.slot(now):
            self._send(outgoing)
            largest = max(largest, len(outgoing.payload))
        return largest + FRAME_OVERHEAD

    def _send(self, outgoing: Outgoing) -> None:
        frame_id = self.port.send(outgoing.payload)
        command = outgoing.command
        if command is not None:
            self.recorder.commands_sampled[command.seq] = command.sampled_s
            self.recorder.uplink_commands[frame_id] = (command.seq, command.sampled_s)

    def _on_reply(self, payload: bytes) -> None:
        """A reply landed: the console refreshes now (one operator frame)."""
        del payload
        self.station.frame(self.env.now)

    def _ingest(self, world: World) -> None:
        """PRE_UPDATE: apply the vehicle's frames that arrived."""
        del world
        now = self.env.now
        result: Ingested = self.link.ingest(self.port.take(), now)
        self.port.rejected(result.rejected)
        for frame_id in result.frames:
            self._held(now, self._reply_odometry_s.get(frame_id, -math.inf))
        for sampled_s in result.sampled_s:
            self._held(now, sampled_s)
        log = self.recorder.images
        for frame_id, size in result.progress:
            log.progress.append((now, log.reply_images.get(frame_id, -1), size))
        for image in result.images:
            number = log.reply_images.get(image.frame_id, -1)
            log.received.append(ReceivedImage(number, now, image.pixels, image.size_bytes))
            self.recorder.event(now, "operator", "image_completed", str(number))

    def _held(self, now: float, sampled_s: float) -> None:
        if sampled_s > self._held_sampled:
            self._held_sampled = sampled_s
            self.recorder.odometry_updates.append((now, sampled_s))
