"""The plant's state at one instant: what :meth:`~testbed.vehicle.physics.Physics.state` returns.

:class:`BodyState` holds the vehicle's time [s], the position of its body origin CO [m] NED,
its attitude (quaternion body FRD → NED, and ZYX roll, pitch, yaw [rad]), its body velocity and
the last step's body acceleration at CO [m/s, rad/s; m/s², rad/s²] FRD, as read-only arrays.
Plain values: no pybullet, no physics here.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["BodyState", "frozen"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True, eq=False)
class BodyState:
    """The vehicle's state at one instant (arrays are read-only).

    Attributes:
        time_s: simulated time [s].
        position_ned: (3,) position of the body origin CO [m], NED.
        quaternion_wxyz: (4,) attitude, body FRD → NED.
        euler_rad: (3,) roll, pitch, yaw [rad], ZYX.
        nu: (6,) body velocity [u v w p q r] at CO [m/s, rad/s], FRD.
        nu_dot: (6,) body acceleration of the last step's model (contacts not included)
            [m/s², rad/s²], FRD.
    """

    time_s: float
    position_ned: FloatArray
    quaternion_wxyz: FloatArray
    euler_rad: FloatArray
    nu: FloatArray
    nu_dot: FloatArray


def frozen(values: Sequence[float] | FloatArray) -> FloatArray:
    """A read-only float copy of ``values`` (a :class:`BodyState` array)."""
    array = np.array(values, dtype=float)
    array.setflags(write=False)
    return array
