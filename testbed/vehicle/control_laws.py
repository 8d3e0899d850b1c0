"""Depth and attitude holds of the user's own: the laws' contracts and the check of what they
return.

A :class:`DepthLaw` or :class:`AttitudeLaw` replaces the packaged PID hold of its axis
(:class:`~testbed.vehicle.control.DepthController`,
:class:`~testbed.vehicle.control.AttitudeController`) wherever that hold would fly: in depth
hold, stabilize, GUIDED and the link failsafe's hold. It is put in the vehicle's
:class:`~testbed.vehicle.resources.Controllers` (``depth_law``, ``attitude_law``) before the
first frame (``vehicle.controllers.depth_law = MyLaw()`` in ``run_scenario``'s
``vehicle_setup``), and :func:`~testbed.vehicle.systems.control_depth` and
:func:`~testbed.vehicle.systems.control_attitude` call it once per frame with the frame's
sensor readings and targets only: never the physics truth.

What must not live here: the packaged laws (``control.py``), the systems that call these
(``systems.py``), and the loading of a user's file (``testbed.run.plugins``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Protocol

from testbed.common.components import ControlTargets, DepthReading, ImuReading
from testbed.config import ConfigError, described_class, shown_error, shown_line

__all__ = ["AttitudeLaw", "ControlLawError", "DepthLaw", "call_law", "checked_vector"]

Vec3 = tuple[float, float, float]


class DepthLaw(Protocol):
    """A depth hold: the depth target and the sensors' readings → a body force.

    ``update`` is called once per vehicle frame while the hold flies (armed, in depth hold,
    GUIDED or the failsafe's hold), ``reset`` on every frame it does not (disarmed, MANUAL,
    STABILIZE, or before the first readings), so a law that integrates starts clean each time
    the hold engages.
    """

    def reset(self) -> None:
        """Forget any state (the hold is not flying)."""

    def update(
        self, target: ControlTargets, depth: DepthReading, imu: ImuReading, dt_s: float
    ) -> Sequence[float]:
        """One control step.

        Args:
            target: the targets held: ``depth_m`` [m, + down] (trimmed by the heave stick,
                ≥ 0.15 m), ``quaternion_wxyz`` the attitude target (body → NED).
            depth: the depth sensor's last reading (``time_s`` [s], vehicle time: the sensor
                samples at its own rate, so between samples the same reading comes again;
                ``depth_m`` [m, + down]; ``pressure_pa`` [Pa]).
            imu: the IMU's last reading (``quaternion_wxyz`` body → NED, ``rates_rad_s``
                (p, q, r) [rad/s], FRD).
            dt_s: time since the previous frame [s], > 0.

        Returns:
            (3,) body force (X, Y, Z) [N], FRD: rotate a world-down force into the body
            with the IMU's attitude, as the packaged hold does.
        """
        ...


class AttitudeLaw(Protocol):
    """An attitude hold: the attitude target and the IMU's reading → a body torque.

    Called while the attitude hold flies (armed and not MANUAL, or the failsafe's hold);
    ``reset`` otherwise.
    """

    def reset(self) -> None:
        """Forget any state (the hold is not flying)."""

    def update(
        self,
        target: ControlTargets,
        imu: ImuReading,
        dt_s: float,
        axes: tuple[bool, bool, bool],
    ) -> Sequence[float]:
        """One control step.

        Args:
            target: the targets held: ``quaternion_wxyz`` (body → NED; the yaw stick turns it
                at the trim rate), ``depth_m``.
            imu: the IMU's last reading (attitude body → NED, body rates [rad/s], FRD).
            dt_s: time since the previous frame [s], > 0.
            axes: which of roll, pitch, yaw the thruster layout can torque; the torque on an
                axis it cannot is set to 0 after the call.

        Returns:
            (3,) body torque (K, M, N) [N·m], FRD.
        """
        ...


class ControlLawError(ConfigError, ValueError):
    """A law of the user's own raised, or returned what a hold cannot apply (not three finite
    numbers): its bug, named with its class and file, in one line on the command line
    (``testbed: error: ...``, exit 2). A ValueError; one the law raised is caused by that
    exception (its traceback, for the Python API)."""


def call_law(law: object, role: str, method: str, *args: object) -> object:
    """``law.<method>(*args)``: what the law returned.

    Args:
        law: a :class:`DepthLaw` or :class:`AttitudeLaw` of the user's.
        role: ``"depth law"`` or ``"attitude law"``, for the message.
        method: ``"reset"`` or ``"update"``.
        args: the call's arguments.

    Raises:
        ControlLawError: the call raised an ``Exception`` (``Type: message``, naming the law's
            role, class and file and the method); an interrupt or ``sys.exit`` passes unchanged.
    """
    try:
        return getattr(law, method)(*args)
    except Exception as error:
        raise ControlLawError(
            f"{role} {described_class(law)}: {method} raised {shown_error(error)}"
        ) from error


def checked_vector(law: object, value: object, what: str) -> Vec3:
    """``value`` as three floats, checked finite.

    Args:
        law: the law that returned it (named in the message).
        value: what its ``update`` returned.
        what: ``"depth law's force [N]"`` or the like, for the message.

    Raises:
        ControlLawError: ``value`` is not a sequence of three finite real numbers.
    """
    finite = False
    if not isinstance(value, (str, bytes)):
        try:
            x, y, z = (float(v) for v in value)  # type: ignore[attr-defined]  # checked here
        except (TypeError, ValueError):
            pass
        else:
            finite = math.isfinite(x) and math.isfinite(y) and math.isfinite(z)
    if not finite:
        shown = shown_line(value)
        raise ControlLawError(
            f"{described_class(law)}: update returned {shown}: expected the {what} as three finite "
            "numbers"
        )
    return (x, y, z)
