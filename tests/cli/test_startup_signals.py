"""Ctrl-C or SIGTERM while ``testbed`` starts: one line and exit 130 / 143, never a traceback.

Before :func:`testbed.cli.main.main` installs its handlers, Python imports the command line
(argparse, pathlib, dataclasses, tomllib, the subcommands' parsers) and parses the arguments:
≈ 30 ms after the interpreter's own ≈ 25 ms of start-up on the development machine, more on a
loaded one. A SIGINT there used to end in a ``KeyboardInterrupt`` traceback (and the process
killed by the signal), a SIGTERM in a silent kill.

The commands are real processes: the installed console script and ``python -m testbed``. The
start-up is sampled by its progress, not by the clock, so the test means the same on a loaded
machine: each child runs with ``PYTHONPROFILEIMPORTTIME`` (Python writes a line to stderr as
each import ends), and the signal is sent once the child has written the line of a chosen
module. The modules are spread over the imports the start-up makes after the ``testbed``
package's own, measured first with ``run --help`` (the same imports; it exits in the argument
parsing). For SIGTERM, whose default action kills until a handler is installed, they are
those after the ``signal`` module's. One more is imported after ``main``'s handlers are in
(numpy, by ``testbed run``). What the interpreter does before it runs the package (its own
start-up, the ``site`` module, the console script's or runpy's import of ``testbed``) is out of
the package's reach and not sampled.
"""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.processes import default_sigint

WAIT_S = 60.0
SAMPLES = 8
"""Start-up points signalled per command and signal."""
AFTER_HANDLERS = "numpy"
"""A module ``testbed run`` imports after ``main`` installed its handlers (its handler's)."""
TIME_LINE = b"import time:"
ONE_LINE = "testbed: interrupted"
LONG = ["--set", "duration_s=86400", "--no-plots"]  # a simulated day: the signal ends it

CONSOLE_SCRIPT = Path(sys.executable).parent / "testbed"


def commands() -> dict[str, list[str]]:
    assert CONSOLE_SCRIPT.is_file(), f"no console script beside {sys.executable}"
    return {"console script": [str(CONSOLE_SCRIPT)], "python -m": [sys.executable, "-m", "testbed"]}


def start(command: list[str]) -> subprocess.Popen[bytes]:
    env = {**os.environ, "PYTHONPROFILEIMPORTTIME": "1"}
    return subprocess.Popen(
        command,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=env,
        preexec_fn=default_sigint,
    )


def module_of(line: bytes) -> str:
    """The module an import-time line names (its last column)."""
    return line.rsplit(b"|", 1)[-1].strip().decode()


def read_until(proc: subprocess.Popen[bytes], module: str) -> bytes:
    """The child's stderr up to and including the import-time line of ``module``."""
    assert proc.stderr is not None
    fd = proc.stderr.fileno()
    seen = b""
    deadline = time.monotonic() + WAIT_S
    while True:
        for line in seen.split(b"\n")[:-1]:
            if line.startswith(TIME_LINE) and module_of(line) == module:
                return seen
        left = deadline - time.monotonic()
        assert left > 0, f"no import of {module} within {WAIT_S} s: {seen.decode()[-2000:]}"
        ready, _, _ = select.select([fd], [], [], left)
        chunk = os.read(fd, 65536) if ready else b""
        assert chunk or not ready, f"the child ended before importing {module}: {seen.decode()}"
        seen += chunk


def imports(err: bytes) -> list[str]:
    """The modules of the import-time lines in ``err``, in order."""
    return [module_of(line) for line in err.splitlines() if line.startswith(TIME_LINE)]


def startup_imports(command: list[str], tmp_path: Path) -> list[str]:
    """The modules the command's start-up imports after the ``testbed`` package's own and
    before ``main`` installs its handlers, in order: those of ``run`` before numpy that
    ``run --help`` imports too (the same start-up, ended in the argument parsing)."""
    proc = start([*command, "run", "--help"])
    _, err = proc.communicate(timeout=WAIT_S)
    assert proc.returncode == 0, err.decode()
    parsing = set(imports(err))
    proc = start([*command, "run", *LONG, "--out", str(tmp_path / "calibration")])
    try:
        modules = imports(read_until(proc, AFTER_HANDLERS))
    finally:
        proc.kill()
        proc.communicate()
    package = max(i for i, name in enumerate(modules) if name in ("testbed", "testbed.__main__"))
    window = [name for name in modules[package + 1 :] if name in parsing]
    assert len(window) >= SAMPLES, modules  # the window the test samples: the CLI's imports
    return window


def other_lines(err: bytes) -> list[str]:
    """Stderr without the import-time lines."""
    return [line.decode() for line in err.splitlines() if not line.startswith(TIME_LINE)]


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
@pytest.mark.parametrize("name", ["console script", "python -m"])
def test_a_signal_anywhere_in_start_up_ends_with_one_line(
    tmp_path: Path, name: str, sig: signal.Signals, code: int
) -> None:
    command = commands()[name]
    window = startup_imports(command, tmp_path)
    if sig == signal.SIGTERM and "signal" in window:  # its default action kills until a
        window = window[window.index("signal") + 1 :]  # handler is in, which needs the module
    picks = [window[round(i * (len(window) - 1) / (SAMPLES - 1))] for i in range(SAMPLES)]
    outcomes = []
    for i, module in enumerate([*picks, AFTER_HANDLERS]):
        proc = start([*command, "run", *LONG, "--out", str(tmp_path / f"out{i}")])
        try:
            seen = read_until(proc, module)
            proc.send_signal(sig)
            out, err = proc.communicate(timeout=WAIT_S)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
        lines = other_lines(seen + err)
        outcomes.append((module, proc.returncode, lines))
        assert out == b""
    # once main's handlers are in, the run's own line (it may have begun simulating)
    started = outcomes.pop()
    wrong = [o for o in outcomes if o[1] != code or o[2] != [ONE_LINE]]
    if started[1] != code or len(started[2]) != 1 or not started[2][0].startswith(ONE_LINE):
        wrong.append(started)
    assert not wrong, "\n".join(f"after {m}: exit {rc}, {lines}" for m, rc, lines in wrong)
