"""What the recorder watches on a vehicle: :class:`VehicleObserver`, the POST_UPDATE system a
run appends to the vehicle's schedule, turns what the vehicle publishes into node events and
the :data:`~testbed.run.recorder.SERIES_COLUMNS` rows of :class:`~testbed.run.recorder.Recorder`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

from testbed.common.geometry import attitude_error, euler_from_quat
from testbed.ecs import World
from testbed.operator.pilots import Pilot
from testbed.run.arm_log import ArmLog
from testbed.run.recorder import Recorder
from testbed.vehicle.autonomy import Autonomy
from testbed.vehicle.components import (
    ActiveMode,
    Armed,
    ControlMode,
    ControlTargets,
    FailsafeLevel,
    FailsafeStatus,
    MissionStatus,
    PoseTarget,
    PositionSetpoint,
)
from testbed.vehicle.filter_values import NavigationEstimate
from testbed.vehicle.manipulation import EndEffectorTarget, Manipulator
from testbed.vehicle.resources import Controllers, PlantTruth, PowerMeter, SimClock
from testbed.vehicle.systems import applied_sticks

__all__ = ["VehicleObserver"]

_DEG = 180.0 / math.pi
_NO_TARGET = (math.nan,) * 4
_NO_ESTIMATE = (math.nan,) * 3


class VehicleObserver:
    """POST_UPDATE system appended to the vehicle's schedule: records what the vehicle
    publishes — failsafe changes, the mission's goals given and reached (``mission_goal``,
    ``mission_reached``: the goal's number, counting from 1) and the mission tree's status line
    whenever it changes (``mission``: "executing square", "…: goal not reached within 10 s",
    "cancelled: …") and, with an arm, the joints whose TPIK limit task is in force whenever
    they change (``limit_tasks``: their names, or "none") as node events and, at
    ``sample_rate_hz``, one series row (and one :class:`~testbed.run.arm_log.ArmLog` row) —
    reading its resources and components only (never the controllers' or the plant's insides).

    Args:
        recorder: where rows and events go.
        pilot: the operator's pilot, sampled again at the vehicle's time for the ``cmd_*``
            columns (the pilot's true sticks, which the vehicle only sees late).
        reference_velocity: applied sticks (6,) → the (u, v, w, r) they ask for
            (:meth:`~testbed.vehicle.vehicle.Vehicle.reference_velocity`).
        sample_rate_hz: rate of the series rows [Hz]; a row is taken at the first frame at
            or after each sample instant.
        other_failsafe: another failsafe that acts on this vehicle, asked at each row (in a
            ``testbed mavlink`` run, ArduSub's pilot-input or GCS failsafe, the vehicle's own
            being off there): while it says True, the ``failsafe`` column reads at least
            HOLD (1). None: the vehicle's own level alone.
    """

    def __init__(
        self,
        recorder: Recorder,
        pilot: Pilot,
        reference_velocity: Callable[[Sequence[float]], tuple[float, float, float, float]],
        sample_rate_hz: float,
        other_failsafe: Callable[[], bool] | None = None,
    ) -> None:
        self._recorder = recorder
        self._other_failsafe = other_failsafe
        self._pilot = pilot
        self._reference_velocity = reference_velocity
        self._sample_period_s = 1.0 / sample_rate_hz
        self._next_sample_s = 0.0
        self._last_failsafe = 0
        self._last_mission: tuple[int, int] = (0, 0)
        self._last_armed = False
        self._last_mode: ControlMode | None = None
        self._autonomy: Autonomy | bool | None = False  # False: not looked up yet
        self._arm: Manipulator | bool | None = False
        self._last_status = ""

    def __call__(self, world: World) -> None:
        now = world.resource(SimClock).time_s
        if world.changed_any(FailsafeStatus, MissionStatus, Armed, ActiveMode):  # since last run
            self._note_changes(world, now)
        auto = self._autonomy
        if auto is False:
            auto = self._autonomy = (
                world.resource(Autonomy) if world.has_resource(Autonomy) else None
            )
        if isinstance(auto, Autonomy) and auto.status != self._last_status:
            self._last_status = auto.status
            self._recorder.event(now, "vehicle", "mission", auto.status)
        arm = self._arm
        if arm is False:
            arm = self._arm = self._start_arm_log(world)
        if isinstance(arm, Manipulator):
            log = self._recorder.arm
            assert log is not None
            if log.note(arm):
                self._recorder.event(now, "vehicle", "limit_tasks", " ".join(log.active) or "none")
        if now < self._next_sample_s - 1e-9:
            return
        if isinstance(arm, Manipulator):
            assert self._recorder.arm is not None
            self._recorder.arm.record(now, arm)
        if self._recorder.link_state is not None:
            self._recorder.link_state.record(now)
        self._next_sample_s += self._sample_period_s
        failsafe = self._last_failsafe
        if self._other_failsafe is not None and self._other_failsafe():
            failsafe = max(failsafe, int(FailsafeLevel.HOLD))
        self._recorder.rows.append(self.row(world, now, float(failsafe)))

    def _start_arm_log(self, world: World) -> Manipulator | None:
        """The vehicle's arm, its log started in the recorder; None without one."""
        if not world.has_resource(Manipulator):
            return None
        arm = world.resource(Manipulator)
        self._recorder.arm = ArmLog.of(arm)
        return arm

    def _note_changes(self, world: World, now: float) -> None:
        """Events for the vehicle arming or disarming, a new mode in effect, a new failsafe
        level, and mission goals given or reached."""
        vehicle = world.resource(Controllers).vehicle
        armed = world.get(vehicle, Armed)
        if armed is not None and armed.armed != self._last_armed:
            self._recorder.event(now, "vehicle", "arm" if armed.armed else "disarm")
            self._last_armed = armed.armed
        mode = world.get(vehicle, ActiveMode)
        if mode is not None and mode.mode is not self._last_mode:
            self._recorder.event(now, "vehicle", "mode", mode.mode.name)
            self._last_mode = mode.mode
        status = world.get(vehicle, FailsafeStatus)
        level = 0 if status is None else int(status.level)
        if level != self._last_failsafe:
            self._recorder.event(now, "vehicle", "failsafe", status.level.name if status else "")
            self._last_failsafe = level
        mission = world.get(vehicle, MissionStatus)
        if mission is not None and (mission.goals, mission.reached) != self._last_mission:
            goals, reached = self._last_mission
            if mission.goals != goals:
                self._recorder.event(now, "vehicle", "mission_goal", str(mission.goals))
            if mission.reached != reached:  # the goal in force was reached: its number
                self._recorder.event(now, "vehicle", "mission_reached", str(mission.goals))
            self._last_mission = (mission.goals, mission.reached)

    def row(self, world: World, now: float, failsafe: float) -> tuple[float, ...]:
        """One row of :data:`SERIES_COLUMNS` at vehicle time ``now`` [s], in their order."""
        ctl = world.resource(Controllers)
        truth = world.resource(PlantTruth)
        sticks = applied_sticks(ctl)  # centred in a failsafe: what the vehicle flies
        pilot = self._pilot.sample(now).sticks
        roll, pitch, yaw = euler_from_quat(truth.quaternion_wxyz)
        targets = world.get(ctl.vehicle, ControlTargets)
        if targets is None or not ctl.flags.armed:
            errors = (math.nan, math.nan, math.nan)
            depth_target = math.nan
        else:  # against the targets a hold flies (MANUAL's targets are flown by nothing)
            errors = (
                attitude_error(targets.quaternion_wxyz, truth.quaternion_wxyz)
                if ctl.flags.attitude_hold
                else (math.nan, math.nan, math.nan)
            )
            depth_target = targets.depth_m if ctl.flags.depth_hold else math.nan
        row: tuple[float, ...] = (now, pilot[0], pilot[1], pilot[2], pilot[5])
        row += (sticks[0], sticks[1], sticks[2], sticks[5], *self._reference_velocity(sticks))
        row += truth.position_ned_m
        row += (roll * _DEG, pitch * _DEG, yaw * _DEG, *truth.velocity_m_s, *truth.rates_rad_s)
        row += (errors[0] * _DEG, errors[1] * _DEG, errors[2] * _DEG, depth_target)
        row += (world.resource(PowerMeter).current_a, float(ctl.flags.armed), failsafe)
        target = world.get(ctl.vehicle, PoseTarget)
        if target is None:
            row += _guided_target(world, ctl)
        else:
            row += (*target.position_ned_m, target.yaw_rad * _DEG)
        estimate = world.get(ctl.vehicle, NavigationEstimate)
        row += _NO_ESTIMATE if estimate is None else estimate.position_ned_m
        if not world.has_resource(Manipulator):
            row += _NO_ESTIMATE + _NO_ESTIMATE
        else:
            arm = world.resource(Manipulator)
            row += arm.end_effector_ned(truth.position_ned_m, truth.quaternion_wxyz)
            reach = world.get(ctl.vehicle, EndEffectorTarget)
            row += _NO_ESTIMATE if reach is None else reach.position_ned_m
        mode = world.get(ctl.vehicle, ActiveMode)
        return (*row, math.nan if mode is None else float(mode.mode))


def _guided_target(world: World, ctl: Controllers) -> tuple[float, ...]:
    """The ``target_*`` columns without an autonomy's pose target: in GUIDED, armed, the
    operator's go-to (:class:`PositionSetpoint`, its heading NaN when it sets none), the one
    the position loop flies; with none, the point the loop holds once it has chosen one
    (:meth:`~testbed.vehicle.guidance.PositionController.latch_hold`: its north and east, the
    depth hold's target, heading NaN); else NaN."""
    if not (ctl.flags.guided and ctl.flags.armed):
        return _NO_TARGET
    setpoints = [sp for _, sp in world.query1(PositionSetpoint)]
    if not setpoints:
        hold = ctl.position.hold_ne_m
        if hold is None or ctl.position.released or ctl.autonomous:
            return _NO_TARGET
        targets = world.get(ctl.vehicle, ControlTargets)
        return (*hold, math.nan if targets is None else targets.depth_m, math.nan)
    goal = setpoints[-1]  # as control_position takes it
    return (*goal.position_ned_m, goal.yaw_rad * _DEG if goal.use_yaw else math.nan)
