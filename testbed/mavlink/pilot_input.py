"""The pilot's sticks and buttons: MANUAL_CONTROL and RC_CHANNELS_OVERRIDE as ArduSub takes them.

Each ``on_<message>(endpoint, channel, message, now_s, arrived_s)`` is a
:data:`~testbed.mavlink.endpoint.Handler`. Both messages are accepted only from the ground
station SYSID_MYGCS (ArduSub's ``sysid_is_gcs``; others counted ``wrong_sysid``), MANUAL_CONTROL
only when its ``target`` is this vehicle (no broadcast), RC_CHANNELS_OVERRIDE on the usual
target rule. MANUAL_CONTROL's axes are scaled as ArduSub's ``joystick.cpp``
(:func:`~testbed.mavlink.ardusub.manual_control_pwm`: the joystick gain, JS_THR_GAIN) into the
RC inputs (an axis out of range is acted on clamped, and counted ``clamped_axis``); the pitch
and roll extensions (``s``, ``t``) go to channels 1 and 2; a button newly pressed acts as
ArduSub's default buttons (1 MANUAL, 2 DEPTH HOLD, 3 STABILIZE, 4 disarm, 6 arm, 11/12 gain − /
+). RC_CHANNELS_OVERRIDE writes the channels it does not mark ignored (MAVLink 2 semantics).
Every accepted packet is pilot input: a new ``MovementCommand`` of the RC inputs
(:meth:`~testbed.mavlink.endpoint.VehicleEndpoint.write_sticks`), the GCS and pilot-input
failsafe timers refreshed.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.mavlink.ardusub import manual_control_pwm

if TYPE_CHECKING:
    from testbed.mavlink.channel import Channel
    from testbed.mavlink.endpoint import VehicleEndpoint

__all__ = ["BUTTON_MODES", "on_manual_control", "on_rc_channels_override"]

_INT16_UNUSED = 32767
"""MANUAL_CONTROL's INT16_MAX: the axis is not sent."""
BUTTON_MODES = {1: 19, 2: 2, 3: 0}
"""ArduSub's default buttons: 1 MANUAL, 2 DEPTH HOLD, 3 STABILIZE (4 disarm, 6 arm, 11/12
gain − / +)."""


def _from_gcs(endpoint: VehicleEndpoint, message: mav.MAVLink_message) -> bool:
    if message.get_srcSystem() != endpoint.gcs_system_id:
        endpoint.reject("wrong_sysid")
        return False
    return True


def on_manual_control(
    endpoint: VehicleEndpoint,
    channel: Channel,
    message: mav.MAVLink_message,
    now_s: float,
    arrived_s: float,
) -> None:
    """MANUAL_CONTROL → the RC inputs, the buttons, a MovementCommand (module docstring)."""
    del channel
    if not _from_gcs(endpoint, message):
        return
    if message.target != endpoint.system_id:  # ArduSub: this vehicle's id only, no broadcast
        endpoint.reject("wrong_target")
        return
    axes = []
    for name, low in (("x", -1000), ("y", -1000), ("z", 0), ("r", -1000)):
        value = int(getattr(message, name))
        if value == _INT16_UNUSED:
            value = 500 if name == "z" else 0
        elif not low <= value <= 1000:
            # acted on as ArduSub's joystick.cpp does: scaled, the pulse constrained
            endpoint.reject("clamped_axis")
        axes.append(value)
    x, y, z, r = axes
    pwm = manual_control_pwm(
        x, y, z, r, gain=endpoint.gain, throttle_gain=endpoint.params["JS_THR_GAIN"]
    )
    channels = endpoint.rc.channels
    for number, value in pwm.items():
        channels[number - 1] = value
    extensions = int(getattr(message, "enabled_extensions", 0) or 0)
    channels[0] = _extension_pwm(message, "s") if extensions & 1 else 1500
    channels[1] = _extension_pwm(message, "t") if extensions & 2 else 1500
    _on_buttons(endpoint, int(message.buttons) & 0xFFFF, now_s)
    _pilot_input(endpoint, now_s, arrived_s)


def on_rc_channels_override(
    endpoint: VehicleEndpoint,
    channel: Channel,
    message: mav.MAVLink_message,
    now_s: float,
    arrived_s: float,
) -> None:
    """RC_CHANNELS_OVERRIDE → the RC inputs it sets, a MovementCommand (module docstring)."""
    del channel
    if not _from_gcs(endpoint, message) or not endpoint.for_us(
        message.target_system, message.target_component
    ):
        return
    channels = endpoint.rc.channels
    for number in range(1, 19):
        value = int(getattr(message, f"chan{number}_raw", 65535))
        if value in (65535, 65534) or (number > 8 and value == 0):
            continue  # ignore this channel (MAVLink 2 semantics)
        channels[number - 1] = 1500 if value == 0 and number <= 6 else value
    _pilot_input(endpoint, now_s, arrived_s)


def _pilot_input(endpoint: VehicleEndpoint, now_s: float, arrived_s: float) -> None:
    """An accepted stick packet: a new MovementCommand, the timers refreshed."""
    endpoint.accepted += 1
    endpoint.pilot_inputs += 1
    endpoint.gcs_seen(now_s)
    endpoint.failsafe.pilot_seen(now_s)
    endpoint.write_sticks(arrived_s)


def _on_buttons(endpoint: VehicleEndpoint, buttons: int, now_s: float) -> None:
    pressed = buttons & ~endpoint.buttons_held
    endpoint.buttons_held = buttons
    if not pressed:
        return
    for button, mode in BUTTON_MODES.items():
        if pressed & (1 << button):
            endpoint.set_mode(mode)
    if pressed & (1 << 4):
        endpoint.request_arm(False, now_s)
    if pressed & (1 << 6):
        endpoint.request_arm(True, now_s)
    params = endpoint.params
    steps = max(1, int(params["JS_GAIN_STEPS"]))
    low, high = params["JS_GAIN_MIN"], params["JS_GAIN_MAX"]
    step = (high - low) / max(1, steps - 1)
    if pressed & (1 << 11):
        endpoint.gain = max(low, endpoint.gain - step)
    if pressed & (1 << 12):
        endpoint.gain = min(high, endpoint.gain + step)


def _extension_pwm(message: mav.MAVLink_message, name: str) -> int:
    """Pitch (s) or roll (t) extension: value + 1500, unscaled, clamped to 1100..1900 [µs]."""
    value = int(getattr(message, name, 0) or 0)
    if value == _INT16_UNUSED:
        return 1500
    return max(1100, min(1900, 1500 + value))
