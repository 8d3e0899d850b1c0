"""A pilot of the user's, checked where it is called: what it raises or returns is its bug.

A pilot of the user's own (a scenario's ``kind = "python"`` factory, or ``run_scenario(pilot=...)``)
is the user's input, like a link model or a control law of theirs. :class:`UserPilot` wraps it
where a run calls it: an exception its ``sample`` or ``see`` raises, or a sample a run cannot
fly (:func:`sample_problem`: not a :class:`~testbed.operator.pilots.PilotSample`, sticks that
are not six finite positions in [−1, 1], an attitude or a goal that is not finite), is a
:class:`~testbed.operator.pilots.PilotError` naming the pilot's class and file, the call and
its time, and the error: ``pilot Sleepy (/home/me/pilots.py): sample(12.3) raised ValueError:
fell asleep``. Every mode reports such a ConfigError that ends a run part way as one line,
exit 2, keeping what ran. One the pilot raised is caused by that exception (its traceback, for
the Python API).

The packaged pilots (:data:`~testbed.operator.pilots.PURE_PILOTS`) are not wrapped: their
samples are built from a checked scenario, and their frame path stays as it was.

Imports: ``config``, ``common``, ``operator.pilots`` and the standard library only.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from testbed.common.components import Odometry
from testbed.config import described_class, shown_error, shown_line
from testbed.operator.pilots import GOAL_FRAMES, GoalOrder, Pilot, PilotError, PilotSample

__all__ = ["STICK_AXES", "UserPilot", "sample_problem", "stick_problem"]

STICK_AXES = ("surge", "sway", "heave", "roll", "pitch", "yaw")
"""The names of the six sticks, in :data:`~testbed.operator.pilots.Sticks` order."""


def stick_problem(sticks: object) -> str | None:
    """What is wrong with a sample's sticks, or None when they are six finite positions in
    [−1, 1] (±1 is full stick)."""
    try:
        count = len(sticks)  # type: ignore[arg-type]
    except TypeError:
        return f"sticks must be six numbers, got {shown_line(sticks)}"
    if count != len(STICK_AXES):
        return f"{count} sticks sampled, expected 6"
    for axis, value in zip(STICK_AXES, sticks, strict=True):  # type: ignore[call-overload]
        try:
            ok = -1.0 <= float(value) <= 1.0  # a NaN fails the comparison
        except (TypeError, ValueError):
            ok = False
        if not ok:
            return f"{axis} stick must be a finite number in [-1, 1], got {shown_line(value)}"
    return None


def _time(t_s: float) -> str:
    """A time [s] for a message: its repr to the microsecond (``2.0``, ``12.3``)."""
    try:
        return repr(round(float(t_s), 6))
    except (TypeError, ValueError, OverflowError):
        return repr(t_s)


def _finite(value: object, count: int) -> bool:
    """Whether ``value`` is ``count`` finite numbers (a tuple or list)."""
    if not isinstance(value, tuple | list) or len(value) != count:
        return False
    try:
        return all(math.isfinite(float(v)) for v in value)
    except (TypeError, ValueError):
        return False


def _goal_problem(goal: object) -> str | None:
    if not isinstance(goal, GoalOrder):
        return f"goal must be None or a GoalOrder, got {shown_line(goal)}"
    if not isinstance(goal.index, int) or isinstance(goal.index, bool):
        return f"goal's index must be an integer, got {shown_line(goal.index)}"
    if goal.position_ned_m is not None and not _finite(goal.position_ned_m, 3):
        return (
            "goal's position_ned_m must be None or three finite numbers [m], got "
            f"{shown_line(goal.position_ned_m)}"
        )
    if goal.yaw_deg is not None and not _finite((goal.yaw_deg,), 1):
        shown = shown_line(goal.yaw_deg)
        return f"goal's yaw_deg must be None or a finite angle [deg], got {shown}"
    if goal.frame not in GOAL_FRAMES:
        return f"goal's frame must be one of {GOAL_FRAMES}, got {shown_line(goal.frame)}"
    return None


def sample_problem(sample: object) -> str | None:
    """What a run cannot fly in a pilot's sample, or None.

    Returns:
        The problem (``got a tuple, not a PilotSample ...``, ``surge stick must be ...``), or
        None for a :class:`PilotSample` of six finite sticks
        in [−1, 1], an attitude of None or three finite angles, a goal of None or a
        :class:`GoalOrder` of finite numbers in a known frame.
    """
    if not isinstance(sample, PilotSample):
        return f"got a {type(sample).__name__}, not a PilotSample (testbed.operator.pilots)"
    problem = stick_problem(sample.sticks)
    if problem is None and sample.attitude_deg is not None and not _finite(sample.attitude_deg, 3):
        problem = (
            "attitude_deg must be None or three finite angles [deg], got "
            f"{shown_line(sample.attitude_deg)}"
        )
    if problem is None and sample.goal is not None:
        problem = _goal_problem(sample.goal)
    return problem


class UserPilot:
    """A pilot of the user's, each call checked (module docstring).

    Args:
        pilot: the user's pilot (an object with ``sample(t_s) -> PilotSample``, and perhaps
            ``see(odometry)``).

    Attributes:
        pilot: the user's pilot.
        name: ``pilot QualifiedName (its file)``, for messages.
        see: the checked ``see`` when the user's pilot has one, else None (the operator
            station shows the vehicle only to a pilot with a callable ``see``).
    """

    __slots__ = ("name", "pilot", "see")

    def __init__(self, pilot: Pilot) -> None:
        self.pilot = pilot
        self.name = f"pilot {described_class(pilot)}"
        see = getattr(pilot, "see", None)
        self.see: Callable[[Odometry], None] | None = self._see if callable(see) else None

    def sample(self, t_s: float) -> PilotSample:
        """The user's pilot's sample at operator time ``t_s`` [s].

        Raises:
            PilotError: its ``sample`` raised an ``Exception`` (caused by it), or returned
                what :func:`sample_problem` refuses; an interrupt or ``sys.exit`` passes.
        """
        try:
            sample = self.pilot.sample(t_s)
        except Exception as error:
            raise PilotError(
                f"{self.name}: sample({_time(t_s)}) raised {shown_error(error)}"
            ) from error
        problem = sample_problem(sample)
        if problem is not None:
            raise PilotError(f"{self.name}: sample({_time(t_s)}): {problem}")
        return sample

    def _see(self, odometry: Odometry) -> None:
        """Show the user's pilot the vehicle's odometry (its ``see``).

        Raises:
            PilotError: ``see`` raised an ``Exception`` (caused by it).
        """
        try:
            self.pilot.see(odometry)  # type: ignore[attr-defined]
        except Exception as error:
            raise PilotError(
                f"{self.name}: see(odometry of {_time(odometry.sampled_s)} s) raised "
                f"{shown_error(error)}"
            ) from error
