"""Test-suite settings.

Under CI (``CI`` set in the environment) hypothesis runs derandomized: the same examples every
run, so a submission's CI result does not depend on the draw. Local runs keep hypothesis's
random exploration (and its example database) to find new counterexamples.

The tests run the compiled kernels' entries checked (``TESTBED_CHECK_KERNELS=1``, set here
before anything imports :mod:`testbed.common.jit`, and inherited by the processes tests start):
every array a frame passes to a kernel is held to its declared type, so a call site that passes
another is an error in the tests rather than a misread. Production runs skip the check;
``tests/common/test_jit_entry.py`` runs scenarios both ways and compares their bits.

Strategies and reference helpers that several test modules use live in ``tests/strategies.py``
(``from tests.strategies import …``): under ``--import-mode=importlib`` test modules cannot
import each other, and fixtures cannot feed ``@given``.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator

os.environ.setdefault("TESTBED_CHECK_KERNELS", "1")  # before testbed.common.jit is imported

import pytest
from hypothesis import settings

# Bytecode caches on, whatever the environment says: with PYTHONDONTWRITEBYTECODE=1 (set on the
# development machines) pytest rewrote every test module's asserts again in each worker, and
# each of the few hundred child processes the tests start (`python -m testbed …`) compiled the
# package's ≈ 140 modules from source, ≈ 0.4 s a child. The workers write the caches as they
# import; the children read them. (`.gitignore` holds __pycache__/.)
sys.dont_write_bytecode = False
os.environ.pop("PYTHONDONTWRITEBYTECODE", None)

settings.register_profile("ci", derandomize=True, deadline=None, print_blob=True)
if os.environ.get("CI"):
    settings.load_profile("ci")


@pytest.hookimpl(tryfirst=True)
def pytest_configure(config: pytest.Config) -> None:
    """A run that selects the ``hil`` tests (``-m hil``) stays in one process: the machine's real
    modems are one set, and two xdist workers (the default ``-n 2``) would open them both."""
    selects_hil = "hil" in str(config.option.markexpr).replace("not hil", "")
    if selects_hil and hasattr(config.option, "numprocesses"):
        config.option.numprocesses = 0
        config.option.dist = "no"
        config.option.tx = []


@pytest.fixture(scope="module")
def no_sweep_plots() -> Iterator[None]:
    """``testbed sweep`` run through ``main`` in this process draws no plots, as ``--no-plots``
    does for ``testbed run`` (a sweep has no such option): for test modules whose subject is not
    the plots (``pytestmark = pytest.mark.usefixtures("no_sweep_plots")``). Drawing the BER
    plots costs about 1 s a sweep, most of a short sweep's time. The plots of real sweeps are
    tested in tests/report/test_sweep_plots.py, and sweeps run as child processes draw them."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr("testbed.report.sweep_plots.plot_ber_sweep", lambda results, out: [])
        yield


def pytest_sessionstart(session: object) -> None:
    """Compile (or load from numba's disk cache) the vehicle's, the navigation filter's and the
    ISMC's kernels once, here, before any test. On a fresh checkout the first process to fly a
    vehicle compiles them (≈ 35 s); otherwise that would be whichever child process a
    real-time or signal test started first, and its set-up would overrun the waits those tests
    derive from a warm start."""
    import numpy as np

    from testbed.vehicle.components import ControlMode
    from testbed.vehicle.vehicle import Vehicle
    from testbed.vehicle.vehicle_config import VehicleConfig

    with Vehicle(VehicleConfig(), np.random.default_rng(0)) as vehicle:  # builds the loops'
        vehicle.arm()
        vehicle.set_mode(ControlMode.DEPTH_HOLD)  # and runs them
        vehicle.command((0.5, 0.0, 0.0, 0.0, 0.0, 0.1))
        vehicle.advance(0.1)
    from testbed.vehicle.estimation import KalmanNavigator
    from testbed.vehicle.filter_values import FilterConfig
    from testbed.vehicle.nav_sensors import Measurement

    navigator = KalmanNavigator(FilterConfig())  # the navigation filter's kernels
    navigator.predict(0.01)
    navigator.update(Measurement("fix", "position_ned", 0.01, (0.0, 0.0, 0.0), (0.1,) * 3))
    from testbed.vehicle.hydrodynamics import load_model
    from testbed.vehicle.ismc import IsmcController, load_ismc_gains

    IsmcController(load_model("bluerov2-heavy"), load_ismc_gains("bluerov2-heavy"))  # the ISMC's
