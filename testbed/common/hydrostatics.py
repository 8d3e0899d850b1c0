"""Hydrostatic constants both nodes use: the vehicle's pressure sensor and the MAVLink
endpoint's depth telemetry (one definition of ArduSub's pressure–depth relation).

ArduSub converts its external pressure sensor to depth as Δp / (9800 Pa/m · specific gravity)
(AP_Baro for water); the testbed's depth sensor reports depth that way, and a shore gateway that
knows only the depth reports the pressure that gives it back.
"""

from __future__ import annotations

__all__ = ["ARDUSUB_PA_PER_M", "SEA_LEVEL_PA", "STANDARD_GRAVITY_M_S2", "ardusub_pressure_pa"]

STANDARD_GRAVITY_M_S2 = 9.80665
"""Standard gravity [m/s²]."""
SEA_LEVEL_PA = 101325.0
"""Standard sea-level pressure [Pa]."""
ARDUSUB_PA_PER_M = 9800.0
"""ArduSub's ρg for specific gravity 1 [Pa/m]."""


def ardusub_pressure_pa(
    depth_m: float, spec_grav: float = 1.0, surface_pressure_pa: float = SEA_LEVEL_PA
) -> float:
    """The absolute pressure [Pa] from which ArduSub computes ``depth_m`` [m, positive down]:
    the inverse of its Δp / (9800·SG); the surface's pressure above the water."""
    return surface_pressure_pa + ARDUSUB_PA_PER_M * spec_grav * max(depth_m, 0.0)
