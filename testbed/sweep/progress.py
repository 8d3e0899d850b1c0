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
    """

    def __init__(self, total: int, done: int, stream: TextIO, label: str) -> None:
        self.total, self.done, self.failed = total, done, 0
        self.stream, self.label = stream, label
        self.start = self.last = time.monotonic()
        self.first_done = done
        self.bar = None
        if stream.isatty():
            from tqdm import tqdm

            self.bar = tqdm(total=total, initial=done, unit="run", file=stream, desc=label)

    def update(self, failed: bool, *, interval_s: float = 1.0) -> None:
        """Count one finished run (``failed`` or not); print a line if ``interval_s`` [s] has
        passed since the last one, or if it was the last run."""
        self.done += 1
        self.failed += failed
        if self.bar is not None:
            self.bar.update(1)
            return
        now = time.monotonic()
        if now - self.last < interval_s and self.done < self.total:
            return
        self.last = now
        rate = (self.done - self.first_done) / max(now - self.start, 1e-9)
        eta = (self.total - self.done) / rate if rate > 0 else math.inf
        print(
            f"{self.label}: {self.done}/{self.total} runs ({self.failed} failed), "
            f"{rate:.2f} runs/s, ETA {eta:.0f} s",
            file=self.stream,
            flush=True,
        )

    def close(self) -> None:
        """Close the bar (if any)."""
        if self.bar is not None:
            self.bar.close()
