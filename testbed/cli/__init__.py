"""The ``testbed`` command line: one module per subcommand group."""

from __future__ import annotations

from testbed.cli.main import main

__all__ = ["main"]
