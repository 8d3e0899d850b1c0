"""A Ctrl-C while a ``--dask local`` sweep closes its LocalCluster, its runs all in.

The interrupt used to be raised inside ``LocalCluster.close`` (the main thread waits there for
the event loop), leaving the cluster half closed: distributed's exit handler then waited for
its 10-s timeout before the process ended (12.5 s from the Ctrl-C to the exit, measured, where
a finished close takes a fraction of that). The sweep now closes the cluster whole, the signal
held, and honours the interrupt after it: one line, exit 130, the cluster closed by the time
the command returns.

The sweep is a child process; the SIGINT is real, sent from the cluster's event-loop thread as
its close coroutine begins, so it lands while the main thread waits in ``close``.
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

from tests.processes import default_sigint

SIGNAL_IN_CLOSE = """
import os, signal, sys
from distributed.deploy.spec import SpecCluster

closed = []
original = SpecCluster._close

async def _close(self, *args, **kwargs):  # on the event-loop thread, main waits in close()
    if not closed:
        closed.append(self)
        os.kill(os.getpid(), signal.SIGINT)
    return await original(self, *args, **kwargs)

SpecCluster._close = _close
from testbed.cli.main import main
code = main({argv!r})
print("cluster status when the command returned:", closed[0].status.name, flush=True)
sys.exit(code)
"""


def test_ctrl_c_while_the_local_cluster_closes_lets_it_close_then_ends_with_one_line(
    tmp_path: Path, two_point_sweep: Callable[[str], Path]
) -> None:
    sweep_file = two_point_sweep("teardown")  # conftest.py: id teardown-v1, 2 runs
    out = tmp_path / "out"
    argv = ["sweep", str(sweep_file), "--dask", "local", "--workers", "1", "--out", str(out)]
    done = subprocess.run(
        [sys.executable, "-c", SIGNAL_IN_CLOSE.format(argv=argv)],
        capture_output=True,
        text=True,
        timeout=600.0,
        preexec_fn=default_sigint,
    )
    assert done.returncode == 130, done.stderr
    lines = [line for line in done.stderr.splitlines() if not line.startswith("teardown-v1:")]
    assert lines == [
        f"testbed: interrupted after 2 of 2 runs; journal kept in {out}; resume with: "
        f"testbed sweep {sweep_file} --workers 1 --dask local --out {out} --resume"
    ]
    assert "cluster status when the command returned: closed" in done.stdout
    assert len((out / "runs.jsonl").read_text().splitlines()) == 2
