"""Progress of a sweep: a tqdm bar on a terminal, otherwise a plain line now and then."""

from __future__ import annotations

import math
import time
from typing import TextIO

__all__ = ["Progress"]


class Progress:
    """A tqdm bar on a terminal; otherwise a plain line at most every ``interval_s``.

    Args:
        total: runs in the sweep.
        done: runs finished before this invocation (a resumed sweep).
        stream: where the progress goes.
        label: what the line names (the sweep id).
        unit: what is counted (``runs``; ``grid points`` while a sweep is checked, where
            nothing fails: no failed count).
    """

    def __init__(
        self, total: int, done: int, stream: TextIO, label: str, unit: str = "runs"
    ) -> None:
        self.total, self.done, self.failed = total, done, 0
        self.stream, self.label, self.unit = stream, label, unit
        self.start = self.last = time.monotonic()
        self.first_done = done
        self.bar = None
        if stream.isatty():
            from tqdm import tqdm

            self.bar = tqdm(
                total=total, initial=done, unit=unit.rstrip("s"), file=stream, desc=label
            )

    def update(self, failed: bool, *, interval_s: float = 1.0) -> None:
        """Count one finished run (``failed`` or not); print a line if ``interval_s`` [s] has
        passed since the last one, or if it was the last run."""
        self.done += 1
        self.failed += failed
        if self.bar is not None:
            self.bar.update(1)
            return
        now = time.monotonic()
        last_one = self.done >= self.total
        if now - self.last < interval_s and not (last_one and self.unit == "runs"):
            return  # the last run always gets a line; a quick check of the grid none
        self.last = now
        rate = (self.done - self.first_done) / max(now - self.start, 1e-9)
        eta = (self.total - self.done) / rate if rate > 0 else math.inf
        failures = f" ({self.failed} failed)" if self.unit == "runs" else ""
        print(
            f"{self.label}: {self.done}/{self.total} {self.unit}{failures}, "
            f"{rate:.2f} {self.unit}/s, ETA {eta:.0f} s",
            file=self.stream,
            flush=True,
        )

    def close(self) -> None:
        """Close the bar (if any); closing twice is harmless."""
        if self.bar is not None:
            self.bar.close()
            self.bar = None
