"""Helpers for tests that signal real child processes."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any


def default_sigint() -> None:
    """``preexec_fn`` for a child that must take Ctrl-C as a terminal's foreground job does.

    A process started from a non-interactive shell's background job inherits SIGINT ignored,
    and Python then never installs its KeyboardInterrupt handler; tests that send SIGINT
    restore the default disposition in the child first, so they test the program, not how
    the test runner was launched.
    """
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def check_set(out: Path) -> dict[str, Any]:
    """The results directory's metrics.json names exactly the files beside it, with their
    sizes (a complete or a marked partial set, never a mixed one); its content."""
    metrics: dict[str, Any] = json.loads((out / "metrics.json").read_text())
    files = metrics["files"]
    assert isinstance(files, dict)
    on_disk = {p.name: p.stat().st_size for p in out.iterdir() if p.name != "metrics.json"}
    assert on_disk == files
    return metrics


def run_testbed(args: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    """``python -m testbed ARGS`` run to its end in ``cwd``, output captured as text (a hung
    child fails the test after 300 s)."""
    return subprocess.run(
        [sys.executable, "-m", "testbed", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=300.0,
    )


def one_error_line(done: subprocess.CompletedProcess[str], *banner: str) -> str:
    """The run's one error line: exit 2, no traceback, nothing else on stderr but ``banner``
    (the lines a real-time mode prints as it starts)."""
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr
    lines = done.stderr.splitlines()
    assert len(lines) == len(banner) + 1, done.stderr
    for line, start in zip(lines, banner, strict=False):
        assert line.startswith(start), done.stderr
    assert lines[-1].startswith("testbed: error: "), done.stderr
    return lines[-1]
