"""Link codecs (testbed.run.links): one class per codec and side, joined only by payload bytes.

The truths: the operator's intents come out of the vehicle's mirror (teleop: the Move order's
sticks on the wire's 1/127 grid, by hand; change-set: the exact command with its sequence and
sample time), garbled payloads are counted and change nothing, and the change-set vehicle sends
at its downlink rate (every control_rate/downlink_rate frames).
"""

from __future__ import annotations

import typing
from collections.abc import Iterator

import numpy as np
import pytest

from testbed.common.components import MovementCommand, Odometry
from testbed.ecs import Origin
from testbed.operator.pilots import PilotSample, ScriptedPilot, SineTerm
from testbed.operator.station import OperatorStation, SessionPlan
from testbed.protocol import (
    ImageSettings,
    Move,
    NoOrder,
    OperatorMessage,
    VehicleMessage,
    decode_vehicle_message,
    order_type_of,
)
from testbed.run.links import (
    OPERATOR_LINKS,
    VEHICLE_LINKS,
    ChangeSetOperatorLink,
    ChangeSetVehicleLink,
    TeleopOperatorLink,
    TeleopVehicleLink,
)
from testbed.run.sections import LinkSection
from testbed.vehicle.vehicle import Vehicle
from testbed.vehicle.vehicle_config import VehicleConfig


@pytest.fixture
def vehicle() -> Iterator[Vehicle]:
    with Vehicle(VehicleConfig(), np.random.default_rng(0)) as v:
        yield v


def station() -> OperatorStation:
    """A station whose pilot holds surge 0.6 and yaw −0.3 from t = 0 (a period of 1e6 s)."""
    pilot = ScriptedPilot(
        0.0, x=(SineTerm(0.6, 1e6, np.pi / 2),), yaw=(SineTerm(-0.3, 1e6, np.pi / 2),)
    )
    return OperatorStation(pilot, SessionPlan(arm_at_s=100.0))


def test_every_codec_a_scenario_accepts_has_both_ends() -> None:
    codecs = set(typing.get_args(typing.get_type_hints(LinkSection)["codec"]))
    assert (
        set(VEHICLE_LINKS)
        == set(OPERATOR_LINKS)
        == codecs
        == {"teleop", "changeset", "mavlink-raw", "mavlink-hl"}
    )


def test_teleop_order_reaches_the_vehicle_mirror(vehicle: Vehicle) -> None:
    op = station()
    link = TeleopOperatorLink(op, console=None)
    op.frame(0.25)
    (out,) = link.slot(0.25)
    assert order_type_of(out.payload) is Move
    assert out.command == op.latest_command()  # ground truth of the sticks this frame carries
    rov = TeleopVehicleLink(vehicle, images=None)
    result = rov.ingest([(out.payload, 7), (b"\x00", 8)], 0.3)
    assert (result.frames, result.rejected) == ([7], 1)
    command = vehicle.world.get(vehicle.operator_entity, MovementCommand)
    assert command is not None
    # Move carries each axis as an int8, ±127 = full stick (REFERENCE §1.3):
    # 0.6 → round(76.2) = 76, −0.3 → round(−38.1) = −38
    assert command.sticks == pytest.approx((76 / 127, 0.0, 0.0, 0.0, 0.0, -38 / 127))


def test_teleop_answer_is_a_reply_the_operator_applies(vehicle: Vehicle) -> None:
    order = OperatorMessage(False, False, 0, True, False, NoOrder()).encode()
    rov = TeleopVehicleLink(vehicle, images=None)
    reply = rov.answer(order)
    assert reply is not None and isinstance(decode_vehicle_message(reply), VehicleMessage)
    assert rov.reply_image is None  # no image source, no chunk
    op = station()
    link = TeleopOperatorLink(op, console=None)
    result = link.ingest([(reply, 3), (b"garbage", 4)], 1.0)
    assert (result.frames, result.rejected) == ([3], 1)
    assert any(True for _ in op.world.query1(Odometry))


def test_teleop_slot_without_move_carries_no_command() -> None:
    op = station()
    link = TeleopOperatorLink(op, console=None)
    op.frame(0.0)

    class Console:  # the console asks for new coder settings this gap
        completed = None

        def settings_due(self, now_s: float) -> ImageSettings:
            return ImageSettings(0, 0, 0, 0, 0, True, 600)

        def request(self) -> tuple[bool, bool, int]:
            return (False, False, 0)

        def settings_sent_with(self, seq_bit: bool) -> None:
            self.sent = seq_bit

    link.console = Console()  # type: ignore[assignment]  # duck-typed stand-in
    (out,) = link.slot(0.0)
    assert order_type_of(out.payload) is ImageSettings and out.command is None


def test_changeset_carries_the_exact_command_and_sends_at_the_downlink_rate(
    vehicle: Vehicle,
) -> None:
    op = station()
    link = ChangeSetOperatorLink(op, snapshot_period_s=0.0)
    op.frame(0.5)
    payloads = [(o.payload, k) for k, o in enumerate(link.slot(0.5))]
    assert payloads and all(o.command is None for o in link.slot(0.5))  # nothing new to send
    rate_hz = vehicle.config.control_rate_hz / 4.0
    rov = ChangeSetVehicleLink(vehicle, downlink_rate_hz=rate_hz, snapshot_period_s=0.0)
    result = rov.ingest([*payloads, (b"\xff\x00", 99)], 0.6)
    sent = op.latest_command()
    assert sent is not None and result.commands == [(sent.seq, sent.sampled_s)]
    assert result.rejected == 1
    mirrored = [c for _, c in vehicle.world.query1(MovementCommand, origin=Origin.REMOTE)]
    assert mirrored == [sent]
    sends = []
    for k in range(1, 13):  # a vehicle-owned change every frame; sent every 4th
        vehicle.world.set(vehicle.entity, Odometry(0.01 * k, (0.0, 0.0, 0.1 * k), (1.0, 0, 0, 0)))
        sends.append(bool(rov.outbound(0.01 * k)))
    assert [k for k, s in enumerate(sends, start=1) if s] == [4, 8, 12]


def test_a_new_pilot_is_one_object_with_sample() -> None:
    class Hold:
        def sample(self, t_s: float) -> PilotSample:
            return PilotSample((0.1, 0.2, 0.3, 0.0, 0.0, 0.4))

    op = OperatorStation(Hold(), SessionPlan(arm_at_s=100.0))
    op.frame(1.0)
    command = op.latest_command()
    assert command is not None and command.sticks == (0.1, 0.2, 0.3, 0.0, 0.0, 0.4)
