"""``--dask local`` while port 8787 is taken (two sweeps at once, tests in parallel, a notebook's
cluster): the sweep prints nothing about it.

distributed's scheduler serves its HTTP endpoints on 8787 even with the dashboard off, and when
that port is taken it moves to another and warns on stderr (``UserWarning: Port 8787 is already
in use. Perhaps you already have a cluster running? Hosting the HTTP server on port … instead``),
in the user's terminal among the sweep's own lines. The sweep is a child process, as a user
runs it; the port is held by this test (or already by someone else: taken either way).
"""

from __future__ import annotations

import contextlib
import csv
import errno
import socket
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

DASHBOARD_PORT = 8787
"""distributed's default port for the scheduler's HTTP server."""


@contextlib.contextmanager
def port_taken(port: int) -> Iterator[None]:
    """``127.0.0.1:port`` listened on by this process inside (unless something else already
    does)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        try:
            sock.bind(("127.0.0.1", port))
            sock.listen()
        except OSError as err:
            if err.errno != errno.EADDRINUSE:
                raise
        yield


def test_a_local_cluster_with_port_8787_taken_prints_only_the_sweeps_lines(
    tmp_path: Path, two_point_sweep: Callable[[str], Path]
) -> None:
    sweep_file = two_point_sweep("dashboard")  # conftest.py: id dashboard-v1, 2 runs
    out = tmp_path / "out"
    argv = ["sweep", str(sweep_file), "--dask", "local", "--workers", "1", "--out", str(out)]
    with port_taken(DASHBOARD_PORT):
        done = subprocess.run(
            [sys.executable, "-m", "testbed", *argv],
            capture_output=True,
            text=True,
            timeout=600.0,
        )
    assert done.returncode == 0, done.stderr
    others = [line for line in done.stderr.splitlines() if not line.startswith("dashboard-v1: ")]
    assert others == []
    with (out / "results.csv").open(newline="") as handle:
        assert len(list(csv.DictReader(handle))) == 2
