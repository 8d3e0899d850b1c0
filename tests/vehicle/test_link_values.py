"""Setpoints a change-set peer sends that no operator could mean (NaN, infinite, beyond the
world) are values: the vehicle counts them in ``ignored_setpoints`` and keeps its targets.

A bit flip that survives a frame's CRC-16 on a change-set link reaches the vehicle as a
well-formed payload (the teleop, live and MAVLink paths range-check their own encodings); a
security review's payloads dived without limit (``DepthSetpoint(inf)``), climbed the wrong way
(``1e300``) and made the attitude target NaN.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator

import numpy as np
import pytest

from testbed.common.changeset import ChangeSetCodec
from testbed.common.changeset_receiver import ApplyStatus, ChangeSetReceiver
from testbed.common.components import (
    ArmRequest,
    AttitudeSetpoint,
    ControlMode,
    ControlTargets,
    DepthSetpoint,
    ModeRequest,
    MovementCommand,
)
from testbed.ecs import Change, ChangeKind, Side
from testbed.run.links import make_registry
from testbed.vehicle.command_systems import MAX_SETPOINT_DEPTH_M
from testbed.vehicle.resources import Controllers
from testbed.vehicle.vehicle import Vehicle
from testbed.vehicle.vehicle_config import VehicleConfig

REGISTRY = make_registry()
CODEC = ChangeSetCodec(REGISTRY)
TYPE_IDS = {entry.cls: entry.type_id for entry in REGISTRY}


def payload(sequence: int, *values: object) -> bytes:
    """An operator's change set writing ``values`` on its entity 7 (the codec's own encoding)."""
    changes = [Change(7, ChangeKind.CHANGED, type(v), TYPE_IDS[type(v)], v, 0) for v in values]
    (encoded,) = CODEC.encode(changes, Side.OPERATOR, sequence)
    return encoded


@contextlib.contextmanager
def holding_depth() -> Iterator[tuple[Vehicle, ChangeSetReceiver]]:
    """A vehicle armed in depth hold through its change-set receiver, 1 s in."""
    vehicle = Vehicle(VehicleConfig(), np.random.default_rng(1))
    try:
        receiver = ChangeSetReceiver(vehicle.world, REGISTRY, Side.VEHICLE)
        start = (ArmRequest(True, 1), ModeRequest(ControlMode.DEPTH_HOLD))
        receiver.apply(payload(0, *start, MovementCommand(1, 0.0, (0.0,) * 6)))
        vehicle.advance(1.0)
        yield vehicle, receiver
    finally:
        vehicle.close()


@pytest.mark.parametrize(
    "setpoint",
    [
        DepthSetpoint(math.inf),
        DepthSetpoint(math.nan),
        DepthSetpoint(1e300),
        DepthSetpoint(-1.0),
        AttitudeSetpoint((math.nan, 0.0, 0.0, 0.0)),
        AttitudeSetpoint((1.0, math.inf, 0.0, 0.0)),
    ],
    ids=["depth-inf", "depth-nan", "depth-1e300", "depth-above", "att-nan", "att-inf"],
)
def test_a_setpoint_no_operator_could_mean_is_counted_and_changes_nothing(
    setpoint: object,
) -> None:
    with holding_depth() as (vehicle, receiver):
        before = vehicle.world.get(vehicle.entity, ControlTargets)
        result = receiver.apply(payload(1, setpoint))
        assert result.status is ApplyStatus.APPLIED  # well-formed: the codec takes it
        vehicle.advance(1.9)  # within the 1-s hold timeout: no failsafe re-measures the targets
        after = vehicle.world.get(vehicle.entity, ControlTargets)
        assert vehicle.world.resource(Controllers).ignored_setpoints == 1
        assert before is not None and after == before
        depth = vehicle.state().position_ned[2]
        assert abs(depth - vehicle.config.start_position_ned_m[2]) < 0.1  # held where it was


def test_the_deepest_setpoint_taken_is_the_worlds_extent() -> None:
    """The bound itself is a depth the vehicle takes (its target moves there)."""
    with holding_depth() as (vehicle, receiver):
        receiver.apply(payload(1, DepthSetpoint(MAX_SETPOINT_DEPTH_M)))
        vehicle.advance(1.1)
        targets = vehicle.world.get(vehicle.entity, ControlTargets)
        assert targets is not None and targets.depth_m == MAX_SETPOINT_DEPTH_M
        assert vehicle.world.resource(Controllers).ignored_setpoints == 0


def test_a_sequence_number_pushed_far_ahead_locks_the_pilot_out_for_one_hold_timeout() -> None:
    """A command whose sequence number a corrupted payload set to 2**63 − 1: later commands
    (seq 3, 4, …) are older by number, so the vehicle ignores them and holds; once no command
    has been accepted for the hold timeout (1 s), the next one is taken whatever its number
    (it used to lock the pilot out for good)."""
    from testbed.common.components import CommandStatus

    with holding_depth() as (vehicle, receiver):
        receiver.apply(payload(1, MovementCommand(2**63 - 1, 1.0, (0.0,) * 6)))
        vehicle.advance(1.1)
        taken = []
        for k in range(20):  # the operator's own commands at 10 Hz: surge stick 0.5
            receiver.apply(
                payload(2 + k, MovementCommand(3 + k, 1.1 + 0.1 * k, (0.5,) + (0.0,) * 5))
            )
            vehicle.advance(1.2 + 0.1 * k)
            status = vehicle.world.get(vehicle.entity, CommandStatus)
            assert status is not None
            taken.append(status.seq)
        assert taken[0] == 2**63 - 1  # at first ignored: older by number
        first = next(k for k, seq in enumerate(taken) if seq != 2**63 - 1)
        assert 0.9 <= 0.1 * first + 0.1 <= 1.2  # taken one hold timeout after the last accepted
        assert taken[-1] == 3 + 19  # and every one after it
