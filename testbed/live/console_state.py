"""The live console's state: what the browser is sent at ``PUBLISH_HZ``, as one JSON-ready dict.

:func:`console_state` reads a :class:`~testbed.live.session.LiveSession` (its operator station's
view, the vehicle's truth and control flags, the pilot, the link monitor, the image console and
the hub's counters) and builds the dict fresh each call; nothing here writes to the session.
Angles in degrees, positions NED [m], ages [s], latencies [ms].
"""

from __future__ import annotations

import math
import time
from collections import deque
from itertools import islice
from typing import TYPE_CHECKING, Any

from testbed.common.components import ActiveMode, Armed, FailsafeStatus, PositionSetpoint
from testbed.common.geometry import euler_from_quat
from testbed.live.monitor import finite_or_none, image_view, latency_ms
from testbed.vehicle.systems import Controllers

if TYPE_CHECKING:
    from testbed.live.session import LiveSession

__all__ = ["console_state"]

_DEG = 180.0 / math.pi


def console_state(self: LiveSession) -> dict[str, Any]:
    """The console's state now: JSON-ready, built fresh from ``self``'s nodes, recorder and hub."""
    now = self.env.now
    recorder = self.recorder
    station, vehicle = self.station, self.vehicle
    odometry = station.vehicle_odometry()
    world = station.world
    armed = next((a.armed for _, a in world.query1(Armed)), None)
    mode = next((m.mode.name.lower() for _, m in world.query1(ActiveMode)), None)
    truth = vehicle.truth
    ctl = vehicle.world.resource(Controllers)
    status = vehicle.world.get(ctl.vehicle, FailsafeStatus)
    self.monitor.update()
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
            "target": _target(self),
        },
        "pilot": {
            "sticks": [round(s, 3) for s in self.pilot.sticks],
            "taken": self.pilot.taken,
        },
        "link": {
            "uplink": self.monitor.direction("uplink", recorder.frames_decoded["uplink"]),
            "downlink": self.monitor.direction("downlink", recorder.frames_decoded["downlink"]),
            "command_lag_s": finite_or_none(lag),
            "command_age_s": finite_or_none(age),
            "odometry_age_s": finite_or_none(odometry_age),
            "simulated": self.medium is not None,
            "ber": None if self.medium is None else self.medium.config.ber,
            "gap_s": None if self.ipg is None else self.ipg.gap_after(13),
            "distance_m": self.distance_m,
            "outage": self.medium is not None and self.medium.in_outage(now, now),
            "timeline": list(self.monitor.timeline),
        },
        "image": _image_state(self, now),
        "console": {
            "inputs": self.hub.counters.as_dict(),
            "input_latency_ms": latency_ms(_newest(self.pilot.latencies_ns, 200)),
            "lateness_ms": latency_ms(_newest(self.lateness_ns, 1000)),
            "notes": list(self.hub.notes),
        },
        "events": [[round(e.t_s, 2), e.node, e.kind, e.detail] for e in recorder.events[-8:]],
    }
    return state


def _target(self: LiveSession) -> list[float] | None:
    """The go-to target the vehicle holds (its operator entity), or None."""
    world = self.vehicle.world
    target = world.get(self.vehicle.operator_entity, PositionSetpoint)
    return None if target is None else [round(v, 2) for v in target.position_ned_m]


def _image_state(self: LiveSession, now: float) -> dict[str, Any] | None:
    console = self.image_console
    images = self.vehicle_node.images
    if console is None or images is None:
        return None
    current = images.current
    coder = images.settings
    return {
        "view": image_view(console.view),
        "bytes": len(console.assembler.prefix()),
        "chunks": console.chunks_received,
        "completed": len(self.recorder.images.received),
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
