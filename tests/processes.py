"""Helpers for tests that signal real child processes."""

from __future__ import annotations

import signal


def default_sigint() -> None:
    """``preexec_fn`` for a child that must take Ctrl-C as a terminal's foreground job does.

    A process started from a non-interactive shell's background job inherits SIGINT ignored,
    and Python then never installs its KeyboardInterrupt handler; tests that send SIGINT
    restore the default disposition in the child first, so they test the program, not how
    the test runner was launched.
    """
    signal.signal(signal.SIGINT, signal.SIG_DFL)
