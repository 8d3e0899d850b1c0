"""The sensors' per-sample arithmetic, compiled by numba: IMU, pressure depth, position fix.

One implementation of each model (described in :mod:`.sensors`, whose classes keep the
configuration, the sample clocks and the draws, and call these). Each kernel writes a reading's
row as the frame store lays it out (:mod:`testbed.ecs.store`; the field order of the reading's
dataclass) and, when a value changed, the row's mark (:func:`~.row_kernels.put_row`); a sensor
sampled outside a world writes a scratch row of its own.

Noise comes from a block of standard normal draws (:class:`~.sensors.NormalDraws`): a kernel
takes its draws at ``cursor[0]`` and advances it, and returns False, having done nothing, when
the block holds too few (the caller then fetches more and calls again).

Row layouts (float64):

* ImuReading: time_s, quaternion_wxyz (4), rates_rad_s (3);
* DepthReading: time_s, pressure_pa, depth_m;
* PositionReading: time_s, position_ned_m (3);
* Odometry (:func:`odometry_rows`, the vehicle's own estimate from these readings): sampled_s,
  position_ned_m (3), quaternion_wxyz (4).

Units: seconds, radians, pascals, metres; quaternions ``(w, x, y, z)`` body → NED; rates body
FRD. The quaternion product is :mod:`testbed.common.geometry`'s own, compiled in
(:func:`~testbed.common.jit.refresh_stale_caches` keeps the disk cache in step with it).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba.extending import register_jitable

from testbed.common import geometry, jit
from testbed.common.geometry import Quaternion, Vec3, quat_multiply
from testbed.common.hydrostatics import ARDUSUB_PA_PER_M, SEA_LEVEL_PA, STANDARD_GRAVITY_M_S2
from testbed.vehicle import row_kernels
from testbed.vehicle.row_kernels import put_row

__all__ = [
    "ARDUSUB_PA_PER_M",
    "IMU_PARAMS_SIZE",
    "SEA_LEVEL_PA",
    "STANDARD_GRAVITY_M_S2",
    "baro_depth_m",
    "baro_pressure_pa",
    "depth_sample",
    "imu_sample",
    "odometry_rows",
    "position_sample",
    "put_position",
]


DECAY, INNOVATION, SIGMA_ROLL, SIGMA_PITCH, SIGMA_HEADING, SIGMA_GYRO = range(6)
IMU_PARAMS_SIZE = 6
"""The IMU's parameters: the attitude error's decay a and innovation b per sample, the roll,
pitch and heading error 1σ [rad] and the gyro noise 1σ [rad/s]."""


@register_jitable
def baro_pressure_pa(
    depth_m: float,
    water_density_kg_m3: float = 1000.0,
    surface_pressure_pa: float = SEA_LEVEL_PA,
    gravity_m_s2: float = STANDARD_GRAVITY_M_S2,
) -> float:
    """Absolute hydrostatic pressure [Pa] at ``depth_m`` (positive down; 0 above the surface)."""
    return surface_pressure_pa + water_density_kg_m3 * gravity_m_s2 * max(depth_m, 0.0)


@register_jitable
def baro_depth_m(
    pressure_pa: float, spec_grav: float = 1.0, surface_pressure_pa: float = SEA_LEVEL_PA
) -> float:
    """Depth [m, positive down] from absolute pressure, as ArduSub: Δp / (9800·spec_grav)."""
    return (pressure_pa - surface_pressure_pa) / (ARDUSUB_PA_PER_M * spec_grav)


@numba.njit(cache=True)
def imu_sample(
    draws: np.ndarray,
    cursor: np.ndarray,
    errors: np.ndarray,
    params: np.ndarray,
    quaternion_wxyz: Quaternion,
    rates_rad_s: Vec3,
    time_s: float,
    row: np.ndarray,
    mark: np.ndarray,
    tick: int,
) -> bool:  # pragma: no cover - compiled
    """One IMU reading (the model of :class:`~.sensors.Imu`) into an ImuReading row.

    Args:
        draws, cursor: the draws; six are taken (attitude errors, then gyro noise).
        errors: (3,) the roll, pitch and heading errors [rad], advanced in place.
        params: (:data:`IMU_PARAMS_SIZE`,) the model's parameters.
        quaternion_wxyz, rates_rad_s: the truth.
        time_s: the sample's time [s].
        row, mark, tick: the row, its mark (change tick and write count) and the tick to write.
    """
    i = cursor[0]
    if i + 6 > draws.size:
        return False
    n0, n1, n2 = draws[i], draws[i + 1], draws[i + 2]  # the attitude errors'
    n3, n4, n5 = draws[i + 3], draws[i + 4], draws[i + 5]  # the gyro noise
    cursor[0] = i + 6
    a, b = params[DECAY], params[INNOVATION]
    ex = a * errors[0] + b * params[SIGMA_ROLL] * n0
    ey = a * errors[1] + b * params[SIGMA_PITCH] * n1
    eh = a * errors[2] + b * params[SIGMA_HEADING] * n2
    errors[0], errors[1], errors[2] = ex, ey, eh
    # body roll/pitch error: rotation vector (ex, ey, 0) on the body axes
    angle = math.sqrt(ex * ex + ey * ey)
    if angle > 0.0:
        s = math.sin(0.5 * angle) / angle
        q_body = (math.cos(0.5 * angle), ex * s, ey * s, 0.0)
    else:
        q_body = (1.0, 0.0, 0.0, 0.0)
    q_heading = (math.cos(0.5 * eh), 0.0, 0.0, math.sin(0.5 * eh))
    w, x, y, z = quat_multiply(q_heading, quat_multiply(quaternion_wxyz, q_body))
    g = params[SIGMA_GYRO]
    p = rates_rad_s[0] + g * n3
    q = rates_rad_s[1] + g * n4
    r = rates_rad_s[2] + g * n5
    put_row(row, mark, tick, (float(time_s), w, x, y, z, p, q, r))
    return True


@numba.njit(cache=True)
def depth_sample(
    draws: np.ndarray,
    cursor: np.ndarray,
    params: np.ndarray,
    depth_m: float,
    time_s: float,
    row: np.ndarray,
    mark: np.ndarray,
    tick: int,
) -> bool:  # pragma: no cover - compiled
    """One pressure-depth reading (the model of :class:`~.sensors.DepthSensor`) into a
    DepthReading row; one draw. ``params``: water density [kg/m³], surface pressure [Pa],
    pressure noise 1σ [Pa], the firmware's specific gravity."""
    i = cursor[0]
    if i + 1 > draws.size:
        return False
    cursor[0] = i + 1
    surface = params[1]
    pressure = baro_pressure_pa(depth_m, params[0], surface, STANDARD_GRAVITY_M_S2)
    pressure += params[2] * draws[i]
    depth = baro_depth_m(pressure, params[3], surface)
    put_row(row, mark, tick, (float(time_s), pressure, depth))
    return True


@numba.njit(cache=True)
def position_sample(
    draws: np.ndarray,
    cursor: np.ndarray,
    noise_m: float,
    position_ned_m: Vec3,
    time_s: float,
    row: np.ndarray,
    mark: np.ndarray,
    tick: int,
) -> bool:  # pragma: no cover - compiled
    """One position fix (the true NED position [m] plus white noise of 1σ ``noise_m``) into a
    PositionReading row; three draws."""
    i = cursor[0]
    if i + 3 > draws.size:
        return False
    cursor[0] = i + 3
    x, y, z = position_ned_m
    put_row(
        row,
        mark,
        tick,
        (
            float(time_s),
            x + noise_m * draws[i],
            y + noise_m * draws[i + 1],
            z + noise_m * draws[i + 2],
        ),
    )
    return True


@numba.njit(cache=True)
def put_position(
    row: np.ndarray, mark: np.ndarray, tick: int, time_s: float, position_ned_m: Vec3
) -> None:  # pragma: no cover - compiled
    """A PositionReading row: its time [s] and NED position [m] (a position source's own, such
    as the navigation filter's estimate; :func:`~.row_kernels.put_row`)."""
    x, y, z = position_ned_m
    put_row(row, mark, tick, (float(time_s), float(x), float(y), float(z)))


@numba.njit(cache=True)
def odometry_rows(
    imu: np.ndarray,
    depth: np.ndarray,
    fix: np.ndarray,
    has_fix: bool,
    row: np.ndarray,
    mark: np.ndarray,
    tick: int,
) -> None:  # pragma: no cover - compiled
    """The vehicle's odometry from its readings' rows into an Odometry row: sampled at the
    later of the IMU's and the depth sensor's times, north and east from the position fix
    (0 without one), depth from the depth sensor, attitude from the IMU."""
    north, east = (fix[1], fix[2]) if has_fix else (0.0, 0.0)
    sampled = max(imu[0], depth[0])
    put_row(row, mark, tick, (sampled, north, east, depth[2], imu[1], imu[2], imu[3], imu[4]))


jit.refresh_stale_caches(
    (imu_sample, depth_sample, position_sample, odometry_rows, put_position),
    (geometry, jit, row_kernels),
)
