"""Pilots: who or what moves the operator's sticks — the seam every new pilot plugs into.

A :class:`Pilot` is sampled by the operator station once per operator frame
(:func:`~testbed.operator.station.sample_pilot`) and returns a :class:`PilotSample`: six stick
positions, or an attitude setpoint for setpoint-driven runs. The station turns that into the
intents the link carries; a pilot never touches the link or the vehicle. The packaged pilots
(:data:`PURE_PILOTS`) are pure functions of time, so observers of a run (the recorder) may
sample them again to know what the pilot was commanding at any instant; any other pilot (a
user's, which may keep state or draw random numbers; a live pilot returning what it holds now)
is sampled by the operator station alone, and observers see those samples through a
:class:`SampleHold`.

Here: :class:`ScriptedPilot` (smooth stick signals, the narrow-band paper's Fig. 5),
:class:`AttitudePilot` (the ECS paper's oscillating roll, pitch and yaw setpoints) and
:class:`SupervisorPilot` (supervised control: a timed list of GoTo goals — of the vehicle or of
its arm's end effector — and cancels for a vehicle that flies itself, the narrow-band paper's
"high level commands"). :class:`~testbed.operator.recorded_pilot.RecordedPilot` (the sticks of
a run's ``series.csv``, held) lives in its own module and is listed here among the pure ones. A
scenario configures them (:class:`~testbed.run.sections.PilotSection`); it does not implement
them.

Imports: ``config``, ``operator.recorded_pilot`` and the standard library only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, Protocol

from testbed.config import ConfigError, check, check_range
from testbed.operator.recorded_pilot import RecordedPilot

__all__ = [
    "GOAL_FRAMES",
    "PERIOD_RANGE_S",
    "PURE_PILOTS",
    "AttitudePilot",
    "GoalFrame",
    "GoalOrder",
    "GoalStep",
    "Pilot",
    "PilotError",
    "PilotSample",
    "SampleHold",
    "ScriptedPilot",
    "SineTerm",
    "Sticks",
    "SupervisorPilot",
    "is_pure",
]

Sticks = tuple[float, float, float, float, float, float]
"""(6,) stick positions in [−1, 1]: surge, sway, heave (+ down), roll, pitch, yaw."""

_NO_STICKS: Sticks = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

PERIOD_RANGE_S = (0.01, 1.0e6)
"""Accepted periods [s] of stick sine terms and attitude setpoints."""

GoalFrame = Literal["vehicle", "end_effector"]
"""What a supervised goal moves: the vehicle's body origin (a PositionSetpoint, a GoTo order)
or the manipulator arm's tool point (an EndEffectorSetpoint, an EndEffectorGoTo order)."""
GOAL_FRAMES: tuple[GoalFrame, ...] = ("vehicle", "end_effector")
"""The accepted :data:`GoalFrame` values; ``"vehicle"`` is the default."""


class PilotError(ConfigError, TypeError):
    """A pilot raised, or sampled what a pilot cannot give (not a :class:`PilotSample`, sticks
    that are not six finite positions in [−1, 1], an attitude or goal that is not finite): its
    bug, named with its class (and for a pilot of the user's its file, the call and its time,
    :class:`~testbed.operator.user_pilots.UserPilot`), in one line on the command line
    (``testbed: error: ...``, exit 2). A ValueError and a TypeError; one the pilot raised is
    caused by that exception (its traceback, for the Python API)."""


@dataclass(frozen=True, slots=True)
class GoalOrder:
    """A supervised order in force: go to a pose, or cancel the goal.

    Attributes:
        index: the order's place in the pilot's list (a new index is a new order).
        position_ned_m: (3,) goal [m], world NED, of the body origin (``frame = "vehicle"``)
            or of the arm's tool point (``"end_effector"``); None = cancel.
        yaw_deg: goal heading [deg, clockwise from north] of the vehicle or of the tool, or
            None to keep the current one.
        frame: what the goal moves (:data:`GoalFrame`).
    """

    index: int
    position_ned_m: tuple[float, float, float] | None
    yaw_deg: float | None = None
    frame: GoalFrame = "vehicle"


@dataclass(frozen=True, slots=True)
class PilotSample:
    """What the pilot asks for at one instant.

    Attributes:
        sticks: (6,) stick positions in [−1, 1]: surge, sway, heave, roll, pitch, yaw.
        attitude_deg: (3,) roll, pitch, yaw setpoint [deg] for setpoint-driven runs (the ECS
            paper's attitude experiment), or None when the pilot flies by sticks.
        goal: the supervised order in force (:class:`SupervisorPilot`), or None.
    """

    sticks: Sticks
    attitude_deg: tuple[float, float, float] | None = None
    goal: GoalOrder | None = None


class Pilot(Protocol):
    """Anything that can be asked, at an operator time, what it commands.

    A run's operator station calls :meth:`sample` once per operator frame, at increasing
    times. It need not be a pure function of ``t_s``: a pilot may keep state or draw from a
    random generator (seed it yourself for repeatable runs). Only a pilot that is a pure
    function of time (:func:`is_pure`: the packaged ones, :data:`PURE_PILOTS`, and any whose
    class sets ``pure_function_of_time = True``) is sampled again by the recorder at the
    vehicle's instants (the ``cmd_*`` columns: its continuous stick); for any other pilot the
    recorder holds the operator's own samples (:class:`SampleHold`), so it never advances the
    pilot's state and the run does not depend on the recording rate. ``signal_lag_s`` is
    measured against the ``cmd_*`` columns, so it means the pilot-to-vehicle delay only for a
    pure pilot; with held samples it leaves out the operator's sampling delay (up to one
    operator frame: 0.3 s on s100). ``metrics.json``'s ``signal_lag_reference`` says which.

    A pilot that flies by what it sees (a person at the console, a model of one) also defines
    ``see(odometry)``: before each sample, the station hands it the vehicle's
    :class:`~testbed.common.components.Odometry` the operator received since the last sample
    (once per arrival; ``sampled_s`` is the vehicle's time of the state, or over the teleop
    codec, whose wire carries no time, its arrival), never the vehicle's truth. Such a pilot
    depends on the run, so it is not pure.

    The station refuses a sample whose sticks are not six finite positions in [−1, 1]
    (:func:`~testbed.operator.station.check_sticks`: a ValueError naming the pilot's type and
    the axis), whatever codec carries them. A run calls a pilot that is not a packaged one
    through a :class:`~testbed.operator.user_pilots.UserPilot`: what its ``sample`` or ``see``
    raises, or a malformed sample, is a :class:`PilotError` naming it, the call and the time.
    """

    def sample(self, t_s: float) -> PilotSample:
        """What the pilot commands at operator time ``t_s`` [s]."""
        ...


@dataclass(frozen=True, slots=True)
class SineTerm:
    """One term ``amplitude · sin(2π τ / period_s + phase_rad)`` of a stick signal.

    Attributes:
        amplitude: stick units, |a| ≤ 1.
        period_s: period [s], in :data:`PERIOD_RANGE_S`.
        phase_rad: phase [rad] at the pilot's start, in [−2π, 2π].
    """

    amplitude: float
    period_s: float
    phase_rad: float = 0.0

    def __post_init__(self) -> None:
        check(abs(self.amplitude) <= 1.0, "amplitude", f"must be in [-1, 1], got {self.amplitude}")
        check_range(self.period_s, "period_s", *PERIOD_RANGE_S, "s")
        check_range(self.phase_rad, "phase_rad", -2.0 * math.pi, 2.0 * math.pi, "rad")

    def at(self, tau_s: float) -> float:
        """The term's value at ``tau_s`` [s] after the pilot's start."""
        return self.amplitude * math.sin(2.0 * math.pi * tau_s / self.period_s + self.phase_rad)


def _mix(terms: tuple[SineTerm, ...], tau_s: float) -> float:
    return min(1.0, max(-1.0, math.fsum(term.at(tau_s) for term in terms)))


def _sine(amplitude: float, period_s: float, tau_s: float) -> float:
    if amplitude == 0.0:
        return 0.0
    return amplitude * math.sin(2.0 * math.pi * tau_s / period_s)


@dataclass(frozen=True, slots=True)
class ScriptedPilot:
    """Smooth stick signals: each stick is ``clip(Σ terms, −1, 1)`` of ``τ = t − start_s``,
    zero before the start (Centelles et al., Fig. 5: a few slow sinusoids per axis).

    Attributes:
        start_s: when the pilot starts [s].
        x, y, z, yaw: surge, sway, heave (+ down) and yaw stick terms.
    """

    start_s: float = 0.0
    x: tuple[SineTerm, ...] = ()
    y: tuple[SineTerm, ...] = ()
    z: tuple[SineTerm, ...] = ()
    yaw: tuple[SineTerm, ...] = ()

    def sticks(self, t_s: float) -> tuple[float, float, float, float]:
        """Surge, sway, heave and yaw sticks in [−1, 1] at ``t_s`` [s] (zero before start)."""
        if t_s < self.start_s:
            return (0.0, 0.0, 0.0, 0.0)
        tau = t_s - self.start_s
        return (_mix(self.x, tau), _mix(self.y, tau), _mix(self.z, tau), _mix(self.yaw, tau))

    def sample(self, t_s: float) -> PilotSample:
        """The sticks at ``t_s`` [s]; roll and pitch sticks stay centred."""
        x, y, z, yaw = self.sticks(t_s)
        return PilotSample((x, y, z, 0.0, 0.0, yaw))


@dataclass(frozen=True, slots=True)
class AttitudePilot:
    """The ECS paper's attitude experiment: no sticks; roll, pitch and yaw setpoints
    ``A · sin(2π τ / T)`` [deg] of ``τ = t − start_s``, zero before the start (the defaults
    live in the scenario's pilot section).

    The operator updates the setpoint ``update_rate_hz`` times a second and holds it in
    between (the ECS paper's operator sent it at 40 Hz): the value at ``τ`` is the sine's at
    ``⌊τ·rate⌋ / rate``; an infinite rate follows the sine continuously.

    Attributes:
        start_s: when the pilot starts [s].
        roll_amplitude_deg, pitch_amplitude_deg, yaw_amplitude_deg: amplitudes ``A`` [deg].
        roll_period_s, pitch_period_s, yaw_period_s: periods ``T`` [s], > 0.
        update_rate_hz: how often the setpoint changes [Hz], > 0 (``math.inf``: continuously).
    """

    start_s: float
    roll_amplitude_deg: float
    roll_period_s: float
    pitch_amplitude_deg: float
    pitch_period_s: float
    yaw_amplitude_deg: float
    yaw_period_s: float
    update_rate_hz: float = math.inf

    def __post_init__(self) -> None:
        check(
            self.update_rate_hz > 0.0, "update_rate_hz", f"must be > 0, got {self.update_rate_hz}"
        )

    def attitude_deg(self, t_s: float) -> tuple[float, float, float]:
        """Roll, pitch and yaw setpoint [deg] at ``t_s`` [s] (zero before start), as last
        updated (see the class docstring)."""
        if t_s < self.start_s:
            return (0.0, 0.0, 0.0)
        tau = t_s - self.start_s
        rate = self.update_rate_hz
        if rate != math.inf:  # the last update instant; 1e-9 absorbs sums of float steps
            tau = math.floor(tau * rate + 1e-9) / rate
        return (
            _sine(self.roll_amplitude_deg, self.roll_period_s, tau),
            _sine(self.pitch_amplitude_deg, self.pitch_period_s, tau),
            _sine(self.yaw_amplitude_deg, self.yaw_period_s, tau),
        )

    def sample(self, t_s: float) -> PilotSample:
        """Centred sticks and the setpoint at ``t_s`` [s]."""
        return PilotSample(_NO_STICKS, self.attitude_deg(t_s))


MAX_GOAL_M = 300.0
"""Largest accepted ``|coordinate|`` of a goal [m]: the teleop codec's int16 centimetres."""


@dataclass(frozen=True, slots=True)
class GoalStep:
    """One entry of a supervisor's script: at ``t_s``, go to a pose or cancel.

    Attributes:
        t_s: operator time the order is given [s], ≥ 0.
        position_ned_m: (3,) goal [m], world NED, each in [−300, 300] (the GoTo order's int16
            cm), the depth (third) ≥ 0 (not above the surface); None with ``cancel``.
        yaw_deg: goal heading [deg], in [−360, 360]; None keeps the vehicle's (or the
            tool's) heading.
        cancel: cancel the goal in force, of either frame (the vehicle holds where it is).
        frame: ``"vehicle"`` (default: the goal is the body origin's, a GoTo order) or
            ``"end_effector"`` (the arm's tool point, an EndEffectorGoTo order); goals only.
    """

    t_s: float
    position_ned_m: tuple[float, float, float] | None = None
    yaw_deg: float | None = None
    cancel: bool = False
    frame: GoalFrame = "vehicle"

    def __post_init__(self) -> None:
        check_range(self.t_s, "t_s", 0.0, 1.0e6, "s")
        check(
            self.cancel == (self.position_ned_m is None),
            "position_ned_m",
            "a step is a goal (position_ned_m) or a cancel (cancel = true), not both or neither",
        )
        if self.position_ned_m is not None:
            for value in self.position_ned_m:
                check_range(value, "position_ned_m", -MAX_GOAL_M, MAX_GOAL_M, "m")
            depth = self.position_ned_m[2]
            check(
                depth >= 0.0,
                "position_ned_m",
                f"the depth (down, the third) must be ≥ 0 m (in the water), got {depth:g}",
            )
        if self.yaw_deg is not None:
            check_range(self.yaw_deg, "yaw_deg", -360.0, 360.0, "deg")
        check(
            self.frame in GOAL_FRAMES,
            "frame",
            f"must be one of {', '.join(map(repr, GOAL_FRAMES))}, got {self.frame!r}",
        )
        check(
            not self.cancel or self.frame == "vehicle",
            "frame",
            "not used with cancel = true (a cancel cancels the goal of either frame)",
        )


@dataclass(frozen=True, slots=True)
class SupervisorPilot:
    """Supervised control: centred sticks and, from each step's time on, its order in force.

    The operator station turns a new goal into a :class:`~testbed.common.components.
    PositionSetpoint` (a GoTo order on the teleop codec) — or, for an ``"end_effector"`` goal,
    an :class:`~testbed.common.components.EndEffectorSetpoint` (an EndEffectorGoTo order) —
    and a cancel into a :class:`~testbed.common.components.GoalCancel`; the vehicle's mission
    logic flies them.

    Attributes:
        steps: the orders, kept in time order (a stable sort of the given ones by ``t_s``).
    """

    steps: tuple[GoalStep, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "steps", tuple(sorted(self.steps, key=lambda step: step.t_s)))

    def sample(self, t_s: float) -> PilotSample:
        """Centred sticks and the latest step at or before ``t_s`` [s], if any."""
        goal = None
        for index, step in enumerate(self.steps):
            if step.t_s > t_s:
                break
            goal = GoalOrder(index, step.position_ned_m, step.yaw_deg, step.frame)
        return PilotSample(_NO_STICKS, None, goal)


PURE_PILOTS = (ScriptedPilot, AttitudePilot, SupervisorPilot, RecordedPilot)
"""The pilots whose ``sample(t)`` is a pure function of ``t`` (observers may sample them again)."""


def is_pure(pilot: object) -> bool:
    """Whether ``pilot.sample(t)`` is a pure function of ``t``, so observers may sample it
    again: a packaged pilot (:data:`PURE_PILOTS`), or a pilot whose class says so with
    ``pure_function_of_time = True`` — unless it watches the vehicle (has ``see``)."""
    if callable(getattr(pilot, "see", None)):  # it flies by what the run shows it
        return False
    return (
        isinstance(pilot, PURE_PILOTS) or getattr(type(pilot), "pure_function_of_time", 0) is True
    )


class SampleHold:
    """A pilot sampled by one caller, the operator station, with its samples held for observers.

    :meth:`sample` forwards to ``pilot`` and keeps what it returned; :attr:`held` is a
    :class:`Pilot` whose ``sample(t)`` returns the newest kept sample (centred sticks before the
    first) without calling ``pilot``: sample and hold at the operator's frames. In a run, whose
    clock only advances, the newest sample is the one taken at or before ``t``.

    Args:
        pilot: the pilot (any :class:`Pilot`, stateful or not).
    """

    def __init__(self, pilot: Pilot) -> None:
        self.pilot = pilot
        self._last = PilotSample(_NO_STICKS)
        self.held: Pilot = _Held(self)

    def sample(self, t_s: float) -> PilotSample:
        """The pilot's sample at ``t_s`` [s], kept for :attr:`held`."""
        self._last = self.pilot.sample(t_s)
        return self._last

    @property
    def last(self) -> PilotSample:
        """The newest sample taken (centred sticks before the first)."""
        return self._last


@dataclass(frozen=True, slots=True)
class _Held:
    """:attr:`SampleHold.held`: the newest sample, whatever ``t_s`` is asked."""

    hold: SampleHold

    def sample(self, t_s: float) -> PilotSample:
        return self.hold.last
