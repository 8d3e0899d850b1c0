"""The sections of a scenario file, each a frozen dataclass that checks its own values:
``[link]`` options (:class:`LinkSection`), ``[operator]``, ``[pilot]`` (the pilot's settings;
the pilots themselves live in :mod:`testbed.operator.pilots`), ``[vehicle.control]`` (the holds
of the user's own, :class:`ControlLawsSection`), ``[faults]`` and ``[metrics]``.
A failed check raises :class:`~testbed.config.FieldError` naming the field; the loader
(:mod:`testbed.run.scenario`) turns it into the one-line error naming the file and dotted key.
``[vehicle]`` is :class:`~testbed.vehicle.vehicle_config.VehicleConfig`, ``[images]``
:class:`~testbed.run.images.ImagesSection`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Literal

from testbed.channel import (
    TELEROBOTICS_2018,
    TELEROBOTICS_2019,
    TELEROBOTICS_2021,
    Fixed,
    IpgPolicy,
    LinkConfig,
)
from testbed.common.components import ControlMode
from testbed.config import ConfigError, FieldError, check, check_range, check_ranges
from testbed.operator.pilots import (
    PERIOD_RANGE_S,
    AttitudePilot,
    GoalStep,
    Pilot,
    ScriptedPilot,
    SineTerm,
    SupervisorPilot,
)
from testbed.operator.recorded_pilot import RecordedPilot, load_recorded_pilot
from testbed.protocol import OPERATOR_HEADER_SIZE, ORDER_TYPES, Move, frame_overhead
from testbed.run.metrics import SIGNAL_LAG_WINDOW_S
from testbed.run.plugins import check_target

ORDER_FRAME_BYTES = frame_overhead() + OPERATOR_HEADER_SIZE + Move.BODY_SIZE
"""A move order's frame [B] (13 with the default framing): the token gap rules size on it."""

LONGEST_ORDER_FRAME_BYTES = (
    frame_overhead() + OPERATOR_HEADER_SIZE + max(order.BODY_SIZE for order in ORDER_TYPES.values())
)
"""The longest order's frame [B] (16: an ``ImageSettings``, a ``GoTo``)."""

__all__ = [
    "MAX_DURATION_S",
    "ControlLawsSection",
    "FaultsSection",
    "LinkOutage",
    "LinkSection",
    "MetricsSection",
    "OperatorSection",
    "PilotSection",
    "SineTerm",
    "ThrusterFault",
    "check_finite",
    "check_non_negative",
    "check_positive",
    "check_rate",
    "check_time",
]

_IPG_CONSTANTS: dict[str, IpgPolicy] = {
    "telerobotics-2018": TELEROBOTICS_2018,
    "telerobotics-2019": TELEROBOTICS_2019,
    "telerobotics-2021": TELEROBOTICS_2021,
}


MAX_DURATION_S = 86400.0
"""Longest accepted scenario [s] (one simulated day) and so the bound of every time in one:
s100-teleop-v1 runs at ≈ 90× real time, so a day takes ≈ 16 min of wall time and its 20 Hz
series holds 1.7 M rows (≈ 0.45 GB)."""
RATE_RANGE_HZ = (1e-3, 1000.0)
"""Accepted send, setpoint and recording rates [Hz]: at most one event a millisecond, at least
one every ≈ 17 min."""
MAX_OPERATOR_DISTANCE_M = 10000.0
"""Largest accepted ``|coordinate|`` [m] of the operator's modem."""
MAX_GAP_S = 60.0
"""Largest accepted fixed inter-packet gap [s]."""
MAX_DEPTH_M = 1000.0
"""Deepest accepted depth setpoint [m]."""
MAX_STUCK_FORCE_N = 100.0
"""Largest accepted ``|value|`` of a stuck thruster [N]: above the T200's 65.9 N at 20 V."""


def check_time(value: float, key: str) -> None:
    """Field check: ``value`` is a time in a run, in [0, :data:`MAX_DURATION_S`] s."""
    check_range(value, key, 0.0, MAX_DURATION_S, "s")


def check_rate(value: float, key: str) -> None:
    """Field check: ``value`` is a rate in :data:`RATE_RANGE_HZ`."""
    check_range(value, key, *RATE_RANGE_HZ, "Hz")


def check_finite(value: float, key: str) -> None:
    """Field check: ``value`` is finite."""
    check(math.isfinite(value), key, f"must be finite, got {value}")


def check_positive(value: float, key: str) -> None:
    """Field check: ``value`` is finite and > 0."""
    check(value > 0.0 and math.isfinite(value), key, f"must be > 0 and finite, got {value}")


def check_non_negative(value: float, key: str) -> None:
    """Field check: ``value`` is finite and ≥ 0."""
    check(value >= 0.0 and math.isfinite(value), key, f"must be ≥ 0 and finite, got {value}")


# --- sections ----------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True, kw_only=True)
class LinkSection:
    """The link between operator and vehicle.

    Attributes:
        preset: channel preset name (:func:`testbed.channel.preset_names`) or the path of a
            ``.toml`` preset file of the user's.
        channel: the preset with every other key of the ``[link]`` table applied over it.
        codec: ``"teleop"`` (the paper's compact orders and replies), ``"changeset"`` (the ECS
            paper's full change-set sync), ``"mavlink-raw"`` (MAVLink itself, the baseline) or
            ``"mavlink-hl"`` (MAVLink on a high-latency link: HIGH_LATENCY2).
        mac: ``"token"`` (the operator is master, the vehicle answers each frame) or ``"free"``
            (each node sends at its own rate). A scenario's default follows the codec: token
            passing for ``teleop``, whose vehicle only answers orders, free access for the
            others, whose vehicles send on their own; the other pairings are refused.
        ipg: the token master's inter-packet-gap policy.
        ipg_s: the gap [s] when ``ipg == "fixed"``, in (0, 60].
        uplink_rate_hz: operator send rate [Hz] when ``mac == "free"`` or
            ``codec == "changeset"``, in [1e-3, 1000].
        downlink_rate_hz: vehicle send rate [Hz], same condition and domain.
        snapshot_period_s: change-set codec: every this many seconds a node sends its full
            owned state instead of the changes alone, so a peer that lost a payload resyncs
            [s], in [0, 86400]; 0 = never.
        operator_position_ned_m: (3,) the operator's modem [m], world NED, each in
            [−1e4, 1e4]; the vehicle's modem moves with the vehicle.
        model: a link model of the user's own, ``"FILE.py:NAME"`` or ``"MODULE:NAME"``: the
            callable called as ``NAME(channel, **model_args)`` for each run
            (:mod:`testbed.run.plugins`); "" = the preset's own model.
        model_args: the model factory's keyword arguments (only with ``model``).
    """

    preset: str = "s100"
    channel: LinkConfig
    codec: Literal["teleop", "changeset", "mavlink-raw", "mavlink-hl"] = "teleop"
    mac: Literal["token", "free"] = "token"
    ipg: Literal["fixed", "telerobotics-2018", "telerobotics-2019", "telerobotics-2021"] = (
        "telerobotics-2021"
    )
    ipg_s: float = 0.6
    uplink_rate_hz: float = 50.0
    downlink_rate_hz: float = 100.0
    snapshot_period_s: float = 5.0
    operator_position_ned_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    model: str = ""
    model_args: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        check_range(self.ipg_s, "ipg_s", 0.0, MAX_GAP_S, "s", low_open=True)
        if self.model:
            problem = check_target(self.model)
            check(problem is None, "model", problem or "")
        check(not self.model_args or bool(self.model), "model_args", "only used with link.model")
        check_time(self.snapshot_period_s, "snapshot_period_s")
        check_rate(self.uplink_rate_hz, "uplink_rate_hz")
        check_rate(self.downlink_rate_hz, "downlink_rate_hz")
        limit = MAX_OPERATOR_DISTANCE_M
        check_ranges(self.operator_position_ned_m, "operator_position_ned_m", -limit, limit, "m")

    @property
    def ipg_policy(self) -> IpgPolicy:
        """The token master's gap policy: ``Fixed(ipg_s)`` or a ``TELEROBOTICS_*`` constant."""
        if self.ipg == "fixed":
            return Fixed(self.ipg_s)
        return _IPG_CONSTANTS[self.ipg]

    @property
    def signal_lag_window_s(self) -> float:
        """Upper end of the stick-lag search [s]: twice the closed-form worst lag of a clean
        link, one order period plus one order's delivery (:meth:`delivery_s`, propagation over
        ``max_range_m`` when finite), and never less than
        :data:`~testbed.run.metrics.SIGNAL_LAG_WINDOW_S`."""
        reach_m = self.channel.max_range_m
        delivery_s = self.delivery_s(ORDER_FRAME_BYTES, reach_m if math.isfinite(reach_m) else None)
        if self.mac == "token":
            period_s = self.ipg_policy.gap_after(ORDER_FRAME_BYTES)
        else:
            period_s = 1.0 / self.uplink_rate_hz
        return max(SIGNAL_LAG_WINDOW_S, 2.0 * (period_s + delivery_s))

    def delivery_s(self, frame_bytes: int, distance_m: float | None) -> float:
        """One frame's delivery on a clean, idle link [s]: each packet's intrinsic delay and
        airtime, the queue gaps between the packets, and propagation over ``distance_m`` [m]
        (None: left out)."""
        channel = self.channel
        packet = channel.packet_bytes or frame_bytes
        packets = math.ceil(frame_bytes / packet)
        return (
            packets * (channel.intrinsic_delay_s + channel.airtime_s(packet))
            + (packets - 1) * channel.queue_gap_s
            + (0.0 if distance_m is None else channel.propagation.delay_s(distance_m))
        )

    def token_round_trip_s(
        self, order_frame_bytes: int, reply_frame_bytes: int, distance_m: float
    ) -> float:
        """From an order's start to the end of its reply's arrival on a clean link [s]: the
        order's delivery, the vehicle's queue gap (it answers once the order is in) and the
        reply's delivery, both over ``distance_m`` [m]. The token master's gap after that order
        must be at least this, or its next order goes out while the reply is still on its way
        (a collision in half duplex, or a request that misses the reply's chunk)."""
        return (
            self.delivery_s(order_frame_bytes, distance_m)
            + self.channel.queue_gap_s
            + self.delivery_s(reply_frame_bytes, distance_m)
        )

    @property
    def rates_used(self) -> bool:
        """Whether the nodes send at ``uplink_rate_hz`` / ``downlink_rate_hz``."""
        return self.mac == "free" or self.codec == "changeset"


OPERATOR_MODES = {
    "manual": ControlMode.MANUAL,
    "stabilize": ControlMode.STABILIZE,
    "depth_hold": ControlMode.DEPTH_HOLD,
    "guided": ControlMode.GUIDED,
}
"""A scenario's ``operator.mode`` names → the control modes the operator asks for."""


@dataclass(frozen=True, slots=True)
class OperatorSection:
    """What the operator requests at start.

    Attributes:
        mode: control mode requested at start (:data:`OPERATOR_MODES`). ``"guided"`` (ArduSub's
            GUIDED) needs a position fix (``vehicle.sensors.position`` or a navigation): with
            no goal the vehicle holds its stopping point until a goal arrives (a
            ``supervisor`` pilot's); sticks are ignored.
        arm_at_s: when the operator requests arming [s], in [0, duration_s).
        depth_m: depth setpoint [m, positive down] sent at start (``depth_hold`` only, over the
            change-set codec: the teleop and MAVLink orders carry none), in [0, 1000]; None =
            hold the depth at arming.
        precision: precision (fine) stick mode.
    """

    mode: Literal["manual", "stabilize", "depth_hold", "guided"] = "depth_hold"
    arm_at_s: float = 0.0
    depth_m: float | None = None
    precision: bool = False

    def __post_init__(self) -> None:
        check_time(self.arm_at_s, "arm_at_s")
        if self.depth_m is not None:
            check_range(self.depth_m, "depth_m", 0.0, MAX_DEPTH_M, "m")
            check(
                self.mode == "depth_hold",
                "depth_m",
                f"only used when mode = 'depth_hold', got mode {self.mode!r}",
            )

    @property
    def control_mode(self) -> ControlMode:
        """The control mode :attr:`mode` names."""
        return OPERATOR_MODES[self.mode]


_STICK_AXES = ("x", "y", "z", "yaw")
_ATTITUDE_AMPLITUDES = ("roll_amplitude_deg", "pitch_amplitude_deg", "yaw_amplitude_deg")


@dataclass(frozen=True, slots=True)
class PilotSection:
    """The scripted operator's settings: smooth stick signals or oscillating attitude setpoints
    (the pilots themselves are :class:`~testbed.operator.pilots.ScriptedPilot` and
    :class:`~testbed.operator.pilots.AttitudePilot`; :meth:`pilot` builds the one configured).

    ``kind = "scripted"``: each stick is ``clip(Σ terms, −1, 1)`` of the time ``τ = t − start_s``
    since the pilot started, zero before (Centelles et al., Fig. 5: a few slow sinusoids per
    axis). ``kind = "attitude"``: the ECS paper's experiment, no sticks; roll, pitch and yaw
    setpoints ``A · sin(2π τ / T)`` [deg], updated ``setpoint_rate_hz`` times a second and held
    in between (the operator sends the held value as AttitudeSetpoint at its own rate).
    ``kind = "supervisor"``: supervised control of a vehicle with ``[vehicle.autonomy]``, no
    sticks; ``goals`` is a timed list of GoTo goals and cancels
    (:class:`~testbed.operator.pilots.SupervisorPilot`). ``kind = "python"``: a pilot of the
    user's own, made for each run by the callable ``factory`` names with ``args``
    (:mod:`testbed.run.plugins`). ``kind = "recorded"``: the sticks of an earlier run played back
    open loop (:class:`~testbed.operator.recorded_pilot.RecordedPilot`): the ``cmd_*`` columns of
    its ``series.csv`` (``file``), each row held until the next, centred sticks before the first
    row and after the last, ``shift_s`` later than recorded; the file is read and checked once,
    here. Each kind rejects the others' non-zero settings.

    Attributes:
        kind: ``"scripted"``, ``"attitude"``, ``"supervisor"``, ``"python"`` or ``"recorded"``.
        start_s: when the pilot starts [s], in [0, duration_s) (not for ``"python"`` or
            ``"recorded"``, which the loader refuses it with).
        x, y, z, yaw: surge, sway, heave (+ down) and yaw stick terms (amplitude in [−1, 1],
            period in [0.01, 1e6] s, phase in [−2π, 2π] rad).
        roll_amplitude_deg, pitch_amplitude_deg: setpoint amplitudes [deg], |A| ≤ 89.9.
        yaw_amplitude_deg: yaw setpoint amplitude [deg], |A| ≤ 180.
        roll_period_s, pitch_period_s, yaw_period_s: setpoint periods [s], in [0.01, 1e6].
        setpoint_rate_hz: how often the operator updates the attitude setpoint [Hz], in
            [1e-3, 1000] (``kind = "attitude"``).
        goals: the supervisor's orders (``kind = "supervisor"``): ``{t_s, position_ned_m,
            yaw_deg}`` goals and ``{t_s, cancel = true}`` cancels, taken in time order.
        factory: ``"FILE.py:NAME"`` or ``"MODULE:NAME"``, the callable that makes the pilot
            (``kind = "python"``; a relative file is the scenario file's folder's).
        args: the factory's keyword arguments (``kind = "python"``), any TOML values; ``rng``
            is the run's to give.
        file: the ``series.csv`` whose sticks a ``"recorded"`` pilot replays (a relative path is
            the scenario file's folder's, or the working directory's on the command line).
        shift_s: a ``"recorded"`` pilot plays the file this much later [s], in [−86400, 86400]
            (negative: its first ``−shift_s`` seconds are skipped).
        recording: the sticks ``file`` holds, read and checked when the section is built
            (``"recorded"``), else None.
    """

    kind: Literal["scripted", "attitude", "supervisor", "python", "recorded"] = "scripted"
    start_s: float = 5.0
    x: tuple[SineTerm, ...] = ()
    y: tuple[SineTerm, ...] = ()
    z: tuple[SineTerm, ...] = ()
    yaw: tuple[SineTerm, ...] = ()
    roll_amplitude_deg: float = 0.0
    roll_period_s: float = 20.0
    pitch_amplitude_deg: float = 0.0
    pitch_period_s: float = 30.0
    yaw_amplitude_deg: float = 0.0
    yaw_period_s: float = 25.0
    setpoint_rate_hz: float = 10.0
    goals: tuple[GoalStep, ...] = ()
    factory: str = ""
    args: dict[str, Any] = field(default_factory=dict)
    file: str = ""
    shift_s: float = 0.0
    recording: RecordedPilot | None = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        check_time(self.start_s, "start_s")
        check_range(self.shift_s, "shift_s", -MAX_DURATION_S, MAX_DURATION_S, "s")
        for name, limit in zip(_ATTITUDE_AMPLITUDES, (89.9, 89.9, 180.0), strict=True):
            check_range(getattr(self, name), name, -limit, limit, "deg")
        for name in ("roll_period_s", "pitch_period_s", "yaw_period_s"):
            check_range(getattr(self, name), name, *PERIOD_RANGE_S, "s")
        check_rate(self.setpoint_rate_hz, "setpoint_rate_hz")
        owners = {
            "scripted": _STICK_AXES,
            "attitude": _ATTITUDE_AMPLITUDES,
            "supervisor": ("goals",),
            "python": ("factory", "args"),
            "recorded": ("file", "shift_s"),
        }
        for kind, names in owners.items():
            if kind != self.kind:
                for name in names:
                    check(not getattr(self, name), name, f"only used when kind = {kind!r}")
        if self.kind == "python":
            check(bool(self.factory), "factory", "required when kind = 'python'")
            problem = check_target(self.factory)
            check(problem is None, "factory", problem or "")
            check("rng" not in self.args, "args.rng", "the run gives rng (its seed's generator)")
        if self.kind == "recorded":
            check(bool(self.file), "file", "required when kind = 'recorded' (a run's series.csv)")
            try:
                recording = load_recorded_pilot(self.file, self.shift_s)
            except ConfigError as err:  # the file's own line, under this key
                raise FieldError("file", str(err)) from None
            object.__setattr__(self, "recording", recording)

    @property
    def timed(self) -> bool:
        """Whether :attr:`start_s` applies: not to a ``"python"`` pilot (it starts when it says,
        from its args) or a ``"recorded"`` one (it plays at the file's times)."""
        return self.kind not in ("python", "recorded")

    def pilot(self) -> Pilot:
        """The packaged pilot this section configures (:mod:`testbed.operator.pilots`); a
        ``kind = "python"`` pilot is made by :func:`testbed.run.plugin_calls.scenario_pilot`."""
        if self.kind == "python":
            raise ValueError("a pilot of kind 'python' is made by plugin_calls.scenario_pilot")
        if self.kind == "supervisor":
            return SupervisorPilot(self.goals)
        if self.kind == "recorded":
            assert self.recording is not None  # built with the section
            return self.recording
        if self.kind == "attitude":
            return AttitudePilot(
                self.start_s,
                self.roll_amplitude_deg,
                self.roll_period_s,
                self.pitch_amplitude_deg,
                self.pitch_period_s,
                self.yaw_amplitude_deg,
                self.yaw_period_s,
                self.setpoint_rate_hz,
            )
        return ScriptedPilot(self.start_s, self.x, self.y, self.z, self.yaw)


@dataclass(frozen=True, slots=True)
class ControlLawsSection:
    """``[vehicle.control]``: a depth or attitude hold of the user's own, flying instead of the
    packaged PID (:mod:`testbed.vehicle.control_laws`), made for each run by the callable a
    target names (:func:`testbed.run.plugin_calls.scenario_control_laws`). Kept apart from
    :class:`~testbed.vehicle.vehicle_config.VehicleConfig`: the vehicle does not load Python
    files.

    Attributes:
        depth: ``"FILE.py:NAME"`` or ``"MODULE:NAME"``, the callable called as
            ``NAME(**depth_args)`` for each run to make a
            :class:`~testbed.vehicle.control_laws.DepthLaw` (a relative file is the scenario
            file's folder's); "" = the packaged depth PID.
        depth_args: its keyword arguments (only with ``depth``), any TOML values.
        attitude: the same for an :class:`~testbed.vehicle.control_laws.AttitudeLaw`
            (``NAME(**attitude_args)``); "" = the packaged attitude PIDs.
        attitude_args: its keyword arguments (only with ``attitude``).
    """

    depth: str = ""
    depth_args: dict[str, Any] = field(default_factory=dict)
    attitude: str = ""
    attitude_args: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in ("depth", "attitude"):
            target: str = getattr(self, name)
            if target:
                problem = check_target(target)
                check(problem is None, name, problem or "")
            used = not getattr(self, f"{name}_args") or bool(target)
            check(used, f"{name}_args", f"only used with vehicle.control.{name}")

    def targets(self) -> dict[str, str]:
        """``{"depth": target, "attitude": target}`` of the laws named (none: empty)."""
        named = {"depth": self.depth, "attitude": self.attitude}
        return {name: target for name, target in named.items() if target}


@dataclass(frozen=True, slots=True)
class ThrusterFault:
    """A thruster failure from time ``t_s`` on (``Vehicle.fail_thruster``).

    Attributes:
        t_s: when it fails [s], in [0, duration_s).
        thruster: a thruster name of the scenario's layout.
        mode: ``"dead"`` (no force), ``"stuck"`` (holds ``value`` [N], or without one the
            force it has when it fails) or ``"degraded"`` (force scaled by ``value`` in
            [0, 1]).
        value: the stuck force [N], in [−100, 100], or the degraded factor (required); left
            out for ``"dead"``. 0 is a value like any other (a stuck thruster at 0 N, a
            degraded one giving nothing).
    """

    t_s: float
    thruster: str
    mode: Literal["dead", "stuck", "degraded"]
    value: float | None = None

    def __post_init__(self) -> None:
        check_time(self.t_s, "t_s")
        check(bool(self.thruster), "thruster", "must not be empty")
        value = self.value
        if self.mode == "dead":
            check(value in (None, 0.0), "value", "not used when mode = 'dead' (leave it out)")
        elif self.mode == "degraded":
            check(value is not None, "value", "the degraded factor is required, in [0, 1]")
        if value is not None:
            limit = MAX_STUCK_FORCE_N
            check_range(value, "value", -limit, limit)
            if self.mode == "degraded":
                check(0.0 <= value <= 1.0, "value", f"must be in [0, 1], got {value}")


@dataclass(frozen=True, slots=True)
class LinkOutage:
    """A window [start_s, end_s) in which nothing is delivered in either direction.

    Attributes:
        start_s: window start [s], ≥ 0.
        end_s: window end [s], > start_s and ≤ the scenario's duration.
    """

    start_s: float
    end_s: float

    def __post_init__(self) -> None:
        check_time(self.start_s, "start_s")
        check_time(self.end_s, "end_s")
        check(
            self.end_s > self.start_s,
            "end_s",
            f"must be > start_s ({self.start_s}), got {self.end_s}",
        )

    @property
    def duration_s(self) -> float:
        """Length of the window [s]."""
        return self.end_s - self.start_s


@dataclass(frozen=True, slots=True)
class FaultsSection:
    """Scheduled faults: thruster failures and link outages (sorted, not overlapping)."""

    thrusters: tuple[ThrusterFault, ...] = ()
    link_outages: tuple[LinkOutage, ...] = ()

    def __post_init__(self) -> None:
        for i in range(1, len(self.link_outages)):
            previous, outage = self.link_outages[i - 1], self.link_outages[i]
            check(
                outage.start_s >= previous.end_s,
                f"link_outages[{i}].start_s",
                f"must be ≥ the previous window's end_s ({previous.end_s}), got {outage.start_s}",
            )


@dataclass(frozen=True, slots=True)
class MetricsSection:
    """What the recorder samples and the metrics leave out.

    Attributes:
        settle_s: samples before this time [s] are left out of error statistics; in
            [0, duration_s).
        sample_rate_hz: time-series recording rate [Hz] for plots and tracking metrics, in
            [1e-3, 1000] (a row at most once a control frame).
    """

    settle_s: float = 10.0
    sample_rate_hz: float = 20.0

    def __post_init__(self) -> None:
        check_time(self.settle_s, "settle_s")
        check_rate(self.sample_rate_hz, "sample_rate_hz")
