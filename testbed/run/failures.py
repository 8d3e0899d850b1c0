"""A run that an error ended part way: what ran is kept, and the error still raised.

An exception raised while a run simulates (a pilot or link model of the user's that raises at
t = 20 s, or a bug of ours) used to lose everything the run had recorded. Now the run is
reduced up to the instant it reached, like a run Ctrl-C stopped, and that partial
:class:`~testbed.run.runner.RunResult` (``failure`` set to :func:`describe`'s line) rides on
the exception (:func:`keep_partial`), which is raised unchanged: callers that know
(``testbed run``, its trials, ``testbed hil``) write it, marked ``"complete": false`` with the
``failure``, before reporting the error; every other caller sees the same exception as before.
"""

from __future__ import annotations

import contextlib
import sysconfig
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from testbed.run.runner import RunResult

__all__ = ["describe", "keep_partial", "partial_run", "raised_in_user_code"]

_PARTIAL = "testbed_partial_run"


def describe(error: BaseException) -> str:
    """One line for ``error``: ``Type: message``, then where the user's own code raised it
    (:func:`raised_in_user_code`), whitespace folded."""
    return " ".join(f"{type(error).__name__}: {error}".split()) + raised_in_user_code(error)


def raised_in_user_code(error: BaseException) -> str:
    """`` (at FILE:LINE)``: the innermost frame of ``error``'s traceback in code of the user's
    own (a pilot or link model named in the scenario), not in the testbed, the standard library
    or an installed package; "" when it never passed through such code."""
    paths = sysconfig.get_paths()
    roots = [Path(paths[key]).resolve() for key in ("stdlib", "platstdlib", "purelib", "platlib")]
    roots.append(Path(__file__).resolve().parents[1])  # the testbed package
    seen: set[int] = set()
    current: BaseException | None = error
    while current is not None and id(current) not in seen:  # simpy raises a copy, caused by it
        seen.add(id(current))
        for frame in reversed(traceback.extract_tb(current.__traceback__)):
            if frame.filename.startswith("<"):
                continue
            path = Path(frame.filename).resolve()
            if not any(path.is_relative_to(root) for root in roots):
                return f" (at {frame.filename}:{frame.lineno})"
        current = current.__cause__ or current.__context__
    return ""


def keep_partial(error: BaseException, reduce: Callable[[str], RunResult]) -> None:
    """Reduce what ran before ``error`` and keep it on the error for :func:`partial_run`.

    Args:
        error: the exception that ended the run's simulation (raised again by the caller).
        reduce: makes the partial result, given :func:`describe`'s line for its ``failure``.
            If it raises too (a recording too short to reduce), nothing is kept: the original
            error is what the user needs, not a second one.
    """
    try:
        result = reduce(describe(error))
    except Exception:
        return
    with contextlib.suppress(AttributeError, TypeError):  # an exception type without a __dict__
        setattr(error, _PARTIAL, result)


def partial_run(error: BaseException) -> RunResult | None:
    """The partial result :func:`keep_partial` kept on ``error``, or None."""
    return getattr(error, _PARTIAL, None)
