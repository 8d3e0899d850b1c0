"""What the ``testbed`` subcommands share: exit codes, the parser class, ``--set``, checks."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import NoReturn, TypeAlias

from testbed.config import ConfigError

__all__ = [
    "EXIT_INTERRUPTED",
    "EXIT_OK",
    "EXIT_TERMINATED",
    "EXIT_USAGE",
    "Parser",
    "Subparsers",
    "Terminated",
    "add_set_option",
    "check_distance",
    "check_out_dir",
    "check_seed",
    "exit_code_of",
]

EXIT_OK = 0
EXIT_USAGE = 2
EXIT_INTERRUPTED = 130
"""Ended by SIGINT (Ctrl-C): 128 + 2, as shells report it."""
EXIT_TERMINATED = 143
"""Ended by SIGTERM: 128 + 15."""


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the program is (the CLI installs the handler): a
    ``KeyboardInterrupt``, so everything that keeps its work on Ctrl-C keeps it on SIGTERM."""


def exit_code_of(interrupt: KeyboardInterrupt) -> int:
    """130 for Ctrl-C, 143 for SIGTERM."""
    return EXIT_TERMINATED if isinstance(interrupt, Terminated) else EXIT_INTERRUPTED


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


def check_seed(seed: int | None) -> None:
    """``--seed``: absent (the default) or ≥ 0; else :class:`ConfigError`."""
    if seed is not None and seed < 0:
        raise ConfigError(f"--seed: must be ≥ 0, got {seed}")


def check_distance(distance_m: float) -> None:
    """``--distance``: a finite distance ≥ 0 m; else :class:`ConfigError`."""
    if not (distance_m >= 0.0 and math.isfinite(distance_m)):
        raise ConfigError(f"--distance: must be ≥ 0 m, got {distance_m}")


def check_out_dir(out: Path) -> None:
    """``--out``: a directory or nothing yet; else :class:`ConfigError`."""
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out: {out} exists and is not a directory")
