"""What every ``testbed`` subcommand shares: exit codes, the parser class, ``--set``."""

from __future__ import annotations

import argparse
from typing import NoReturn, TypeAlias

__all__ = ["EXIT_OK", "EXIT_USAGE", "Parser", "Subparsers", "add_set_option"]

EXIT_OK = 0
EXIT_USAGE = 2


class Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one line on stderr and exit code 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message}\n")


Subparsers: TypeAlias = "argparse._SubParsersAction[Parser]"


def add_set_option(parser: argparse.ArgumentParser, help_text: str) -> None:
    """The repeatable ``--set KEY=VALUE`` override option, collected in ``args.overrides``."""
    parser.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE", help=help_text
    )
