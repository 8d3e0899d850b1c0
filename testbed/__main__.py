"""The process's entry: the ``testbed`` console script (:func:`console_main`) and
``python -m testbed``.

Python runs this before anything else of the testbed's, so it imports nothing at its top but
``sys``. :func:`console_main` first holds SIGINT and SIGTERM (blocks them), then imports the
command line (:mod:`testbed.cli.main`: argparse, pathlib, dataclasses, tomllib, every
subcommand's parser) and calls :func:`~testbed.cli.main.main`, which parses the arguments,
installs its handlers and lets the signals in: one that came meanwhile (≈ 40 ms after the
interpreter's start-up, on the development machine) ends the command as any interrupt it does
not handle, ``testbed: interrupted`` and exit 130 or 143. Raised where it landed instead, in an
import, it ended in a traceback, and in code compiled from text (the methods ``dataclasses`` and
``namedtuple`` write as they are imported) it made ``python -m testbed`` end killed by SIGINT
whatever it had caught; SIGTERM killed silently.

What comes before this module runs (the interpreter's own start-up and its ``site`` module:
≈ 25 ms there, most of it an editable install's import hook) is out of its reach.
"""

import sys

_INTERRUPTED = "testbed: interrupted"
"""The line :func:`testbed.cli.main.main` ends an interrupt it does not handle with."""
_EXIT_INTERRUPTED = 130


def console_main() -> int:
    """Run ``testbed`` with the process's arguments; the exit code of
    :func:`testbed.cli.main.main`.

    A Ctrl-C in the moment before the signals are held, or after ``main`` returned, ends with
    the same line, exit 130 (143 for a SIGTERM ``main`` raised as its own).
    """
    try:
        import signal  # inside: a Ctrl-C while it is imported is caught below too

        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
        from testbed.cli.main import main

        return main()
    except KeyboardInterrupt as interrupt:
        print(_INTERRUPTED, file=sys.stderr)
        options = sys.modules.get("testbed.cli.options")  # imported by then, if main ran
        return _EXIT_INTERRUPTED if options is None else int(options.exit_code_of(interrupt))


if __name__ == "__main__":
    sys.exit(console_main())
