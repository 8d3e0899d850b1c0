"""Link codecs: how a node's replicated state becomes payloads, one class per codec and side.

A node (:mod:`testbed.run.nodes`) holds one codec and never asks which: it hands the codec the
payloads its modem decoded (:meth:`~VehicleLink.ingest`), sends what the codec gives it after a
frame (:meth:`~VehicleLink.outbound`) or in a MAC slot (:meth:`~OperatorLink.slot`), and, on a
token-passing link, lets the vehicle's codec answer each order (:meth:`~VehicleLink.answer`).
What the codecs return besides payloads (the frames whose state was applied, the command a
frame carries, completed images) is ground truth for the recorder, which the wire itself does
not carry.

- ``teleop``: the narrow-band paper's orders (13–20 B frames) and 60-B replies (state and an
  image chunk), :mod:`testbed.common.teleop`; the vehicle replies only when asked.
- ``changeset``: every owned, changed replicated component (the ECS paper's sync),
  :mod:`testbed.common.changeset`, sent by each node at its own rate, with a full snapshot every
  ``snapshot_period_s`` so a peer that lost a payload resyncs.
- ``mavlink-raw``: the ground station's MAVLink packets themselves, the baseline
  (:mod:`testbed.run.mavlink_links`); ``mavlink-hl`` the same on a MAVLink high-latency link
  (HIGH_LATENCY2 every 5 s).

:data:`VEHICLE_LINKS` and :data:`OPERATOR_LINKS` are the only places that name the codecs; a new
codec (raw MAVLink bytes, say) is one class per side and one entry in each.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from testbed.common.changeset_receiver import ChangeSetReceiver
from testbed.common.changeset_sender import ChangeSetSender
from testbed.common.components import MovementCommand, Odometry, register_components
from testbed.common.teleop import TeleopOperatorEnd, TeleopVehicleEnd
from testbed.ecs import ComponentRegistry, Origin, Side, World
from testbed.operator.station import OperatorStation
from testbed.operator.video import ImageConsole
from testbed.protocol import (
    AssemblyEvent,
    ImageSettings,
    Move,
    OperatorMessage,
    decode_operator_message,
    order_type_of,
)
from testbed.vehicle.vehicle import Vehicle
from testbed.vehicle.video import ImageSource

__all__ = [
    "OPERATOR_LINKS",
    "VEHICLE_LINKS",
    "ChangeSetOperatorLink",
    "ChangeSetOutbox",
    "ChangeSetVehicleLink",
    "CompletedImage",
    "Ingested",
    "OperatorLink",
    "Outgoing",
    "TeleopOperatorLink",
    "TeleopVehicleLink",
    "VehicleLink",
    "make_registry",
]


def make_registry() -> ComponentRegistry:
    """The registry of replicated components both nodes use."""
    registry = ComponentRegistry()
    register_components(registry)
    return registry


@dataclass(frozen=True, slots=True)
class CompletedImage:
    """An image the operator's console completed from a reply.

    Attributes:
        frame_id: the reply frame that completed it.
        pixels: the operator's decoded view (empty if it could not be decoded).
        size_bytes: the coded image's length [B].
    """

    frame_id: int
    pixels: np.ndarray
    size_bytes: int


@dataclass(slots=True)
class Ingested:
    """What applying a batch of payloads did.

    Attributes:
        rejected: payloads the codec refused (garbled past the CRC, or the other side's data).
        frames: frame ids whose payload was applied, in order (for codecs whose payloads carry
            no sample times: the recorder knows them by frame).
        sampled_s: sample times [s] the applied state carries on the wire (the mirrored
            command or odometry), in order.
        commands: ``(seq, sampled_s)`` of the mirrored movement command, if the wire carries it.
        images: images the operator's console completed.
        progress: ``(frame_id, bytes)`` for each reply that grew the image the console is
            assembling: the coded bytes from its start it now holds (the picture it shows).
    """

    rejected: int = 0
    frames: list[int] = field(default_factory=list)
    sampled_s: list[float] = field(default_factory=list)
    commands: list[tuple[int, float]] = field(default_factory=list)
    images: list[CompletedImage] = field(default_factory=list)
    progress: list[tuple[int, int]] = field(default_factory=list)


@dataclass(frozen=True, slots=True)
class Outgoing:
    """A payload for the modem, and the movement command it carries if the wire does not say
    when it was sampled (ground truth for the recorder)."""

    payload: bytes
    command: MovementCommand | None = None


class VehicleLink(Protocol):
    """The vehicle's codec."""

    images: ImageSource | None
    reply_image: int | None

    def ingest(self, payloads: list[tuple[bytes, int]], now_s: float) -> Ingested:
        """Apply the payloads (with their frame ids) that arrived since the last frame."""
        ...

    def outbound(self, now_s: float) -> list[bytes]:
        """The payloads to send after this frame (POST_UPDATE)."""
        ...

    def answer(self, payload: bytes) -> bytes | None:
        """Token passing: the reply to a valid order, or None to stay silent."""
        ...


class OperatorLink(Protocol):
    """The operator's codec."""

    console: ImageConsole | None

    def slot(self, now_s: float) -> list[Outgoing]:
        """The payloads of this send slot (one per IPG, or one per period)."""
        ...

    def ingest(self, payloads: list[tuple[bytes, int]], now_s: float) -> Ingested:
        """Apply the vehicle's payloads that arrived."""
        ...


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


def _apply_changesets(receiver: ChangeSetReceiver, payloads: list[tuple[bytes, int]]) -> int:
    """Apply change-set payloads; the number refused."""
    return receiver.apply_all([p for p, _ in payloads]) if payloads else 0


# ------------------------------------------------------------------------------ vehicle side


class TeleopVehicleLink:
    """The vehicle's teleop codec: orders in, state and an image chunk out, on request.

    Args:
        vehicle: the vehicle whose world the orders write.
        images: the vehicle's image source, or None for replies without images.
    """

    def __init__(self, vehicle: Vehicle, images: ImageSource | None) -> None:
        self.teleop = TeleopVehicleEnd(vehicle.world, vehicle.entity, vehicle.operator_entity)
        self.images = images
        self.reply_image: int | None = None
        """Number of the image the last reply carried a chunk of, or None."""

    def ingest(self, payloads: list[tuple[bytes, int]], now_s: float) -> Ingested:
        result = Ingested()
        for payload, frame_id in payloads:
            if self.teleop.apply_order(payload, now_s):
                result.frames.append(frame_id)
            else:
                result.rejected += 1
        return result

    def outbound(self, now_s: float) -> list[bytes]:
        del now_s
        return []

    def answer(self, payload: bytes) -> bytes | None:
        message = decode_operator_message(payload)
        images = self.images
        chunk = None
        if isinstance(message, OperatorMessage):
            self.teleop.acknowledge(message)
            if images is not None:
                images.on_order(message)
        if images is not None:
            chunk = images.reply_chunk()
        current = None if images is None else images.current
        self.reply_image = current.number if chunk is not None and chunk.data and current else None
        return self.teleop.encode_reply(chunk)


class ChangeSetVehicleLink:
    """The vehicle's change-set codec: mirrors the operator's intents, sends its own state at
    ``downlink_rate_hz``.

    Args:
        vehicle: the vehicle.
        downlink_rate_hz: send rate [Hz] (every ``control_rate / rate`` frames).
        snapshot_period_s: full state this often [s] (0: never).
    """

    images: ImageSource | None = None
    reply_image: int | None = None

    def __init__(
        self, vehicle: Vehicle, *, downlink_rate_hz: float, snapshot_period_s: float
    ) -> None:
        registry = make_registry()
        self._world = vehicle.world
        self.outbox = ChangeSetOutbox(
            ChangeSetSender(vehicle.world, registry, Side.VEHICLE), snapshot_period_s
        )
        self.receiver = ChangeSetReceiver(vehicle.world, registry, Side.VEHICLE)
        self._send_every = max(1, round(vehicle.config.control_rate_hz / downlink_rate_hz))
        self._frame_count = 0

    def ingest(self, payloads: list[tuple[bytes, int]], now_s: float) -> Ingested:
        del now_s
        result = Ingested(rejected=_apply_changesets(self.receiver, payloads))
        for _, command in self._world.query1(MovementCommand, origin=Origin.REMOTE):
            result.commands.append((command.seq, command.sampled_s))
        return result

    def outbound(self, now_s: float) -> list[bytes]:
        self._frame_count += 1
        if self._frame_count % self._send_every:
            return []
        return self.outbox.payloads(now_s)

    def answer(self, payload: bytes) -> bytes | None:
        del payload
        return None


# ----------------------------------------------------------------------------- operator side


class TeleopOperatorLink:
    """The operator's teleop codec: one order per slot (with the console's image request and
    settings), replies applied to the vehicle's mirrored state.

    Args:
        station: the operator's station.
        console: the image console, or None without image feedback.
    """

    def __init__(self, station: OperatorStation, console: ImageConsole | None) -> None:
        self.teleop = TeleopOperatorEnd(station.world, station.entity)
        self.console = console
        self._station = station

    def slot(self, now_s: float) -> list[Outgoing]:
        payload = self._order(now_s)
        moves = order_type_of(payload) is Move
        return [Outgoing(payload, self._station.latest_command() if moves else None)]

    def _order(self, now_s: float) -> bytes:
        """This gap's order: the image request in its header, coder settings when due."""
        console = self.console
        if console is None:
            return self.teleop.encode_order()
        settings = console.settings_due(now_s)
        payload = self.teleop.encode_order(console.request(), settings)
        if settings is not None and order_type_of(payload) is ImageSettings:
            console.settings_sent_with(self.teleop.order_seq_bit)
        else:
            console.order_sent()
        return payload

    def ingest(self, payloads: list[tuple[bytes, int]], now_s: float) -> Ingested:
        result = Ingested()
        console = self.console
        for payload, frame_id in payloads:
            message = self.teleop.apply_reply(payload, now_s)
            if message is None:
                result.rejected += 1
                continue
            result.frames.append(frame_id)
            if console is None:
                continue
            event = console.on_reply(message)
            if event is AssemblyEvent.PROGRESS:
                result.progress.append((frame_id, len(console.assembler.prefix())))
            if event is AssemblyEvent.COMPLETED and console.completed is not None:
                view = console.completed_view
                pixels = view if view is not None else np.zeros((0, 0), np.uint8)
                result.images.append(CompletedImage(frame_id, pixels, len(console.completed)))
                result.progress.append((frame_id, len(console.completed)))
        return result


class ChangeSetOperatorLink:
    """The operator's change-set codec: its intents out each slot, the vehicle's state mirrored.

    Args:
        station: the operator's station.
        snapshot_period_s: full state this often [s] (0: never), so a vehicle that lost a
            payload (an arm request, a setpoint) resyncs.
    """

    console: ImageConsole | None = None

    def __init__(self, station: OperatorStation, *, snapshot_period_s: float) -> None:
        registry = make_registry()
        self._world: World = station.world
        self.outbox = ChangeSetOutbox(
            ChangeSetSender(station.world, registry, Side.OPERATOR), snapshot_period_s
        )
        self.receiver = ChangeSetReceiver(station.world, registry, Side.OPERATOR)

    def slot(self, now_s: float) -> list[Outgoing]:
        return [Outgoing(p) for p in self.outbox.payloads(now_s)]

    def ingest(self, payloads: list[tuple[bytes, int]], now_s: float) -> Ingested:
        del now_s
        result = Ingested(rejected=_apply_changesets(self.receiver, payloads))
        for _, odometry in self._world.query1(Odometry, origin=Origin.REMOTE):
            result.sampled_s.append(odometry.sampled_s)
        return result


def _mavlink_raw_vehicle(vehicle: Vehicle, **_: object) -> VehicleLink:
    from testbed.run.mavlink_links import RawMavlinkVehicleLink  # it imports this module

    return RawMavlinkVehicleLink(vehicle)


def _mavlink_raw_operator(station: OperatorStation, **_: object) -> OperatorLink:
    from testbed.run.mavlink_links import RawMavlinkOperatorLink

    return RawMavlinkOperatorLink(station)


def _mavlink_hl_vehicle(vehicle: Vehicle, **_: object) -> VehicleLink:
    from testbed.run.mavlink_links import HighLatencyVehicleLink

    return HighLatencyVehicleLink(vehicle)


def _mavlink_hl_operator(station: OperatorStation, **_: object) -> OperatorLink:
    from testbed.run.mavlink_links import HighLatencyOperatorLink

    return HighLatencyOperatorLink(station)


VEHICLE_LINKS: dict[str, Callable[..., VehicleLink]] = {
    "teleop": lambda vehicle, *, images, downlink_rate_hz, snapshot_period_s: TeleopVehicleLink(
        vehicle, images
    ),
    "changeset": lambda vehicle, *, images, downlink_rate_hz, snapshot_period_s: (
        ChangeSetVehicleLink(
            vehicle, downlink_rate_hz=downlink_rate_hz, snapshot_period_s=snapshot_period_s
        )
    ),
    "mavlink-raw": _mavlink_raw_vehicle,
    "mavlink-hl": _mavlink_hl_vehicle,
}
"""Vehicle codec by scenario name (``link.codec``)."""

OPERATOR_LINKS: dict[str, Callable[..., OperatorLink]] = {
    "teleop": lambda station, *, console, snapshot_period_s: TeleopOperatorLink(station, console),
    "changeset": lambda station, *, console, snapshot_period_s: ChangeSetOperatorLink(
        station, snapshot_period_s=snapshot_period_s
    ),
    "mavlink-raw": _mavlink_raw_operator,
    "mavlink-hl": _mavlink_hl_operator,
}
"""Operator codec by scenario name (``link.codec``)."""
