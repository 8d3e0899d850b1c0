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
import dataclasses
import sysconfig
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from testbed.run.interrupts import deferred_interrupts

if TYPE_CHECKING:
    from testbed.run.runner import RunResult

__all__ = [
    "RunExit",
    "describe",
    "failed_trial",
    "keep_partial",
    "keep_trial",
    "partial_run",
    "raised_in_user_code",
    "reduce_run",
    "run_error",
]

_PARTIAL = "testbed_partial_run"
_TRIAL = "testbed_failed_trial"


class RunExit(Exception):  # noqa: N818  # named for what it is, as SystemExit is
    """``sys.exit()`` called inside a run (by a pilot, link model or control law of the
    user's): the run's error like any other its code raises, not the program's exit. It has
    the ``SystemExit``'s traceback and ``code`` and is caused by it (so :func:`describe` names
    the user's line)."""

    def __init__(self, code: object) -> None:
        super().__init__(f"sys.exit({code!r}) called during the run")
        self.code = code


def run_error(error: BaseException) -> Exception | None:
    """The error a run that ``error`` ended part way keeps what ran for: ``error`` itself, or
    for a ``SystemExit`` a :class:`RunExit` caused by it (a sweep's process-pool worker then
    records a failed run instead of the whole sweep exiting, and ``testbed run`` keeps what
    ran); None for what ends no run (``GeneratorExit``, an interrupt: the caller's to take)."""
    if isinstance(error, Exception):
        return error
    if isinstance(error, SystemExit):
        exit_error = RunExit(error.code).with_traceback(error.__traceback__)
        exit_error.__cause__ = error  # simpy raised a copy of the user's, caused by it
        return exit_error
    return None


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
            If it raises too, nothing is kept and the original error is raised with a note
            saying why (the user needs that error, not a second one).
    """
    try:
        result = reduce(describe(error))
    except Exception as failure:  # the run's own error is the one to report
        error.add_note(f"testbed: what ran could not be kept ({describe(failure)})")
        return
    with contextlib.suppress(AttributeError, TypeError):  # an exception type without a __dict__
        setattr(error, _PARTIAL, result)


def partial_run(error: BaseException) -> RunResult | None:
    """The partial result :func:`keep_partial` kept on ``error``, or None."""
    return getattr(error, _PARTIAL, None)


def keep_trial(error: BaseException, trial: int) -> None:
    """Note on ``error`` the number of the trial it ended (1-based; :func:`failed_trial`)."""
    with contextlib.suppress(AttributeError, TypeError):
        setattr(error, _TRIAL, trial)


def failed_trial(error: BaseException) -> int | None:
    """The trial :func:`keep_trial` noted on ``error``, or None (not a trial's)."""
    return getattr(error, _TRIAL, None)


def reduce_run(
    reduce: Callable[[str | None], RunResult],
    failed: Exception | None,
    reached_s: float,
    stopped: KeyboardInterrupt | None,
) -> RunResult:
    """The end of a run's simulation: its result, or ``failed`` raised with what ran kept.

    Args:
        reduce: makes the result from the recording (given the error's line, or None).
        failed: the error that ended the simulation part way, or None.
        reached_s: the simulated time reached [s]; an error at 0 leaves nothing to keep.
        stopped: the interrupt that ended it early, or None.

    Returns:
        The result, its ``stopped`` set by ``stopped`` or a Ctrl-C while reducing (which is
        reduced whole, then honoured by the caller).

    Raises:
        Exception: ``failed``, carrying the partial result (:func:`partial_run`).
    """
    result = None
    with deferred_interrupts() as late:
        if failed is None:
            result = reduce(None)
        elif reached_s > 0:
            keep_partial(failed, reduce)
    if failed is not None:
        raise failed
    assert result is not None
    return dataclasses.replace(result, stopped=stopped or (late[0] if late else None))
