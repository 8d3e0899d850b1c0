"""The MAVLink parameter protocol over the endpoint's :class:`~testbed.mavlink.params.ParamTable`.

PARAM_REQUEST_LIST starts a channel's download (ArduPilot's banner first: the firmware version
and the frame), which :func:`send_params` paces per update; PARAM_REQUEST_READ answers one
parameter by index or name; PARAM_SET sets one and echoes the new value to every channel (a
refused value of a known parameter is answered with the unchanged one, an unknown name not at
all). A parameter asked for by its alias (ArduPilot 4.7's ``MAV_GCS_SYSID``) is answered by that
name. Handlers as :mod:`testbed.mavlink.commands`'s: ``on_<message>(endpoint, channel,
message, now_s, arrived_s)``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.mavlink.ardusub import FIRMWARE_VERSION, GIT_HASH
from testbed.mavlink.params import ALIASES

if TYPE_CHECKING:
    from testbed.mavlink.channel import Channel
    from testbed.mavlink.endpoint import VehicleEndpoint

__all__ = ["on_param_request_list", "on_param_request_read", "on_param_set", "send_params"]


def _text(value: object) -> str:
    """A char[] field as pymavlink gives it (str or bytes), NULs stripped."""
    if isinstance(value, bytes):
        value = value.decode("ascii", "replace")
    return str(value).split("\x00", 1)[0]


def _param_value(
    endpoint: VehicleEndpoint, index: int, asked: str = ""
) -> mav.MAVLink_message | None:
    """PARAM_VALUE of parameter ``index``, named as ``asked`` when that is its alias (a ground
    station that set or read it by the other release's name waits for that name)."""
    entry = endpoint.params.entry(index)
    if entry is None:
        return None
    param, value = entry
    name = asked if ALIASES.get(asked) == param.name else param.name
    return mav.MAVLink_param_value_message(
        name.encode(), value, param.mav_type, len(endpoint.params), index
    )


def on_param_request_list(
    endpoint: VehicleEndpoint,
    channel: Channel,
    message: mav.MAVLink_message,
    now_s: float,
    arrived_s: float,
) -> None:
    """Start (or restart) the channel's parameter download; ArduPilot's banner first."""
    del now_s, arrived_s
    if not endpoint.for_us(message.target_system, message.target_component):
        return
    endpoint.accepted += 1
    major, minor, patch = FIRMWARE_VERSION
    endpoint.statustext(
        mav.MAV_SEVERITY_INFO, f"ArduSub V{major}.{minor}.{patch} ({GIT_HASH.decode()})"
    )
    frame = int(endpoint.params["FRAME_CONFIG"])
    endpoint.statustext(mav.MAV_SEVERITY_INFO, f"Frame: {_FRAMES.get(frame, 'CUSTOM')}")
    channel.param_cursor = 0


_FRAMES = {
    0: "BLUEROV1",
    1: "VECTORED",
    2: "VECTORED_6DOF",
    3: "VECTORED_6DOF_90",
    4: "SIMPLEROV_3",
    5: "SIMPLEROV_4",
    6: "SIMPLEROV_5",
    7: "CUSTOM",
}


def send_params(endpoint: VehicleEndpoint, channel: Channel) -> None:
    """Queue the next PARAM_VALUEs of a download in progress (paced per update)."""
    cursor = channel.param_cursor
    if cursor is None:
        return
    end = min(len(endpoint.params), cursor + endpoint.options.params_per_update)
    for index in range(cursor, end):
        message = _param_value(endpoint, index)
        if message is not None:
            endpoint.queue(channel, message)
    channel.param_cursor = None if end >= len(endpoint.params) else end


def on_param_request_read(
    endpoint: VehicleEndpoint,
    channel: Channel,
    message: mav.MAVLink_message,
    now_s: float,
    arrived_s: float,
) -> None:
    """PARAM_VALUE of one parameter, by index (≥ 0) or by name; unknown ones unanswered."""
    del now_s, arrived_s
    if not endpoint.for_us(message.target_system, message.target_component):
        return
    index: int | None = int(message.param_index)
    asked = ""
    if index is None or index < 0:
        asked = _text(message.param_id)
        index = endpoint.params.index_of(asked)
    reply = None if index is None else _param_value(endpoint, index, asked)
    if reply is None:
        endpoint.reject("unknown_param")
        return
    endpoint.accepted += 1
    endpoint.queue(channel, reply)


def on_param_set(
    endpoint: VehicleEndpoint,
    channel: Channel,
    message: mav.MAVLink_message,
    now_s: float,
    arrived_s: float,
) -> None:
    """Set a parameter; the new value goes to every channel. A refused value of a known
    parameter is answered with the unchanged value; an unknown name is not answered."""
    del now_s, arrived_s
    if not endpoint.for_us(message.target_system, message.target_component):
        return
    name = _text(message.param_id)
    index = endpoint.params.set(name, float(message.param_value))
    if index is None:
        endpoint.reject("param_refused")
        known = endpoint.params.index_of(name)
        reply = None if known is None else _param_value(endpoint, known, name)
        if reply is not None:
            endpoint.queue(channel, reply)
        return
    endpoint.accepted += 1  # (SYSID_THISMAV and JS_GAIN_DEFAULT take effect at the next boot)
    reply = _param_value(endpoint, index, name)
    if reply is not None:
        endpoint.broadcast(reply)
