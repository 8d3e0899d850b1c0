"""``arm.png``: the arm's joints over a run (a vehicle with an arm).

One panel per joint, sharing the time axis: the measured angle [deg], the joint's physical
limits (solid grey) and the safety range of its TPIK joint-limit task (dashed), and shaded the
stretches where that task was in force (the ``<joint>_limit`` column of ``arm.csv``,
:class:`~testbed.run.arm_log.ArmLog`). Built on :class:`matplotlib.figure.Figure` directly
(:mod:`testbed.report.figures`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from testbed.report.figures import no_data, save
from testbed.run.arm_log import ArmLog

__all__ = ["plot_arm"]


def plot_arm(log: ArmLog, path: Path, *, title: str) -> Path:
    """Write ``arm.png`` of ``log`` to ``path`` and return it."""
    joints = log.joints
    fig = Figure(figsize=(8.0, 1.6 + 1.5 * len(joints)), layout="constrained")
    axes = fig.subplots(len(joints), 1, sharex=True, squeeze=False)[:, 0]
    table = log.table()
    t = table["t_s"]
    for ax, joint, physical, safety in zip(
        axes, joints, log.physical_deg, log.safety_deg, strict=True
    ):
        if not t.size:
            no_data(ax, "no rows")
            continue
        for limit in physical:
            ax.axhline(limit, color="0.5", linewidth=1.0)
        if safety is not None:
            for limit in safety:
                ax.axhline(limit, color="tab:red", linewidth=1.0, linestyle="--")
        active = np.abs(np.nan_to_num(table[f"{joint}_limit"])) > 0.5
        ax.fill_between(
            t, 0, 1, where=active, transform=ax.get_xaxis_transform(), color="tab:red",
            alpha=0.12, linewidth=0.0, step="post",
        )  # fmt: skip
        ax.plot(t, table[f"{joint}_deg"], color="tab:blue", linewidth=1.2)
        ax.set_ylabel(f"{joint} [deg]")
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(
        f"{title}\narm joints: physical limits (grey), safety range (dashed), "
        "joint-limit task in force (shaded)",
        fontsize="medium",
    )
    return save(fig, path)
