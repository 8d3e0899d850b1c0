"""Command-line interface: ``testbed link|...``.

Each subcommand parses its arguments, builds frozen configs through :mod:`testbed.config`, runs,
prints results to stdout and logs to stderr. A user's mistake (unknown key, bad value, missing
file) prints one line to stderr and returns exit code 2, never a traceback.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import NoReturn

from testbed.config import ConfigError

EXIT_OK = 0
EXIT_USAGE = 2


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one line on stderr and exit code 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    """The ``testbed`` argument parser with all subcommands."""
    parser = _Parser(prog="testbed", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    _add_link_parser(sub)
    return parser


def _add_link_parser(sub: argparse._SubParsersAction[_Parser]) -> None:
    """``testbed link``: one-way frame probe through the simulated channel (see channel.probe)."""
    raise NotImplementedError  # written with the channel model (issue 2)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI. Returns the process exit code (0 ok, 2 bad input)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        code: int = args.handler(args)
    except ConfigError as err:
        print(f"testbed: error: {err}", file=sys.stderr)
        return EXIT_USAGE
    return code
