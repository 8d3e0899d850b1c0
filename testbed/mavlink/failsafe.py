"""ArduSub's pilot-input and GCS failsafes (``failsafe.cpp``), acting through the endpoint.

Pilot input (FS_PILOT_INPUT 0 off, 1 warn, 2 disarm; FS_PILOT_TIMEOUT [s]): when no accepted
MANUAL_CONTROL or RC_CHANNELS_OVERRIDE has come for the timeout (counted from boot, as
ArduSub's timer is), the failsafe triggers once: STATUSTEXT "Lost manual control", the sticks
go neutral (a neutral MovementCommand) and, with action 2, a disarm request. The next accepted
pilot input clears it.

GCS (FS_GCS_ENABLE 0 off, 1 warn, 2 disarm, 3 depth hold, 4 surface; FS_GCS_TIMEOUT [s]):
only once a heartbeat or pilot input from SYSID_MYGCS has been seen; when none for the
timeout, STATUSTEXT "MYGCS: <id>, heartbeat lost" (again every 30 s while lost) and, if armed
and not yet triggered, the action: disarm; ALT_HOLD; or "surface" — the simulator has no
SURFACE mode, so depth hold with a 0 m depth target, which rises to the surface. The mode is
not restored when the GCS returns; the failsafe clears.

Either active makes the heartbeat's system_status CRITICAL.
"""

from __future__ import annotations

from collections import Counter
from typing import TYPE_CHECKING

from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.common.components import ControlMode

if TYPE_CHECKING:
    from testbed.mavlink.endpoint import VehicleEndpoint
    from testbed.mavlink.vehicle_snapshot import VehicleSnapshot

__all__ = ["GCS_WARNING_PERIOD_S", "FailsafeMonitor"]

GCS_WARNING_PERIOD_S = 30.0
"""Repeat period of the GCS-lost warning [s]."""


class FailsafeMonitor:
    """The two failsafes' timers and states (module docstring).

    Attributes:
        pilot_input: the pilot-input failsafe is active.
        gcs: the GCS failsafe is active.
        triggered: how often each triggered (``pilot_input``, ``gcs``).
    """

    def __init__(self) -> None:
        self.pilot_input = False
        self.gcs = False
        self.triggered: Counter[str] = Counter()
        self._last_pilot_s = 0.0
        self._last_gcs_s: float | None = None
        self._last_warning_s: float | None = None

    @property
    def active(self) -> bool:
        """Any failsafe active."""
        return self.pilot_input or self.gcs

    def pilot_seen(self, now_s: float) -> None:
        """An accepted pilot input at ``now_s`` [s]."""
        self._last_pilot_s = now_s
        self.pilot_input = False

    def gcs_seen(self, now_s: float) -> bool:
        """A heartbeat or pilot input from the GCS at ``now_s`` [s]; True if that ended an
        active GCS failsafe."""
        self._last_gcs_s = now_s
        cleared = self.gcs
        self.gcs = False
        return cleared

    def check(self, endpoint: VehicleEndpoint, snapshot: VehicleSnapshot, now_s: float) -> None:
        """Trigger what is due at ``now_s`` [s] (call once per update)."""
        self._check_pilot(endpoint, snapshot, now_s)
        self._check_gcs(endpoint, snapshot, now_s)

    def _check_pilot(
        self, endpoint: VehicleEndpoint, snapshot: VehicleSnapshot, now_s: float
    ) -> None:
        params = endpoint.params
        action = int(params["FS_PILOT_INPUT"])
        if action == 0:
            self.pilot_input = False
            return
        if now_s < self._last_pilot_s + params["FS_PILOT_TIMEOUT"] or self.pilot_input:
            return
        self.pilot_input = True
        self.triggered["pilot_input"] += 1
        endpoint.statustext(mav.MAV_SEVERITY_CRITICAL, "Lost manual control")
        endpoint.rc.neutral()
        endpoint.write_sticks(now_s)
        if action == 2 and snapshot.armed:
            endpoint.request_arm(False, now_s)

    def _check_gcs(
        self, endpoint: VehicleEndpoint, snapshot: VehicleSnapshot, now_s: float
    ) -> None:
        params = endpoint.params
        action = int(params["FS_GCS_ENABLE"])
        if (action == 0 and not self.gcs) or self._last_gcs_s is None:
            return
        if now_s - self._last_gcs_s < params["FS_GCS_TIMEOUT"]:
            self.gcs = False
            return
        last = self._last_warning_s
        if last is None or now_s - last > GCS_WARNING_PERIOD_S:
            self._last_warning_s = now_s
            endpoint.statustext(
                mav.MAV_SEVERITY_WARNING, f"MYGCS: {endpoint.gcs_system_id}, heartbeat lost"
            )
        if self.gcs or not snapshot.armed:
            return
        self.gcs = True
        self.triggered["gcs"] += 1
        if action == 2:
            endpoint.request_arm(False, now_s)
        elif action == 3:
            endpoint.request_mode(ControlMode.DEPTH_HOLD)
        elif action == 4:
            endpoint.request_mode(ControlMode.DEPTH_HOLD)
            endpoint.request_depth(0.0)
