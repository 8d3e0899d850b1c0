"""One run of the testbed, wired: scenario schema, link codecs, nodes, runner, real-time runs,
recorder and metrics. The only place that joins operator, link and vehicle.

The Python API (README: "Python API"): :func:`load_scenario` (a scenario by name or path, with
``key=value`` overrides), :func:`run_scenario` (one run, optionally with your own ``pilot`` and a
``vehicle_setup`` hook), :class:`RunResult`, :func:`write_run` (the run's files), and for the
hooks the :class:`Pilot` protocol, :class:`PilotSample`, :data:`Sticks` and
:data:`VehicleSetup`. They are imported on first use, so that importing a light module of this
package (``testbed.run.metrics``) does not load the simulation.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from testbed.operator.pilots import Pilot, PilotSample, Sticks
    from testbed.run.outputs import write_run
    from testbed.run.runner import RunResult, VehicleSetup, run_scenario
    from testbed.run.scenario import load_scenario
    from testbed.run.scenario_config import Scenario

__all__ = [
    "Pilot",
    "PilotSample",
    "RunResult",
    "Scenario",
    "Sticks",
    "VehicleSetup",
    "load_scenario",
    "run_scenario",
    "write_run",
]

_HOMES = {
    "Pilot": "testbed.operator.pilots",
    "PilotSample": "testbed.operator.pilots",
    "Sticks": "testbed.operator.pilots",
    "RunResult": "testbed.run.runner",
    "VehicleSetup": "testbed.run.runner",
    "run_scenario": "testbed.run.runner",
    "Scenario": "testbed.run.scenario_config",
    "load_scenario": "testbed.run.scenario",
    "write_run": "testbed.run.outputs",
}


def __getattr__(name: str) -> Any:
    """The exported name ``name``, imported from its module on first use."""
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(home), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
