"""Dask preload of the ``--dask local`` workers: die with the sweep that started them.

``LocalCluster(preload=["testbed.sweep.worker_setup"])`` imports this module in every worker
process and calls :func:`dask_setup`, which sets ``PR_SET_PDEATHSIG`` (SIGKILL) like the process
pool's initializer (:func:`testbed.sweep.backends.die_with_parent`). The sweep's PID comes from
the environment (``TESTBED_SWEEP_PARENT_PID``, set by the sweep before it starts the cluster);
without it, this module does nothing.
"""

from __future__ import annotations

import os
from typing import Any

from testbed.sweep.backends import PARENT_PID_ENV, die_with_parent

__all__ = ["dask_setup"]


def dask_setup(worker: Any) -> None:  # the hook's signature
    """Called by dask in each worker process at start-up."""
    parent = os.environ.get(PARENT_PID_ENV)
    if parent and parent.isdigit():
        die_with_parent(int(parent))
