"""The wall clock of real-time runs: how late ``simpy.rt.RealtimeEnvironment`` runs a step.

Real-time runs (:func:`~testbed.run.realtime.run_hil`, the live console, the MAVLink runs) use
simpy's real-time environment with ``strict=False``: a step that runs late is caught up, not an
error. :func:`rt_lateness_ns` is the instrumentation that says how late: each run samples it in
a process that wakes on a fixed period (the HIL poll, the MAVLink vehicle's frames) and reports
it as ``scheduler_lateness_ms``, and tests derive their real-time bounds from it (a loaded
machine runs late; the model does not change).

Nothing here builds or runs an environment.
"""

from __future__ import annotations

import time

import simpy.rt

__all__ = ["SAMPLES_KEPT", "rt_lateness_ns"]

SAMPLES_KEPT = 200_000
"""Samples a real-time run keeps of each per-poll or per-frame measurement (lateness, compute
time, latencies; the newest): 200 s of 1-ms polls, 2000 s of 100-Hz frames."""


def rt_lateness_ns(env: simpy.rt.RealtimeEnvironment) -> int:
    """How late the real-time environment is running now [ns]: the wall clock less the
    instant ``env.now`` was scheduled for (``real_start + (now − env_start)·factor``, on
    :func:`time.monotonic`, simpy's clock). Called from a process just resumed, it is how late
    that step ran; ≥ 0 except for clock rounding."""
    scheduled_s = env.real_start + (env.now - env.env_start) * env.factor
    return round((time.monotonic() - scheduled_s) * 1e9)
