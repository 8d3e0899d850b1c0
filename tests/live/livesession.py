"""A running ``testbed live`` process for the browser tests, and where Chromium is.

Shared by ``test_browser.py`` and ``test_console_page.py`` (test modules cannot import each
other under ``--import-mode=importlib``); the ``browser_path`` fixture is in ``conftest.py``.
"""

from __future__ import annotations

import contextlib
import json
import select
import shutil
import signal
import subprocess
import sys
import time
import urllib.request
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from tests.processes import default_sigint

__all__ = ["CAP_S", "DEADLINE_S", "Live", "chromium"]

DEADLINE_S = 60.0
CAP_S = 600.0
"""Failure bound of every wait [s of wall clock]: a loaded machine runs late, never wrong."""


def chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        found = shutil.which(name)
        if found:
            return found
    return None


class Live:
    """A running ``testbed live`` process."""

    def __init__(self, out: Path, *args: str) -> None:
        self.out = out
        command = [sys.executable, "-m", "testbed", "live", *args, "--port", "0", "--no-plots"]
        command += ["--out", str(out), "--duration", "3600"]  # the test ends it (SIGINT)
        self.proc = subprocess.Popen(
            command,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            preexec_fn=default_sigint,  # it must take the test's Ctrl-C however pytest started
        )
        assert self.proc.stdout is not None
        ready, _, _ = select.select([self.proc.stdout], [], [], 4 * DEADLINE_S)
        line = self.proc.stdout.readline() if ready else ""  # once the console is up
        assert line.startswith("testbed live: console on "), line + self.proc.stderr.read()
        self.url = line.split()[-1]

    def state(self) -> dict[str, Any]:
        with urllib.request.urlopen(self.url + "state", timeout=10) as response:
            document: dict[str, Any] = json.loads(response.read())
        return document["state"] or {}

    def wait(self, what: str, ok: Callable[[dict[str, Any]], bool]) -> dict[str, Any]:
        """The first state that satisfies ``ok``. A progress timeout: the deadline
        (``DEADLINE_S``) restarts whenever the link's counters move (a loaded host runs the
        session slowly, not wrongly), up to ``CAP_S`` in all."""
        start = time.monotonic()
        deadline = start + DEADLINE_S
        progress = None
        state: dict[str, Any] = {}
        while time.monotonic() < min(deadline, start + CAP_S):
            ended = self.proc.poll() is not None
            assert not ended, f"testbed live ended waiting for {what}: " + self.proc.stderr.read()
            state = self.state()
            if state and ok(state):
                return state
            link = (state or {}).get("link") or {}
            now = json.dumps([link.get("uplink"), link.get("downlink")], sort_keys=True)
            if now != progress:
                progress, deadline = now, time.monotonic() + DEADLINE_S
            time.sleep(0.05)
        waited = time.monotonic() - start
        last = json.dumps(state)[:2000]
        raise AssertionError(f"never in {waited:.0f} s: {what}; last state {last}")

    @classmethod
    @contextlib.contextmanager
    def running(cls, out: Path, *args: str) -> Iterator[Live]:
        """A session for a fixture: killed at the end if the test left it running."""
        process = cls(out, *args)
        try:
            yield process
        finally:
            if process.proc.poll() is None:
                process.proc.kill()
                process.proc.wait()

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
        return self.proc.wait(timeout=300)  # progress timeout: a loaded host writes slowly
