"""Bad MAVLink never raises and is counted: random bytes, truncated and CRC-bad packets, unknown
ids, out-of-range fields, floods; fed whole, byte by byte and in random chunks."""

from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.common.components import ActiveMode, Armed, ControlMode, MovementCommand
from testbed.ecs import World
from testbed.mavlink import OUTBOX_LIMIT, EndpointOptions, MavlinkWire, VehicleEndpoint


class _Null:
    def write(self, data: bytes) -> None:
        del data


GCS = mav.MAVLink(_Null(), srcSystem=255, srcComponent=190)


def endpoint() -> VehicleEndpoint:
    """An endpoint on a bare world (no vehicle behind it: decoding and counting only)."""
    world = World()
    vehicle = world.spawn(Armed(False), ActiveMode(ControlMode.MANUAL))
    intents = world.spawn()
    return VehicleEndpoint(world, vehicle, intents, EndpointOptions())


def packet(message: mav.MAVLink_message) -> bytes:
    return bytes(message.pack(GCS))


HEARTBEAT = packet(GCS.heartbeat_encode(6, 8, 0, 0, 4))
STICKS = packet(GCS.manual_control_encode(1, 300, 0, 500, 0, 0))


def test_wire_classifies_bad_packets() -> None:
    wire = MavlinkWire()
    bad_crc = bytearray(STICKS)
    bad_crc[-1] ^= 0xFF
    assert wire.decode(bytes(bad_crc)).bad["crc"] == 1
    unknown = bytearray(HEARTBEAT)
    unknown[7:10] = (0x39, 0x30, 0x00)  # message id 12345: not in the dialect
    assert wire.decode(bytes(unknown)).bad["unknown_id"] == 1
    assert wire.decode(STICKS[:10]).messages == []  # truncated: waits for the rest
    assert [m.get_type() for m in wire.decode(STICKS[10:]).messages] == ["MANUAL_CONTROL"]
    assert wire.decode(b"\x00" * 70000).bad["oversize"] == 1


@settings(max_examples=60, deadline=None)
@given(st.binary(max_size=600), st.integers(0, 600), st.data())
def test_random_bytes_never_raise_and_a_good_packet_still_decodes_after(
    garbage: bytes, cut: int, data: st.DataObject
) -> None:
    ep = endpoint()
    channel = ep.open_channel("fuzz")
    stream = garbage + STICKS[: cut % len(STICKS)] + garbage[::-1]
    mode = data.draw(st.sampled_from(["whole", "bytes", "chunks"]))
    if mode == "whole":
        pieces = [stream]
    elif mode == "bytes":
        pieces = [stream[i : i + 1] for i in range(len(stream))]
    else:
        sizes = data.draw(st.lists(st.integers(1, 64), min_size=1, max_size=20))
        pieces, at = [], 0
        while at < len(stream):
            size = sizes[len(pieces) % len(sizes)]
            pieces.append(stream[at : at + size])
            at += size
    for piece in pieces:
        ep.receive(channel, piece, 0.0)
    ep.update(0.0)
    # after the garbage, well-formed packets get through (a stray start byte's fake header
    # swallows up to one longest packet, 280 bytes, before the parser resynchronises)
    for _ in range(15):
        ep.receive(channel, HEARTBEAT * 2, 0.0)
    assert ep.received["HEARTBEAT"] >= 1


def test_out_of_range_fields_are_clamped_or_refused_and_counted() -> None:
    ep = endpoint()
    channel = ep.open_channel("range")
    ep.receive(channel, packet(GCS.manual_control_encode(1, 5000, -32000, 4000, 999, 0)), 0.0)
    command = ep.world.get(ep.intents, MovementCommand)
    # as ArduSub's joystick.cpp: the axis scaled (gain 0.5: 0.2 µs a unit), the pulse
    # constrained to 1100..1900: x 5000 → 1900 µs, full stick (a clamp of the axis first gave
    # 1700 µs, half; a MAVLink user's review)
    assert command is not None and command.sticks[0] == 1.0
    assert command.sticks[1] == -1.0 and command.sticks[2] == -1.0  # y −32000; z 4000: up
    assert ep.rejected["clamped_axis"] == 3  # x, y, z; r is in range
    nan = math.nan
    ep.receive(channel, packet(GCS.command_long_encode(1, 1, 400, 0, nan, 0, 0, 0, 0, 0, 0)), 0.0)
    ep.receive(channel, packet(GCS.command_long_encode(1, 1, 176, 0, 1, nan, 0, 0, 0, 0, 0)), 0.0)
    ep.receive(channel, packet(GCS.command_long_encode(1, 1, 512, 0, -5, 0, 0, 0, 0, 0, 0)), 0.0)
    ep.receive(channel, packet(GCS.param_set_encode(1, 1, b"FS_GCS_ENABLE", nan, 9)), 0.0)
    ep.receive(channel, packet(GCS.param_set_encode(1, 1, b"FS_GCS_ENABLE", 99, 9)), 0.0)
    ep.receive(channel, packet(GCS.command_long_encode(1, 1, 31337, 0, 0, 0, 0, 0, 0, 0, 0)), 0.0)
    ep.receive(channel, packet(GCS.request_data_stream_encode(1, 1, 99, 10, 1)), 0.0)
    ep.receive(channel, packet(GCS.param_request_read_encode(1, 1, b"NOPE", -1)), 0.0)
    ep.receive(channel, packet(GCS.param_request_read_encode(1, 1, b"", 30000)), 0.0)
    decoder = mav.MAVLink(None)
    replies = [m for p in channel.take() for m in decoder.parse_buffer(p) or []]
    results = [(m.command, m.result) for m in replies if m.get_type() == "COMMAND_ACK"]
    assert results == [
        (400, mav.MAV_RESULT_UNSUPPORTED),
        (176, mav.MAV_RESULT_FAILED),
        (512, mav.MAV_RESULT_DENIED),
        (31337, mav.MAV_RESULT_UNSUPPORTED),
    ]
    assert ep.params["FS_GCS_ENABLE"] == 2
    assert ep.rejected["param_refused"] == 2
    assert ep.rejected["unknown_stream"] == 1 and ep.rejected["unknown_param"] == 2


def test_a_flood_is_bounded_and_counted() -> None:
    ep = endpoint()
    channel = ep.open_channel("flood")
    request = packet(GCS.command_long_encode(1, 1, 512, 0, 148, 0, 0, 0, 0, 0, 0))
    ep.receive(channel, request * 1000, 0.0)  # 1000 requests, 2 replies each, in one go
    assert len(channel.outbox) == OUTBOX_LIMIT
    assert ep.rejected["outbox_full"] == 2000 - OUTBOX_LIMIT
    assert ep.received["COMMAND_LONG"] == 1000
    unknown_kind = packet(GCS.vision_position_estimate_encode(0, 0, 0, 0, 0, 0, 0))
    ep.receive(channel, unknown_kind * 10, 0.0)
    assert ep.rejected["unhandled"] == 10


def test_manual_control_to_the_broadcast_id_is_dropped_as_ardusub_drops_it() -> None:
    """ArduSub's GCS_MAVLink_Sub: ``if (packet.target != sysid_this_mav) break;`` — a
    MANUAL_CONTROL to system 0 moves nothing (it was taken as broadcast)."""
    ep = endpoint()
    channel = ep.open_channel("broadcast")
    ep.receive(channel, packet(GCS.manual_control_encode(0, 800, 0, 500, 0, 0)), 0.0)
    assert ep.world.get(ep.intents, MovementCommand) is None
    assert ep.rejected["wrong_target"] == 1 and ep.pilot_inputs == 0
    ep.receive(channel, packet(GCS.manual_control_encode(1, 800, 0, 500, 0, 0)), 0.0)
    command = ep.world.get(ep.intents, MovementCommand)
    assert command is not None and command.sticks[0] > 0.0
