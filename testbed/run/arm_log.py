"""What the recorder keeps of a vehicle's arm: :class:`ArmLog`, the rows of ``arm.csv`` (the
joints' angles, rates and commands, and the TPIK's joint-limit tasks in force) and the
``"arm"`` key of ``metrics.json`` (:meth:`ArmLog.metrics`).

Rows are taken with the series rows (the first frame at or after each sample instant). The
angles and rates are the arm's measured joints (the plant's, as the vehicle reads them each
frame); the command is the joint-rate command of that frame (the TPIK's rates after the
acceleration limit). A ``<joint>_limit`` column is the joint-limit set task of that joint in
the TPIK solution in force (none while the TPIK is not steering): 0 inactive, −1 active at its
low threshold, +1 at its high one, NaN for a joint without a limit task.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from testbed.config import CSV_NUMBER_FORMAT
from testbed.run.recorder import SeriesRows
from testbed.vehicle.manipulation import Manipulator
from testbed.vehicle.tpik import JointLimitTask

__all__ = ["ArmLog"]

_DEG = 180.0 / math.pi


@dataclass(slots=True)
class ArmLog:
    """The arm's rows and counters over one run.

    Attributes:
        joints: the arm's joint names, base → tip.
        physical_deg: each joint's (lower, upper) position limits [deg].
        safety_deg: each joint's (low, high) safety range of its limit task [deg], or None.
        rows: one row of :meth:`columns` per sample.
        solves: TPIK solves over the run.
        limit_activations: solves with a joint-limit task active.
        active: the joints whose limit task is active in the last solution (their names).
    """

    joints: tuple[str, ...]
    physical_deg: tuple[tuple[float, float], ...]
    safety_deg: tuple[tuple[float, float] | None, ...]
    rows: SeriesRows = field(init=False)
    solves: int = 0
    limit_activations: int = 0
    active: tuple[str, ...] = ()
    _tasks: dict[str, JointLimitTask] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.rows = SeriesRows(len(self.columns()))

    @classmethod
    def of(cls, arm: Manipulator) -> ArmLog:
        """The empty log of ``arm`` (its joints and its TPIK's limit tasks)."""
        joints = arm.model.joints
        safety: list[tuple[float, float] | None] = [None] * len(joints)
        for task in arm.tpik.limit_tasks:
            safety[task.joint] = (task.safety[0] * _DEG, task.safety[1] * _DEG)
        log = cls(
            joints=tuple(j.name for j in joints),
            physical_deg=tuple((j.lower_rad * _DEG, j.upper_rad * _DEG) for j in joints),
            safety_deg=tuple(safety),
        )
        log._tasks = {task.name: task for task in arm.tpik.limit_tasks}
        return log

    def columns(self) -> tuple[str, ...]:
        """``t_s``, then ``<joint>_deg``, ``<joint>_rate_deg_s``, ``<joint>_cmd_deg_s`` and
        ``<joint>_limit`` of every joint, in that order."""
        names = ["t_s"]
        for suffix in ("deg", "rate_deg_s", "cmd_deg_s", "limit"):
            names += [f"{joint}_{suffix}" for joint in self.joints]
        return tuple(names)

    def note(self, arm: Manipulator) -> bool:
        """Take the arm's counters and its last solution's active set; True when the set of
        joints with an active limit task changed since the last call."""
        self.solves = arm.solves
        self.limit_activations = arm.limit_activations
        names = _in_force(arm)
        joints = tuple(self.joints[self._tasks[name].joint] for name in names)
        if joints == self.active:
            return False
        self.active = joints
        return True

    def record(self, now: float, arm: Manipulator) -> None:
        """Append the row of vehicle time ``now`` [s]."""
        sides = [math.nan if s is None else 0.0 for s in self.safety_deg]
        for name in _in_force(arm):
            task = self._tasks[name]
            middle = 0.5 * (task.low_threshold + task.high_threshold)
            sides[task.joint] = -1.0 if arm.q_rad[task.joint] <= middle else 1.0
        self.rows.append(
            (
                now,
                *(q * _DEG for q in arm.q_rad),
                *(rate * _DEG for rate in arm.rates_rad_s),
                *(rate * _DEG for rate in arm.command_rad_s),
                *sides,
            )
        )

    def table(self) -> dict[str, np.ndarray]:
        """The rows as one array per column (read-only views, no copy)."""
        table = self.rows.table()
        return {name: table[:, k] for k, name in enumerate(self.columns())}

    def write_csv(self, path: Path) -> None:
        """Write ``arm.csv``: a header of :meth:`columns`, values to 6 significant digits."""
        with path.open("w", newline="", encoding="utf-8") as handle:
            writer = csv.writer(handle, lineterminator="\n")
            writer.writerow(self.columns())
            writer.writerows([f"{v:{CSV_NUMBER_FORMAT}}" for v in row] for row in self.rows)

    def metrics(self) -> dict[str, Any]:
        """The ``"arm"`` key of ``metrics.json``: ``solves`` and ``limit_activations`` (TPIK
        solves, and those with a joint-limit task active), and per joint ``{min_deg, max_deg,
        margin_deg}`` over the rows: ``margin_deg`` is the closest the joint came to the nearer
        edge of its safety range [deg] (to its physical limits for a joint without a limit
        task); negative means it went past it. NaN with no rows."""
        table = self.table()
        joints: dict[str, dict[str, float]] = {}
        for joint, physical, safety in zip(
            self.joints, self.physical_deg, self.safety_deg, strict=True
        ):
            angles = table[f"{joint}_deg"]
            low, high = physical if safety is None else safety
            if angles.size:
                margin = float(np.minimum(angles - low, high - angles).min())
                joints[joint] = {
                    "min_deg": float(angles.min()),
                    "max_deg": float(angles.max()),
                    "margin_deg": margin,
                }
            else:
                joints[joint] = dict.fromkeys(("min_deg", "max_deg", "margin_deg"), math.nan)
        return {
            "solves": self.solves,
            "limit_activations": self.limit_activations,
            "joints": joints,
        }


def _in_force(arm: Manipulator) -> tuple[str, ...]:
    """The limit tasks active in the TPIK solution the arm flies now (none while the TPIK is
    not steering: disarmed, or no end-effector target)."""
    if arm.last is None or arm.vehicle_twist is None:
        return ()
    return arm.last.active
