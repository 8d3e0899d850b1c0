"""Command-line interface: ``testbed SUBCOMMAND``, one per job (run, link, sweep, plot, …).

Each subcommand parses its arguments, builds frozen configs through :mod:`testbed.config`, runs,
prints results to stdout and logs to stderr. A user's mistake (unknown key, bad value, missing
file) prints one line to stderr and returns exit code 2, never a traceback.

This module holds the parser, the dispatch and the error handling; each subcommand group has its
own module (:mod:`~testbed.cli.run`, :mod:`~testbed.cli.link`, :mod:`~testbed.cli.sweep`,
:mod:`~testbed.cli.emulator`, :mod:`~testbed.cli.hil`, :mod:`~testbed.cli.mavlink`,
:mod:`~testbed.cli.live`), whose heavy imports happen only when the command runs, so
``testbed --help`` stays fast.
"""

from __future__ import annotations

import _thread
import argparse
import errno
import signal
import sys
import threading
import time
from collections.abc import Sequence
from types import FrameType

from testbed.cli.emulator import add_modem_emulator_parser
from testbed.cli.hil import add_hil_parser
from testbed.cli.link import add_link_parser
from testbed.cli.live import add_live_parser
from testbed.cli.mavlink import add_mavlink_parser
from testbed.cli.options import (
    EXIT_FAILED,
    EXIT_OK,
    EXIT_USAGE,
    Parser,
    Terminated,
    exit_code_of,
)
from testbed.cli.run import add_run_parser, add_scenarios_parser
from testbed.cli.run_summary import format_summary
from testbed.cli.sweep import add_plot_parser, add_sweep_parser
from testbed.config import USER_MODULE_PREFIX, ConfigError

__all__ = ["EXIT_OK", "EXIT_USAGE", "build_parser", "format_summary", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The ``testbed`` argument parser with all subcommands."""
    parser = Parser(
        prog="testbed",
        description="A network-simulated teleoperation testbed for underwater ROVs: "
        "one subcommand per job (testbed SUBCOMMAND --help for each).",
    )
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)
    add_run_parser(sub)
    add_link_parser(sub)
    add_sweep_parser(sub)
    add_plot_parser(sub)
    add_modem_emulator_parser(sub)
    add_hil_parser(sub)
    add_mavlink_parser(sub)
    add_live_parser(sub)
    add_scenarios_parser(sub)
    return parser


_SIGNALLED: list[int] = []
"""The interrupt signals this process received (a list, so the handlers can append)."""

_PUT_OFF_IN = ("numba.", "llvmlite.")
"""Modules whose Python code an interrupt must not be raised in (see :func:`_put_off`)."""

_PUT_OFF_FILES = frozenset(
    {"<frozen importlib._bootstrap>", "<frozen importlib._bootstrap_external>"}
)
"""Code an interrupt must not be raised in either: an import under way (see :func:`_put_off`)."""

_FROM_TEXT = "<string>"
"""The file name of code ``exec`` or ``eval`` compiled from text. Only the text's own body
(``<module>``) is put off, not the functions it defines, and not ``python -c``'s body, the
bottom of its stack."""

_PUT_OFF_S = 0.001
"""How long an interrupt is put off at a time [s]."""


def _put_off(signum: int, frame: FrameType | None) -> bool:
    """Send ``signum`` again, to be handled after the code running now, if it is code an
    interrupt must not be raised in.

    Python runs a handler wherever the program is, and in three places an exception raised
    there does harm:

    - numba's own Python code: its compiler, and the callbacks its compiled kernels make
      (``_numba_unpickle``, each time a kernel hands a new array back, as the navigation
      filter's did every frame). An exception raised in a kernel's first callback crashes
      the process (a segmentation fault, seen), in a later one it comes out as
      ``SystemError``.
    - an import: a compiled module's initialisation may swallow it (numpy's random
      generator, registering its classes, did: Ctrl-C was lost and ``testbed link`` ran to
      its end), and a module left half imported stays broken.
    - code compiled from text by ``exec`` or ``eval`` (the methods ``dataclasses`` writes, at
      every import that declares one): CPython notes an interrupt that leaves such code as
      unhandled, and however the program handles it, the process ends killed by SIGINT
      instead of with its own exit code (130 after the one line, seen as -2).

    So while any frame the command runs (newer than :func:`main`'s: a program that calls
    ``main`` from inside an import of its own still takes Ctrl-C) is one of those, the signal is
    sent again a moment later, from a thread of its own (sent from the handler, it would be
    handled inside it; a ``threading.Timer`` would wait here for its thread to start), until
    the stack is the program's own. A user's module the testbed imports by path (a scenario's
    pilot or link model, :data:`~testbed.config.USER_MODULE_PREFIX`) is the program's own: the
    import under way below it does not put the signal off (a pilot file that slept or looped
    at import kept Ctrl-C waiting until it was done), one above it (an import it makes) does.
    """
    while frame is not None and frame.f_code is not main.__code__:  # the command's own frames
        code = frame.f_code
        if frame.f_globals.get("__name__", "").startswith(USER_MODULE_PREFIX):
            return False  # the user's own code, running (its module is dropped when raised in)
        if (
            code.co_filename in _PUT_OFF_FILES
            or (code.co_filename == _FROM_TEXT and code.co_name == "<module>" and frame.f_back)
            or frame.f_globals.get("__name__", "").startswith(_PUT_OFF_IN)
        ):
            _thread.start_new_thread(_send_again, (threading.get_ident(), signum))
            return True
        frame = frame.f_back
    return False


def _send_again(thread_id: int, signum: int) -> None:
    time.sleep(_PUT_OFF_S)
    signal.pthread_kill(thread_id, signum)


def _interrupt_for(signum: int) -> KeyboardInterrupt:
    """What a signal is raised as: :class:`Terminated` for SIGTERM, else ``KeyboardInterrupt``."""
    return Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()


def _signalled(signum: int, frame: FrameType | None) -> None:
    """The handler of SIGTERM and SIGINT: the signal's interrupt, raised here unless put off."""
    if _put_off(signum, frame):
        return
    _SIGNALLED.append(signum)
    _RESENT.clear()
    raise _interrupt_for(signum)


def _swallowed(unraisable: sys.UnraisableHookArgs) -> None:
    """``sys.unraisablehook`` while a command runs: an interrupt the handler raised where
    Python cannot raise (a weakref callback, a ``__del__``, the garbage collector's callbacks:
    "Exception ignored in …", and the command went on to exit 0, seen while plotting) is sent
    again a moment later, to be raised in the command's own code; anything else goes to the
    hook that was there before."""
    if isinstance(unraisable.exc_value, KeyboardInterrupt) and _SIGNALLED:
        signum = _SIGNALLED.pop()  # appended again when it is handled
        _RESENT.append(signum)
        _thread.start_new_thread(_send_again, (threading.get_ident(), signum))  # the main one
        return
    _PREVIOUS_UNRAISABLE_HOOK[0](unraisable)


_PREVIOUS_UNRAISABLE_HOOK = [sys.unraisablehook]
_RESENT: list[int] = []
"""Signals :func:`_swallowed` sent again that have not been handled yet."""
_RESENT_WAIT_S = 0.5
"""How long a command that ended meanwhile waits for one to land [s] (it lands in ≈ 1 ms)."""


_HELD_AT_ENTRY = frozenset({signal.SIGINT, signal.SIGTERM})
"""The signals the process's entry (:func:`testbed.__main__.console_main`) blocks from its
start until :func:`main` has its handlers in place: one sent while the command line is imported
and its arguments parsed is handled as soon as they are, in :func:`main`'s own code."""


_STORAGE_ERRORS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EIO, errno.EROFS, errno.EFBIG})
"""What a disk says when results cannot be written: one line, not a traceback (exit 1)."""

_PATH_ERRORS = frozenset(
    {
        errno.ENAMETOOLONG,
        errno.ENOENT,
        errno.ENOTDIR,
        errno.EISDIR,
        errno.EACCES,
        errno.EPERM,
        errno.ELOOP,
    }
)
"""What the system says of a path the user gave that cannot be written (a name too long, a
folder under /proc, no permission): one line naming the path, exit 2, like bad input."""


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI. Returns the process exit code: 0 ok, 1 the storage failed (a full disk:
    one line naming the file), 2 bad input (also a path that cannot be written: a name too
    long, no permission; one line naming it), 130 Ctrl-C, 143 SIGTERM.

    SIGTERM is raised as :class:`~testbed.cli.options.Terminated` (a ``KeyboardInterrupt``), so
    a command keeps what it finished the same way for both. On the main thread the two are
    unblocked once the handlers are in (the console script and ``python -m testbed`` block them
    from the start: :mod:`testbed.__main__`). A command that has something to keep says so in
    its own one line; an interrupt it does not handle ends with ``testbed: interrupted`` and
    nothing more.
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    previous: list[tuple[int, object]] = []
    on_main_thread = threading.current_thread() is threading.main_thread()
    if on_main_thread:
        del _SIGNALLED[:]
        del _RESENT[:]
        previous.append((signal.SIGTERM, signal.signal(signal.SIGTERM, _signalled)))
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:  # not when ignored
            previous.append((signal.SIGINT, signal.signal(signal.SIGINT, _signalled)))
        _PREVIOUS_UNRAISABLE_HOOK[0] = sys.unraisablehook
        sys.unraisablehook = _swallowed
    try:
        if on_main_thread:  # what the process's entry held until now is handled here
            signal.pthread_sigmask(signal.SIG_UNBLOCK, _HELD_AT_ENTRY)
        code: int = args.handler(args)
        deadline = time.monotonic() + _RESENT_WAIT_S
        while _RESENT and time.monotonic() < deadline:  # one sent again lands here, handled
            time.sleep(_PUT_OFF_S)
    except ConfigError as err:
        print(f"testbed: error: {err}", file=sys.stderr)
        return EXIT_USAGE
    except BrokenPipeError:  # e.g. `testbed run | head`: the reader left, nothing to report
        sys.stderr.close()
        return EXIT_OK
    except OSError as err:
        if err.errno in _PATH_ERRORS and err.filename:
            print(f"testbed: error: cannot write {err.filename}: {err.strerror}", file=sys.stderr)
            return EXIT_USAGE
        if err.errno not in _STORAGE_ERRORS:
            raise
        where = f" {err.filename}" if err.filename else ""
        print(f"testbed: cannot write{where}: {err.strerror}", file=sys.stderr)
        return EXIT_FAILED
    except KeyboardInterrupt as interrupt:
        print("testbed: interrupted", file=sys.stderr)
        return exit_code_of(interrupt)
    except Exception:
        # An interrupt raised inside a library that turned it into an error of its own (the
        # handler runs wherever the program is, e.g. in a compiler's clean-up): still the
        # interrupt the user asked for, ended as one the command does not handle (one line).
        if not _SIGNALLED:
            raise
        print("testbed: interrupted", file=sys.stderr)
        return exit_code_of(_interrupt_for(_SIGNALLED[0]))
    finally:
        for signum, handler in previous:
            signal.signal(signum, handler)  # type: ignore[arg-type]
        if sys.unraisablehook is _swallowed:
            sys.unraisablehook = _PREVIOUS_UNRAISABLE_HOOK[0]
    return code
