"""GLOBAL_POSITION_INT's integer fields as ArduPilot converts them, read by pymavlink.

ArduPilot's ``GCS_MAVLINK::send_global_position_int`` (``libraries/GCS_MAVLink/GCS_Common.cpp``,
the same in a 4.5 branch and in the newest stored master-era copy) sends ``ahrs.yaw_sensor`` as
``hdg``; ``AP_AHRS::update_cd_values`` (``libraries/AP_AHRS/AP_AHRS.cpp``) sets that int32 to
``degrees(yaw) * 100`` — the centidegrees truncated toward 0 — and adds 36000 when negative.
So for a yaw east of north the heading's fraction of a centidegree is dropped (12.345° → 1234),
west of north (yaw < 0) it is rounded up instead (−1.7 cd → 35999, not 35998): never the nearest
centidegree, which the endpoint used to send. Its ``vx, vy, vz`` are ``vel.x * 100`` (a float)
passed to int16 fields and ``relative_alt`` is ``global_position_int_relative_alt``'s
``posD *= -1000.0f`` returned as an int32: C's conversions, toward 0; the endpoint used to
round them too.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mav

from tests.mavlink.gcs import SimGcs


def _ardupilot_yaw_sensor(yaw_rad: float) -> int:
    """``AP_AHRS::update_cd_values``: int32 ``degrees(yaw) * 100`` (toward 0), + 36000 if < 0."""
    centideg = math.trunc(math.degrees(yaw_rad) * 100.0)
    return centideg + 36000 if centideg < 0 else centideg


def test_hdg_is_ardupilots_yaw_sensor_truncated_not_rounded(gcs: SimGcs) -> None:
    """Turning to port, then to starboard through north, with GLOBAL_POSITION_INT and ATTITUDE
    asked for every 50 ms together (SET_MESSAGE_INTERVAL in one step, so they share a
    schedule): each hdg is the yaw_sensor of the ATTITUDE yaw sent in the same step (the same
    state; ATTITUDE's float32 yaw resolves a centidegree to ~1e-3 cd, so fractions within
    0.02 cd of a whole one are left out). Both signs of yaw occur, and in many pairs the
    nearest centidegree differs."""
    interval = mav.MAV_CMD_SET_MESSAGE_INTERVAL
    gcs.send(
        gcs.heartbeat(),
        gcs.arm(),
        gcs.command(interval, mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 50_000),
        gcs.command(interval, mav.MAVLINK_MSG_ID_ATTITUDE, 50_000),
    )
    gcs.run(0.2, gcs.flying())
    pairs: list[tuple[int, float]] = []
    for k in range(round(12.0 / 0.01)):  # turning west of north, then back east of it
        gcs.send(*([gcs.sticks(r=-500 if k < 500 else 500)] if k % 4 == 0 else []))
        gcs.send(*([gcs.heartbeat()] if k % 100 == 0 else []))
        before = len(gcs.messages)
        gcs.step()
        new = gcs.messages[before:]
        fixes = [m for m in new if m.get_type() == "GLOBAL_POSITION_INT"]
        attitudes = [m for m in new if m.get_type() == "ATTITUDE"]
        if fixes and attitudes:
            pairs.append((fixes[-1].hdg, attitudes[-1].yaw))
    checked = negative = rounding_differs = 0
    for hdg, yaw in pairs:
        centideg = math.degrees(yaw) * 100.0
        fraction = abs(centideg) - math.floor(abs(centideg))
        if not 0.02 < fraction < 0.98:
            continue
        assert hdg == _ardupilot_yaw_sensor(yaw), (hdg, yaw)
        checked += 1
        negative += yaw < 0.0
        rounding_differs += hdg != round(math.degrees(yaw) % 360.0 * 100.0) % 36000
    assert checked >= 150 and negative >= 20 and checked - negative >= 20
    assert rounding_differs >= 30


def _diving_pairs(gcs: SimGcs) -> list[tuple[Any, Any]]:
    """(GLOBAL_POSITION_INT, LOCAL_POSITION_NED) sent in the same step, both at 20 Hz, for 8 s
    of diving forward and turning."""
    interval = mav.MAV_CMD_SET_MESSAGE_INTERVAL
    gcs.send(
        gcs.heartbeat(),
        gcs.arm(),
        gcs.command(interval, mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 50_000),
        gcs.command(interval, mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 50_000),
    )
    gcs.run(0.2, gcs.flying())
    pairs: list[tuple[Any, Any]] = []
    for k in range(round(8.0 / 0.01)):
        gcs.send(*([gcs.sticks(x=600, z=200, r=300)] if k % 4 == 0 else []))
        gcs.send(*([gcs.heartbeat()] if k % 100 == 0 else []))
        before = len(gcs.messages)
        gcs.step()
        new = gcs.messages[before:]
        fixes = [m for m in new if m.get_type() == "GLOBAL_POSITION_INT"]
        locals_ = [m for m in new if m.get_type() == "LOCAL_POSITION_NED"]
        if fixes and locals_:
            pairs.append((fixes[-1], locals_[-1]))
    return pairs


def test_velocities_and_relative_alt_are_converted_toward_zero(gcs: SimGcs) -> None:
    """``vel.x * 100`` (float) into the int16 vx, vy, vz and ``posD * -1000.0f`` returned as
    the int32 relative_alt are C's conversions, toward 0. LOCAL_POSITION_NED (the same group,
    the same step, the same state) carries the same velocity and depth as float32, so each
    GLOBAL_POSITION_INT field is that float32 times 100 (or −1000) in single precision,
    truncated. Diving forward and turning, the nearest integer differs in many of them."""
    pairs = _diving_pairs(gcs)
    hundred, minus_thousand = np.float32(100.0), np.float32(-1000.0)
    checked = rounding_differs = 0
    for fix, local in pairs:
        expected = [
            (fix.vx, np.float32(local.vx) * hundred),
            (fix.vy, np.float32(local.vy) * hundred),
            (fix.vz, np.float32(local.vz) * hundred),
            (fix.relative_alt, np.float32(local.z) * minus_thousand),
        ]
        for sent, product in expected:
            assert sent == math.trunc(float(product)), (sent, float(product))
            checked += 1
            rounding_differs += sent != round(float(product))
    assert len(pairs) >= 100 and checked >= 400 and rounding_differs >= 100


def test_alt_is_ardusubs_millimetres_toward_zero(gcs: SimGcs) -> None:
    """ArduSub 4.5 (``GCS_MAVLink_Sub.cpp``, #26649 backported to Sub-4.5 as #31564):
    ``return static_cast<int32_t>(sub.get_alt_msl() * 1000.0f);`` with ``Sub::get_alt_msl``
    ``posD -= static_cast<float>(origin.alt) * 0.01f; return -posD;`` — the origin at 0 m here,
    so the float ``-z`` times 1000 in single precision, truncated, the same integer as
    relative_alt. It was ``round(-depth * 1000)``: the nearest millimetre."""
    pairs = _diving_pairs(gcs)
    rounding_differs = 0
    for fix, local in pairs:
        product = -np.float32(local.z) * np.float32(1000.0)
        assert fix.alt == math.trunc(float(product)) == fix.relative_alt, (fix.alt, product)
        rounding_differs += fix.alt != round(float(product))
    assert len(pairs) >= 100 and rounding_differs >= 25
