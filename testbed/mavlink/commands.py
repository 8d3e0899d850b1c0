"""The endpoint's request handlers: commands, modes, mission, streams, time sync, MAVFTP.

Each ``on_<message>(endpoint, channel, message, now_s, arrived_s)`` answers on the channel the
request came on (STATUSTEXT goes to every channel); the parameter protocol's handlers are
:mod:`testbed.mavlink.param_protocol`'s.
COMMAND_LONG and COMMAND_INT share one table (:data:`COMMANDS`): arm/disarm (400), DO_SET_MODE
(176), SET_MESSAGE_INTERVAL (511), GET_MESSAGE_INTERVAL (510), REQUEST_MESSAGE (512),
REQUEST_AUTOPILOT_CAPABILITIES (520), GET_HOME_POSITION (410), DO_MOTOR_TEST (209,
:mod:`~testbed.mavlink.motor_test`), CONTROL_HIGH_LATENCY (2600,
:mod:`~testbed.mavlink.high_latency`), and those carrying a location
(:data:`LOCATION_COMMANDS`): DO_REPOSITION (192, :func:`~testbed.mavlink.guided.do_reposition`);
anything else is acknowledged UNSUPPORTED. Commands are
not gated on the sender's system id (ArduSub's are not), only on the target.

Mode policy (ArduSub ``Sub::set_mode``): MANUAL 19, STABILIZE 0 and ALT_HOLD 2 are accepted
and requested of the vehicle; GUIDED 4 too when the vehicle has a position estimate
(:meth:`~testbed.mavlink.endpoint.VehicleEndpoint.has_position_estimate`), whose entry holds
at ArduSub's stopping point (:func:`~testbed.mavlink.guided_entry.hold_where_entered`);
every other number is refused with MAV_RESULT_FAILED and the warning "Flight mode change
failed" — ArduSub's answer for AUTO, GUIDED, CIRCLE and POSHOLD without a position estimate and
for unknown numbers. AUTO, CIRCLE, POSHOLD, ACRO, SURFACE, MOTOR_DETECT and SURFTRAK exist in
ArduSub but not in the simulator, so a position fix does not change their answer. GUIDED's
SET_POSITION_TARGET_LOCAL_NED is :mod:`testbed.mavlink.guided`'s.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.common.components import ControlMode
from testbed.mavlink import guided, guided_entry, high_latency
from testbed.mavlink.ardusub import (
    FLIGHT_SW_VERSION,
    GIT_HASH,
    MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
    POSITION_MODES,
    SIMULATED_MODES,
)
from testbed.mavlink.motor_test import do_motor_test
from testbed.mavlink.telemetry import MESSAGE_IDS

if TYPE_CHECKING:
    from collections.abc import Callable

    from testbed.mavlink.channel import Channel
    from testbed.mavlink.endpoint import VehicleEndpoint

__all__ = [
    "CAPABILITIES",
    "COMMANDS",
    "LOCATION_COMMANDS",
    "autopilot_version",
    "on_command_int",
    "on_command_long",
    "on_mission_request_list",
    "on_mission_upload",
    "on_request_data_stream",
    "on_set_mode",
    "on_timesync",
    "set_mode",
]

CAPABILITIES = (
    mav.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
    | mav.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | mav.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    | mav.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | mav.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST
    | mav.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    | mav.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    | mav.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
    | mav.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
)
"""AUTOPILOT_VERSION.capabilities (ArduPilot's, less what the simulator cannot do;
PARAM_ENCODE_C_CAST is REFERENCE §4.4's, which marks it unverified: parameters are sent as
floats cast, as ArduPilot's GCS code does)."""
_NAMES_BY_ID = {msg_id: name for name, msg_id in MESSAGE_IDS.items()}
_ACCEPTED: int = mav.MAV_RESULT_ACCEPTED
_FAILED: int = mav.MAV_RESULT_FAILED
_UNSUPPORTED: int = mav.MAV_RESULT_UNSUPPORTED
_DENIED: int = mav.MAV_RESULT_DENIED


def autopilot_version(endpoint: VehicleEndpoint) -> mav.MAVLink_message:
    """AUTOPILOT_VERSION: ArduSub :data:`~.ardusub.FIRMWARE_VERSION`, MAVLink 2."""
    del endpoint
    hash_bytes = list(GIT_HASH[:8].ljust(8, b"0"))
    return mav.MAVLink_autopilot_version_message(
        CAPABILITIES,
        FLIGHT_SW_VERSION,
        0,
        0,
        0,
        hash_bytes,
        [0] * 8,
        [0] * 8,
        0,
        0,
        0,
        [0] * 18,
    )


def _ack(
    endpoint: VehicleEndpoint, channel: Channel, message: mav.MAVLink_message, cmd: int, result: int
) -> None:
    endpoint.queue(
        channel,
        mav.MAVLink_command_ack_message(
            cmd, result, 0, 0, message.get_srcSystem(), message.get_srcComponent()
        ),
    )


def set_mode(endpoint: VehicleEndpoint, custom_mode: int) -> int:
    """Request ArduSub mode ``custom_mode``; the MAV_RESULT (module docstring)."""
    mode = SIMULATED_MODES.get(custom_mode)
    if mode is not None and custom_mode in POSITION_MODES and not endpoint.has_position_estimate():
        mode = None
    if mode is None:
        endpoint.reject("mode_refused")
        endpoint.statustext(mav.MAV_SEVERITY_WARNING, "Flight mode change failed")
        return _FAILED
    entered = mode is not endpoint.requested_mode  # ArduSub's set_mode: the same mode, nothing
    endpoint.request_mode(mode)
    if entered and mode is ControlMode.GUIDED:
        guided_entry.hold_where_entered(endpoint)
    return _ACCEPTED


def _arm(endpoint: VehicleEndpoint, p: tuple[float, ...], now_s: float) -> int:
    if p[0] == 1.0:
        endpoint.request_arm(True, now_s)
        return _ACCEPTED
    if p[0] == 0.0:
        endpoint.request_arm(False, now_s)
        return _ACCEPTED
    return _UNSUPPORTED


def _do_set_mode(endpoint: VehicleEndpoint, p: tuple[float, ...], now_s: float) -> int:
    del now_s
    if not (math.isfinite(p[0]) and math.isfinite(p[1])) or not int(p[0]) & 1:
        return _FAILED
    return set_mode(endpoint, int(p[1]))


def _send_by_id(endpoint: VehicleEndpoint, channel: Channel, msg_id: int) -> int:
    if msg_id == mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
        endpoint.queue(channel, autopilot_version(endpoint))
        return _ACCEPTED
    name = _NAMES_BY_ID.get(msg_id)
    if name is None:
        return _UNSUPPORTED
    endpoint.queue(channel, endpoint.message(name))
    return _ACCEPTED


def _cmd_arm(e: VehicleEndpoint, c: Channel, p: tuple[float, ...], now_s: float) -> int:
    del c
    return _arm(e, p, now_s)


def _cmd_set_mode(e: VehicleEndpoint, c: Channel, p: tuple[float, ...], now_s: float) -> int:
    del c
    return _do_set_mode(e, p, now_s)


def _cmd_request_message(e: VehicleEndpoint, c: Channel, p: tuple[float, ...], now_s: float) -> int:
    del now_s
    if not math.isfinite(p[0]) or not 0 <= p[0] < 2**24:
        return _DENIED
    return _send_by_id(e, c, int(p[0]))


def _cmd_capabilities(e: VehicleEndpoint, c: Channel, p: tuple[float, ...], now_s: float) -> int:
    del p, now_s
    return _send_by_id(e, c, mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION)


def _cmd_home(e: VehicleEndpoint, c: Channel, p: tuple[float, ...], now_s: float) -> int:
    del p, now_s
    return _send_by_id(e, c, mav.MAVLINK_MSG_ID_HOME_POSITION)


def _cmd_motor_test(e: VehicleEndpoint, c: Channel, p: tuple[float, ...], now_s: float) -> int:
    del c
    return do_motor_test(e, p, now_s)


def _message_id(param1: float) -> int | None:
    """SET/GET_MESSAGE_INTERVAL's param1 as ArduPilot reads it, ``(uint32_t)packet.param1``
    (toward 0); None where C leaves that conversion undefined (NaN, −1 and below, 2³² and up)."""
    return math.trunc(param1) if -1.0 < param1 < 2.0**32 else None


def _cmd_set_interval(e: VehicleEndpoint, c: Channel, p: tuple[float, ...], now_s: float) -> int:
    """ArduPilot 4.5's ``GCS_MAVLINK::set_message_interval`` (``GCS_Common.cpp``, the
    ``mavlink_command_int_t`` handlers of 4.5) for an id with no ``ap_message`` (here: one this
    endpoint does not send): it says "No ap_message for mavlink id (N)" (INFO, to every link)
    before it reads the interval, and answers MAV_RESULT_DENIED, whatever param2 (0 too; the
    4.4-era code answered FAILED, silently for 0). HEARTBEAT's rate is set on this link
    (ArduPilot's MSG_HEARTBEAT, a deferred message: :meth:`.StreamSchedule.set_interval`). A
    message sent on request but in no stream group (:data:`~.streams.ON_REQUEST`:
    HOME_POSITION, GPS_GLOBAL_ORIGIN, ATTITUDE_QUATERNION) is streamed as asked, ACCEPTED, as
    ``set_ap_message_interval`` buckets any ``ap_message``; a NaN interval is UNSUPPORTED (C
    leaves ``(int32_t)`` of it undefined)."""
    del now_s
    msg_id = _message_id(p[0])
    name = None if msg_id is None else _NAMES_BY_ID.get(msg_id)
    if name is None:
        if msg_id is not None:
            e.statustext(mav.MAV_SEVERITY_INFO, f"No ap_message for mavlink id ({msg_id})")
        return _DENIED
    if not c.streams.set_interval(name, p[1]):
        return _UNSUPPORTED
    return _ACCEPTED


def _cmd_get_interval(e: VehicleEndpoint, c: Channel, p: tuple[float, ...], now_s: float) -> int:
    """ArduPilot 4.5's ``GCS_MAVLINK::handle_command_get_message_interval`` (``GCS_Common.cpp``):
    an id of 65536 or more, or one with no ``ap_message`` (here: not sent), is answered
    MESSAGE_INTERVAL 0 ("not available"; the id cut to the field's uint16) and
    MAV_RESULT_FAILED; a message sent but not streamed now (an :data:`~.streams.ON_REQUEST`
    one until SET_MESSAGE_INTERVAL streams it; one switched off) −1 ("disabled") and ACCEPTED —
    ``get_ap_message_interval`` finds it in no bucket, or its interval is 0 — else the interval
    kept (:meth:`.StreamSchedule.interval_us`), ACCEPTED."""
    del now_s
    msg_id = _message_id(p[0])
    if msg_id is None:
        return _FAILED
    name = _NAMES_BY_ID.get(msg_id) if msg_id < 2**16 else None
    interval_us = 0 if name is None else c.streams.interval_us(name)
    e.queue(c, mav.MAVLink_message_interval_message(msg_id & 0xFFFF, interval_us))
    return _FAILED if name is None else _ACCEPTED


COMMANDS: dict[int, Callable[[VehicleEndpoint, Channel, tuple[float, ...], float], int]] = {
    mav.MAV_CMD_COMPONENT_ARM_DISARM: _cmd_arm,
    mav.MAV_CMD_DO_SET_MODE: _cmd_set_mode,
    mav.MAV_CMD_REQUEST_MESSAGE: _cmd_request_message,
    mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: _cmd_capabilities,
    mav.MAV_CMD_GET_HOME_POSITION: _cmd_home,
    mav.MAV_CMD_SET_MESSAGE_INTERVAL: _cmd_set_interval,
    mav.MAV_CMD_GET_MESSAGE_INTERVAL: _cmd_get_interval,
    mav.MAV_CMD_DO_MOTOR_TEST: _cmd_motor_test,
    mav.MAV_CMD_CONTROL_HIGH_LATENCY: high_latency.control_high_latency,
}
"""MAV_CMD → handler returning the MAV_RESULT to acknowledge."""
LOCATION_COMMANDS: dict[int, Callable[[VehicleEndpoint, int, tuple[float, ...], int, int], int]] = {
    mav.MAV_CMD_DO_REPOSITION: guided.do_reposition,
}
"""MAV_CMD → handler of a command that carries a location (ArduPilot's
``command_long_stores_location``), given its frame, params and latitude and longitude
[1e-7 deg]; the MAV_RESULT to acknowledge. It counts itself: ``accepted`` only when it
answers ACCEPTED, else the reason it refused."""


def _e7(degrees: float) -> int:
    """ArduPilot's ``convert_COMMAND_LONG_loc_param``: degrees → 1e-7 degrees (NaN → 0; beyond
    int32, its bound)."""
    if not math.isfinite(degrees):
        return 0
    return max(-(2**31), min(2**31 - 1, int(degrees * 1e7)))


def _command(
    endpoint: VehicleEndpoint,
    channel: Channel,
    message: mav.MAVLink_message,
    params: tuple[float, ...],
    now_s: float,
    location: tuple[int, int, int],
) -> None:
    """Act on a command and acknowledge it; ``location`` is its (frame, lat, lon [1e-7 deg])."""
    if not endpoint.for_us(message.target_system, message.target_component):
        return
    cmd = int(message.command)
    located = LOCATION_COMMANDS.get(cmd)
    if located is not None:  # it counts what it did
        _ack(endpoint, channel, message, cmd, located(endpoint, location[0], params, *location[1:]))
        return
    handler = COMMANDS.get(cmd)
    if handler is None:
        endpoint.reject("unsupported_command")
        _ack(endpoint, channel, message, cmd, _UNSUPPORTED)
        return
    before = sum(endpoint.rejected.values())
    result = handler(endpoint, channel, params, now_s)
    _ack(endpoint, channel, message, cmd, _counted(endpoint, result, before))


def _counted(endpoint: VehicleEndpoint, result: int, rejected_before: int) -> int:
    """``result`` (a MAV_RESULT), counted once: ``accepted`` when ACCEPTED, else under the
    reason its handler counted (``mode_refused``, ``bad_field``…) or, when it counted none,
    ``command_refused``; ``rejected_before`` is the rejections' total before the handler ran."""
    if result == _ACCEPTED:
        endpoint.accepted += 1
    elif sum(endpoint.rejected.values()) == rejected_before:
        endpoint.reject("command_refused")
    return result


def on_command_long(
    endpoint: VehicleEndpoint,
    channel: Channel,
    message: mav.MAVLink_message,
    now_s: float,
    arrived_s: float,
) -> None:
    """COMMAND_LONG → :data:`COMMANDS`, acknowledged; a location command's params 5, 6 are its
    latitude and longitude [deg] in MAV_FRAME_GLOBAL, as ArduPilot converts it to a
    COMMAND_INT (``convert_COMMAND_LONG_to_COMMAND_INT``)."""
    del arrived_s
    params = tuple(float(getattr(message, f"param{k}")) for k in range(1, 8))
    location = (mav.MAV_FRAME_GLOBAL, _e7(params[4]), _e7(params[5]))
    _command(endpoint, channel, message, params, now_s, location)


def on_command_int(
    endpoint: VehicleEndpoint,
    channel: Channel,
    message: mav.MAVLink_message,
    now_s: float,
    arrived_s: float,
) -> None:
    """COMMAND_INT → :data:`COMMANDS` (param1–4; x, y, z as params 5–7), acknowledged; a
    location command's x, y are its latitude and longitude [1e-7 deg] in its ``frame``."""
    del arrived_s
    params = tuple(float(getattr(message, f"param{k}")) for k in range(1, 5))
    params += (float(message.x), float(message.y), float(message.z))
    location = (int(message.frame), int(message.x), int(message.y))
    _command(endpoint, channel, message, params, now_s, location)


def on_set_mode(
    endpoint: VehicleEndpoint,
    channel: Channel,
    message: mav.MAVLink_message,
    now_s: float,
    arrived_s: float,
) -> None:
    """SET_MODE → a COMMAND_ACK whose command is SET_MODE's message id, 11, as ArduPilot's
    ``GCS_MAVLINK::handle_set_mode`` sends (not DO_SET_MODE's 176); DENIED without the custom
    mode flag (``_set_mode_common``'s "supported but invalid parameters")."""
    del now_s, arrived_s
    if not endpoint.for_us(message.target_system):
        return
    before = sum(endpoint.rejected.values())
    if not int(message.base_mode) & MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
        result = _DENIED
    else:
        result = set_mode(endpoint, int(message.custom_mode))
    _ack(
        endpoint, channel, message, mav.MAVLINK_MSG_ID_SET_MODE, _counted(endpoint, result, before)
    )


# ------------------------------------------------------------------- mission, streams, time


def on_mission_request_list(
    endpoint: VehicleEndpoint,
    channel: Channel,
    message: mav.MAVLink_message,
    now_s: float,
    arrived_s: float,
) -> None:
    """MISSION_COUNT 0: the simulated vehicle holds no mission, fence or rally points."""
    del now_s, arrived_s
    if not endpoint.for_us(message.target_system, message.target_component):
        return
    endpoint.accepted += 1
    mission_type = int(getattr(message, "mission_type", 0) or 0)
    endpoint.queue(
        channel,
        mav.MAVLink_mission_count_message(
            message.get_srcSystem(), message.get_srcComponent(), 0, mission_type
        ),
    )


def on_mission_upload(
    endpoint: VehicleEndpoint,
    channel: Channel,
    message: mav.MAVLink_message,
    now_s: float,
    arrived_s: float,
) -> None:
    """MISSION_COUNT (an upload) is refused at once with MISSION_ACK MAV_MISSION_UNSUPPORTED
    (the simulated vehicle flies no AUTO missions: a ground station's upload fails now rather
    than timing out); MISSION_CLEAR_ALL is acknowledged MAV_MISSION_ACCEPTED (nothing held)."""
    del now_s, arrived_s
    if not endpoint.for_us(message.target_system, message.target_component):
        return
    endpoint.accepted += 1
    mission_type = int(getattr(message, "mission_type", 0) or 0)
    cleared = message.get_type() == "MISSION_CLEAR_ALL"
    result = mav.MAV_MISSION_ACCEPTED if cleared else mav.MAV_MISSION_UNSUPPORTED
    endpoint.queue(
        channel,
        mav.MAVLink_mission_ack_message(
            message.get_srcSystem(), message.get_srcComponent(), result, mission_type
        ),
    )


def on_request_data_stream(
    endpoint: VehicleEndpoint,
    channel: Channel,
    message: mav.MAVLink_message,
    now_s: float,
    arrived_s: float,
) -> None:
    """REQUEST_DATA_STREAM: a group's rate on this channel (start_stop 0 stops it)."""
    del now_s, arrived_s
    if not endpoint.for_us(message.target_system, message.target_component):
        return
    rate = float(message.req_message_rate) if int(message.start_stop) else 0.0
    if not channel.streams.set_group(int(message.req_stream_id), rate):
        endpoint.reject("unknown_stream")
        return
    endpoint.accepted += 1


def on_timesync(
    endpoint: VehicleEndpoint,
    channel: Channel,
    message: mav.MAVLink_message,
    now_s: float,
    arrived_s: float,
) -> None:
    """TIMESYNC request (tc1 0) → reply with tc1 = our time [ns] and the request's ts1."""
    del arrived_s
    endpoint.accepted += 1
    if int(message.tc1) != 0:
        return  # a reply to a request we never send
    tc1 = max(1, round(now_s * 1e9))  # never 0, which would read as a request
    endpoint.queue(channel, mav.MAVLink_timesync_message(tc1, int(message.ts1)))


_FTP_ACK = 128
_FTP_NAK = 129
_FTP_END_SESSION = frozenset({1, 2})  # TerminateSession, ResetSessions: acknowledged
_FTP_FILE_NOT_FOUND = 10
_FTP_PAYLOAD_BYTES = 251


def on_file_transfer_protocol(
    endpoint: VehicleEndpoint,
    channel: Channel,
    message: mav.MAVLink_message,
    now_s: float,
    arrived_s: float,
) -> None:
    """MAVFTP: the simulated vehicle has no file system. Every request is answered with a NAK
    (FileNotFound), session ends with an ACK, so a ground station that tries MAVFTP first
    (MAVProxy's parameter download) falls back to the parameter protocol at once instead of
    timing out."""
    del now_s, arrived_s
    if not endpoint.for_us(message.target_system, message.target_component):
        return
    payload = bytes(message.payload)
    if len(payload) < 12:
        endpoint.reject("bad_field")
        return
    endpoint.accepted += 1
    seq = (payload[0] | payload[1] << 8) + 1
    opcode = payload[3]
    ack = opcode in _FTP_END_SESSION
    reply = bytearray(_FTP_PAYLOAD_BYTES)
    reply[0:2] = (seq & 0xFFFF).to_bytes(2, "little")
    reply[2] = payload[2]  # session
    reply[3] = _FTP_ACK if ack else _FTP_NAK
    reply[4] = 0 if ack else 1  # size
    reply[5] = opcode  # req_opcode
    if not ack:
        reply[12] = _FTP_FILE_NOT_FOUND
    endpoint.queue(
        channel,
        mav.MAVLink_file_transfer_protocol_message(
            0, message.get_srcSystem(), message.get_srcComponent(), list(reply)
        ),
    )
