"""The live console's state: what the browser is sent at ``PUBLISH_HZ``, as one JSON-ready dict.

:func:`console_state` reads a :class:`~testbed.live.session.LiveSession` (its operator station's
view, the vehicle's truth and control flags, the pilot, the link monitor, the image console and
the hub's counters) and builds the dict fresh each call; the only thing it changes is the link
monitor, which it brings up to date first.
Angles in degrees, positions NED [m], ages [s], latencies [ms].
"""

from __future__ import annotations

import math
import time
from collections import deque
from itertools import islice
from typing import TYPE_CHECKING, Any

from testbed.common.components import (
    ActiveMode,
    Armed,
    FailsafeStatus,
    ModeRequest,
    PositionSetpoint,
)
from testbed.common.geometry import euler_from_quat
from testbed.live.monitor import finite_or_none, image_view, latency_ms
from testbed.vehicle.resources import Controllers

if TYPE_CHECKING:
    from testbed.live.session import LiveSession

__all__ = ["console_state"]

_DEG = 180.0 / math.pi


def console_state(session: LiveSession) -> dict[str, Any]:
    """The console's state now: JSON-ready, built fresh from the session."""
    now = session.env.now
    recorder = session.recorder
    station, vehicle = session.station, session.vehicle
    odometry = station.vehicle_odometry()
    world = station.world
    armed = next((a.armed for _, a in world.query1(Armed)), None)
    mode = next((m.mode.name.lower() for _, m in world.query1(ActiveMode)), None)
    asked_mode = session.requests.asked  # asked on the console, or else the session plan's
    if asked_mode is None:
        asked_mode = next((r.mode for _, r in world.query1(ModeRequest)), None)
    asked = None if asked_mode is None else asked_mode.name.lower()
    truth = vehicle.truth
    ctl = vehicle.world.resource(Controllers)
    status = vehicle.world.get(ctl.vehicle, FailsafeStatus)
    session.monitor.update()
    lag = age = odometry_age = math.nan
    if recorder.command_updates:
        applied, sampled = recorder.command_updates[-1]
        lag = applied - sampled
        age = now - sampled
    if recorder.odometry_updates:
        odometry_age = now - recorder.odometry_updates[-1][1]
    state: dict[str, Any] = {
        "t": round(now, 3),
        "server_ns": time.monotonic_ns(),
        "operator": None
        if odometry is None
        else {
            "pos": [round(v, 3) for v in odometry.position_ned_m],
            "rpy": _rpy_deg(odometry.quaternion_wxyz),
            "armed": armed,
            "mode": mode,
            "age_s": finite_or_none(station.vehicle_state_age_s(now)),
        },
        "truth": {
            "pos": [round(v, 3) for v in truth.position_ned_m],
            "rpy": _rpy_deg(truth.quaternion_wxyz),
            "armed": ctl.flags.armed,
            "failsafe": "NOMINAL" if status is None else status.level.name,
            "sticks": [round(s, 3) for s in ctl.sticks],
            "target": _target(session),
        },
        "pilot": {
            "mode": asked,
            "sticks": [round(s, 3) for s in session.pilot.sticks],
            "taken": session.pilot.taken,
        },
        "link": {
            "uplink": session.monitor.direction("uplink", recorder.frames_decoded["uplink"]),
            "downlink": session.monitor.direction("downlink", recorder.frames_decoded["downlink"]),
            "command_lag_s": finite_or_none(lag),
            "command_age_s": finite_or_none(age),
            "odometry_age_s": finite_or_none(odometry_age),
            "simulated": session.medium is not None,
            "ber": None if session.medium is None else session.medium.config.ber,
            "gap_s": None if session.ipg is None else session.ipg.gap_after(13),
            "distance_m": session.distance_m,
            "outage": session.medium is not None and session.medium.in_outage(now, now),
            "timeline": list(session.monitor.timeline),
        },
        "image": _image_state(session, now),
        "console": {
            "inputs": session.hub.counters.as_dict(),
            "input_latency_ms": latency_ms(_newest(session.pilot.latencies_ns, 200)),
            "lateness_ms": latency_ms(_newest(session.lateness_ns, 1000)),
            "notes": list(session.hub.notes),
        },
        "events": [[round(e.t_s, 2), e.node, e.kind, e.detail] for e in recorder.events[-8:]],
    }
    return state


def _target(session: LiveSession) -> list[float] | None:
    """The go-to target the vehicle holds (its operator entity), or None."""
    world = session.vehicle.world
    target = world.get(session.vehicle.operator_entity, PositionSetpoint)
    return None if target is None else [round(v, 2) for v in target.position_ned_m]


def _image_state(session: LiveSession, now: float) -> dict[str, Any] | None:
    console = session.image_console
    images = session.vehicle_node.images
    if console is None or images is None:
        return None
    current = images.current
    coder = images.settings
    return {
        "view": image_view(console.view),
        "bytes": len(console.assembler.prefix()),
        "chunks": console.chunks_received,
        "completed": len(session.recorder.images.received),
        "age_s": None if current is None else round(now - current.t_s, 2),
        "coder": {
            "roi": [coder.x0, coder.y0, coder.x1, coder.y1],
            "shift": coder.roi_shift,
            "budget": coder.budget_bytes,
        },
    }


def _rpy_deg(quaternion: tuple[float, float, float, float]) -> list[float]:
    return [round(a * _DEG, 2) for a in euler_from_quat(quaternion)]


def _newest(samples: deque[int], count: int) -> list[int]:
    """The newest ``count`` samples (without copying the whole deque)."""
    return list(islice(reversed(samples), count))
