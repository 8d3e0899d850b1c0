"""`testbed hil` as a real process: Ctrl-C and SIGTERM keep a marked partial result (even
before ``metrics.settle_s``), a bad --out fails before any work, a bad port URL is one line.

Each session is a child process (``python -m testbed hil``) on the two ports of a
``testbed modem-emulator`` child, as tests/cli/test_signals.py does for ``testbed run``; signals
are real. A session is signalled once it has said it is running (its stderr line) and run a
little; waits are bounded by generous multiples of the work, polled, never slept blindly. The
refusals (a bad --out, a port that cannot be opened) and --force involve no signal: they call
the CLI's ``main`` in this process (a child costs ≈ 2 s of imports each), the refusals checked
for the exit code, the one stderr line and no serial thread left running.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from testbed.cli.main import main
from tests.processes import check_set, default_sigint

WAIT_S = 120.0
LONG = ["--duration", "86400", "--set", "metrics.settle_s=30"]
"""Hours of wall time, settling for 30 s: a signal after ~2 s ends it before settle_s."""


def start(args: list[str]) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "testbed", *args],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=default_sigint,
    )


@pytest.fixture
def ports() -> Iterator[tuple[str, str]]:
    """The two ports of a ``testbed modem-emulator`` child (s100, its defaults)."""
    emulator = start(["modem-emulator", "--set", "ber=0"])
    try:
        assert emulator.stdout is not None
        a, b = emulator.stdout.readline().split(), emulator.stdout.readline().split()
        assert a[0] == "A" and b[0] == "B", (a, b)
        yield a[1], b[1]
    finally:
        emulator.send_signal(signal.SIGINT)
        emulator.communicate(timeout=WAIT_S)


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_interrupt_before_settling_keeps_a_marked_partial_result(
    tmp_path: Path, ports: tuple[str, str], sig: signal.Signals, code: int
) -> None:
    out = tmp_path / "hil"
    args = ["hil", "--operator-port", ports[0], "--vehicle-port", ports[1], *LONG]
    proc = start([*args, "--out", str(out)])
    assert proc.stderr is not None
    banner = proc.stderr.readline()  # printed once the nodes are built, as the clock starts
    assert banner.startswith("testbed: hil both: operator on "), banner
    time.sleep(2.0)
    proc.send_signal(sig)
    stdout, stderr = proc.communicate(timeout=WAIT_S)
    assert proc.returncode == code, stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("testbed: interrupted at t = "), stderr
    assert lines[0].endswith(f"of 86400 s; partial results in {out}")
    assert stdout == ""
    metrics = check_set(out)
    assert metrics["complete"] is False
    reached = float(lines[0].split("t = ")[1].split(" s")[0])
    assert 0.0 < metrics["sim_s"] < 30.0  # before settle_s
    assert metrics["sim_s"] == pytest.approx(reached, abs=0.05 + 1e-9)  # the line rounds to 0.1 s
    assert set(metrics["files"]) == {"events.csv", "series.csv"}
    assert metrics["command_age_s"] == {"mean": None, "p95": None}  # needs the settled window
    assert metrics["hil"]["mode"] == "both"


@pytest.mark.parametrize(
    ("out", "words"),
    [
        ("afile/sub", "cannot write there"),
        ("afile", "exists and is not a directory"),
        ("full", "is not empty (use --force"),
    ],
)
def test_bad_out_fails_before_any_work(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], out: str, words: str
) -> None:
    (tmp_path / "afile").write_text("x")
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "old.txt").write_text("x")
    # ports that exist nowhere: the --out check comes first, before they are opened (the
    # vehicle port's error would name --vehicle-port); a session of 86400 s would take a day:
    # returning at all shows nothing ran
    args = ["hil", "--operator-port", "loop://", "--vehicle-port", "/dev/null/x", *LONG]
    assert main([*args, "--out", str(tmp_path / out)]) == 2
    stdout, stderr = capsys.readouterr()
    assert stdout == ""
    assert stderr.count("\n") == 1 and stderr.startswith("testbed: error: --out: ")
    assert words in stderr
    assert (tmp_path / "full" / "old.txt").read_text() == "x"
    assert _serial_threads() == []  # the loop:// port was never opened


def test_force_replaces_a_previous_result(tmp_path: Path, ports: tuple[str, str]) -> None:
    out = tmp_path / "hil"
    out.mkdir()
    (out / "old.csv").write_text("x")  # a previous run's file, listed by its metrics.json
    (out / "metrics.json").write_text(json.dumps({"complete": True, "files": {"old.csv": 1}}))
    args = ["hil", "--operator-port", ports[0], "--vehicle-port", ports[1], "--no-plots"]
    args += ["--duration", "1.5", "--set", "metrics.settle_s=1", "--force", "--out", str(out)]
    assert main(args) == 0
    metrics = check_set(out)  # the previous run's file is gone with its metrics.json
    assert metrics["complete"] is True and metrics["sim_s"] == 1.5


@pytest.mark.parametrize("url", ["bogus://x", "loop://?bad=1", "/dev/does-not-exist-testbed"])
def test_a_port_that_cannot_be_opened_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], url: str
) -> None:
    args = ["hil", "--operator-port", url, "--vehicle-port", "loop://", *LONG]
    assert main([*args, "--out", str(tmp_path / "hil")]) == 2
    stdout, stderr = capsys.readouterr()
    assert stdout == ""
    assert stderr.count("\n") == 1, stderr
    assert stderr.startswith(f"testbed: error: --operator-port: cannot open {url}: ")
    assert _serial_threads() == []  # nothing opened is left running


def _serial_threads() -> list[str]:
    """The names of this process's running serial reader and writer threads."""
    return [t.name for t in threading.enumerate() if t.name.startswith("serial:")]
