"""The component types, registry and checks shared by the change-set tests.

Two operator-owned types (ids 1, 2), four vehicle-owned ones (ids 10–13) covering every field
kind the field codec writes, and one never registered; :func:`assert_mirrored` compares a
receiver's mirrors with the sender's world directly, not through the codec.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Any

from testbed.common.changeset_receiver import ApplyStatus, ChangeSetReceiver
from testbed.ecs import ComponentRegistry, Entity, Replicate, Side, World

VEHICLE, OPERATOR = Side.VEHICLE, Side.OPERATOR


class Level(enum.IntEnum):
    NOMINAL = 0
    HOLD = 1
    SURFACE = 2


class Mode(enum.Enum):
    MANUAL = "manual"
    HOLD = "depth-hold"


@dataclass(frozen=True, slots=True)
class Inner:
    ok: bool
    count: int


# operator-owned
@dataclass(frozen=True, slots=True)
class Sticks:
    seq: int
    axes: tuple[float, ...]


@dataclass(frozen=True, slots=True)
class ModeRequest:
    mode: Mode
    precision: bool


# vehicle-owned
@dataclass(frozen=True, slots=True)
class Pose:
    position: tuple[float, float, float]
    heading: float


@dataclass(frozen=True, slots=True)
class Status:
    armed: bool
    level: Level
    inner: Inner


@dataclass(frozen=True, slots=True)
class Note:
    text: str
    data: bytes
    tags: tuple[Mode, ...]


@dataclass(frozen=True, slots=True)
class Forces:
    forces_n: tuple[float, ...]


# never registered
@dataclass(frozen=True, slots=True)
class Local:
    x: float


OPERATOR_TYPES = (Sticks, ModeRequest)
VEHICLE_TYPES = (Pose, Status, Note, Forces)


def make_registry() -> ComponentRegistry:
    registry = ComponentRegistry()
    for type_id, cls in enumerate(OPERATOR_TYPES, start=1):
        registry.register(cls, type_id, OPERATOR)
    for type_id, cls in enumerate(VEHICLE_TYPES, start=10):
        registry.register(cls, type_id, VEHICLE)
    return registry


def replicated_state(
    world: World, registry: ComponentRegistry, owner: Side
) -> dict[Entity, dict[type[Any], object]]:
    """Registered components of ``owner`` on each Replicate entity (entities with none left out)."""
    state: dict[Entity, dict[type[Any], object]] = {}
    for entity, _ in world.query(Replicate):
        comps = {
            type(c): c
            for c in world.components(entity)
            if registry.is_registered(type(c)) and registry.owner_of(type(c)) is owner
        }
        if comps:
            state[entity] = comps
    return state


def assert_mirrored(
    sender_world: World,
    receiver: ChangeSetReceiver,
    receiver_world: World,
    registry: ComponentRegistry,
    owner: Side,
) -> None:
    """The receiver's mirrors hold exactly the sender's replicated components of ``owner``."""
    mirrors = receiver.mirrors()
    sent = replicated_state(sender_world, registry, owner)
    mirrored = {
        remote: comps
        for remote, comps in (
            (remote, replicated_state(receiver_world, registry, owner).get(local, {}))
            for remote, local in mirrors.items()
        )
        if comps
    }
    assert mirrored == sent
    alive_replicated = {e for e, _ in sender_world.query(Replicate)}
    assert set(mirrors) <= alive_replicated  # every sender despawn reached the receiver


def deliver(payloads: list[bytes], receiver: ChangeSetReceiver) -> None:
    for payload in payloads:
        result = receiver.apply(payload)
        assert result.status is ApplyStatus.APPLIED, result.reason
