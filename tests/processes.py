"""Helpers for tests that run the command line: in a real child process (signals, the process
boundary) or in-process through :func:`testbed.cli.main.main` (:func:`run_main`: the same
exit code and output, without a child's ≈ 1.3 s of start-up)."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import pytest


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


def run_main(
    args: list[str],
    cwd: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> subprocess.CompletedProcess[str]:
    """``testbed ARGS`` run in this process in ``cwd`` (restored after the test), as
    :func:`run_testbed` reports it: the exit code :func:`~testbed.cli.main.main` returns and
    what it wrote to stdout and stderr (output captured before the call is dropped). An
    exception ``main`` lets out fails the test, as a child's traceback would."""
    from testbed.cli.main import main

    monkeypatch.chdir(cwd)
    capsys.readouterr()
    code = main(args)
    captured = capsys.readouterr()
    return subprocess.CompletedProcess(["testbed", *args], code, captured.out, captured.err)


Runner = Callable[[list[str], Path], subprocess.CompletedProcess[str]]
"""A way to run ``testbed ARGS`` in a folder: :func:`run_testbed`, or :func:`in_process`'s."""


def in_process(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> Runner:
    """:func:`run_main` with the test's fixtures bound: called as :func:`run_testbed` is."""
    return partial(run_main, monkeypatch=monkeypatch, capsys=capsys)


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
