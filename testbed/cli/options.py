"""What the ``testbed`` subcommands share: exit codes, the parser class, ``--set``, checks."""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn, TypeAlias

from testbed.config import ConfigError, FieldError, check_range

if TYPE_CHECKING:
    from testbed.channel import LinkConfig
    from testbed.hil import LinkEndpoint, PortSettings
    from testbed.run.scenario_config import Scenario

__all__ = [
    "EXIT_FAILED",
    "EXIT_INTERRUPTED",
    "EXIT_OK",
    "EXIT_TERMINATED",
    "EXIT_USAGE",
    "Parser",
    "Subparsers",
    "Terminated",
    "add_set_option",
    "check_baud",
    "check_distance",
    "check_duration",
    "check_only_with",
    "check_out_dir",
    "check_seed",
    "exit_code_of",
    "format_value",
    "link_config_option",
    "missing",
    "open_modem_ports",
    "warn_late_goals",
    "warn_token_cycle",
]

EXIT_OK = 0
EXIT_FAILED = 1
"""The system refused what a command had to do (a full or failing disk)."""
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


def missing(value: float | None) -> bool:
    """A figure metrics.json has as null: None, NaN or infinite (before writing)."""
    return value is None or not math.isfinite(value)


def format_value(value: float | None, scale: float = 1.0, digits: int = 3, unit: str = "") -> str:
    """A summary's figure: ``scale · value`` to ``digits`` places with ``unit``, or ``n/a``
    where metrics.json has null (:func:`missing`)."""
    if missing(value):
        return "n/a"
    assert value is not None
    return f"{scale * value:.{digits}f}{unit}"


def check_distance(distance_m: float) -> None:
    """``--distance``: a finite distance ≥ 0 m; else :class:`ConfigError`."""
    if not (distance_m >= 0.0 and math.isfinite(distance_m)):
        raise ConfigError(f"--distance: must be ≥ 0 m, got {distance_m}")


def check_duration(
    duration_s: float,
    *,
    low_s: float = 0.0,
    low_open: bool = True,
    note: str = "",
    low_note: str = "",
) -> None:
    """``--duration``: a time in (``low_s``, one day] s, the longest a scenario may run
    (:data:`testbed.run.sections.MAX_DURATION_S`, ``testbed run``'s limit); ``low_open=False``
    admits ``low_s`` itself. ``note`` ends every message; ``low_note`` (where the lower bound
    comes from) only that of a duration too short.

    Raises:
        ConfigError: ``--duration: must be in (0, 86400] s, got 1e+300`` and the note.
    """
    from testbed.run.sections import MAX_DURATION_S

    try:
        check_range(duration_s, "--duration", low_s, MAX_DURATION_S, "s", low_open=low_open)
    except FieldError as err:
        too_short = duration_s <= low_s  # NaN is neither: no bound to explain
        raise ConfigError(f"{err}{low_note if too_short else ''}{note}") from None


def link_config_option(preset: str, overrides: Sequence[str]) -> LinkConfig:
    """``--preset`` (a packaged preset or a ``.toml`` path) with the ``--set`` overrides: a bad
    preset is a one-line error naming ``--preset``, a bad override one naming ``--set``.

    Raises:
        ConfigError: ``--preset: link preset file not found: /abs/modem.toml``, or the
            override's message.
    """
    from testbed.channel import load_link_config

    try:
        load_link_config(preset)
    except ConfigError as err:
        raise ConfigError(f"--preset: {err}") from None
    return load_link_config(preset, overrides)


def check_baud(baud: int | None) -> None:
    """``--baud``: absent (the modem's default) or in :data:`testbed.hil.BAUD_RANGE` bit/s;
    else :class:`ConfigError` (checked before pyserial, which overflows above 2^31 − 1)."""
    from testbed.hil import BAUD_RANGE

    low, high = BAUD_RANGE
    if baud is not None and not low <= baud <= high:
        raise ConfigError(f"--baud: must be in [{low}, {high}] bit/s, got {baud}")


def check_only_with(options: Mapping[str, bool], used: bool, condition: str) -> None:
    """Options that take effect only under ``condition``: the first given one (``name →
    given``) is a :class:`ConfigError` unless ``used``, rather than silently ignored.

    Raises:
        ConfigError: e.g. ``--modem: only used with --operator-port and --vehicle-port``.
    """
    if used:
        return
    for option, given in options.items():
        if given:
            raise ConfigError(f"{option}: only used with {condition}")


def check_out_dir(out: Path) -> None:
    """``--out``: a directory or nothing yet; else :class:`ConfigError` (also when the path
    cannot even be looked at: a name too long, a component that is not a directory…)."""
    try:
        if out.exists() and not out.is_dir():
            raise ConfigError(f"--out: {out} exists and is not a directory")
    except OSError as err:
        raise ConfigError(f"--out: {out}: {err.strerror or err}") from None


def open_modem_ports(
    ports: Mapping[str, tuple[str, PortSettings]], *, log_bytes: bool = False
) -> dict[str, LinkEndpoint]:
    """Each role's modem endpoint on its port (``role → (option, settings)``), in order; with
    ``log_bytes``, each transport keeps every byte it reads and writes (its ``byte_log``).

    Raises:
        ConfigError: a port cannot be opened (no such device, a bad pyserial URL or option):
            one line naming its option, after the endpoints already open are closed.
    """
    from testbed.hil import PORT_ERRORS, open_endpoint

    # pyserial: OSError (no such port), ValueError (unknown URL scheme), KeyError (bad option),
    # OverflowError (a baud rate its termios call cannot hold)…
    errors: tuple[type[Exception], ...] = (*PORT_ERRORS, LookupError, OverflowError)
    endpoints: dict[str, LinkEndpoint] = {}
    try:
        for role, (option, settings) in ports.items():
            _check_socket_url(option, settings.url)
            try:
                endpoints[role] = open_endpoint(settings, log_bytes=log_bytes)
            except errors as err:
                reason = " ".join(str(err).split()) or type(err).__name__
                raise ConfigError(f"{option}: cannot open {settings.url}: {reason}") from None
    except BaseException:
        for endpoint in endpoints.values():
            endpoint.close()
        raise
    return endpoints


_SOCKET_OPTIONS = frozenset({"logging"})
"""The URL options pyserial's ``socket://`` handler knows."""


def _check_socket_url(option: str, url: str) -> None:
    """A ``socket://`` URL names its host and port and only options pyserial knows (its own
    messages for these were ``'<=' not supported between instances of 'int' and 'NoneType'``
    and ``'debug|info|warning|error'``).

    Raises:
        ConfigError: naming the option and what is missing or unknown.
    """
    from urllib.parse import parse_qs, urlsplit

    if not url.startswith("socket://"):
        return
    try:
        parts = urlsplit(url)
    except ValueError as err:  # an unclosed [IPv6 bracket
        raise ConfigError(f"{option}: {url}: not a socket:// URL ({err})") from None
    try:
        port = parts.port
    except ValueError:  # not a number, or out of range
        port = None
    if not parts.hostname or port is None:
        raise ConfigError(f"{option}: {url}: a socket:// URL needs a host and a port (host:port)")
    unknown = sorted(set(parse_qs(parts.query, keep_blank_values=True)) - _SOCKET_OPTIONS)
    if unknown:
        raise ConfigError(
            f"{option}: {url}: unknown URL option {unknown[0]!r} (socket:// takes: logging)"
        )


def warn_token_cycle(scenario: Scenario) -> None:
    """One ``testbed: warning:`` line on stderr when the scenario's token gap is shorter than
    a move order's round trip (:class:`~testbed.run.run_metrics.TokenCycle`); the run goes on,
    since that may be what is studied, and ``metrics.json`` says ``reply_fits_gap: false``."""
    from testbed.run.run_metrics import token_cycle

    cycle = token_cycle(scenario)
    if cycle is not None and not cycle.fits:
        print(f"testbed: warning: {cycle.warning(scenario.link.ipg)}", file=sys.stderr)


def warn_late_goals(scenario: Scenario) -> None:
    """One ``testbed: warning:`` line on stderr when the scripted supervisor's goals come at or
    after the run's end (``testbed run``, which runs ``duration_s`` with that pilot): they are
    never sent. A shortened run (``--set duration_s=30``) may mean it: a line, not a refusal."""
    end = scenario.duration_s
    late = [i for i, goal in enumerate(scenario.pilot.goals) if goal.t_s >= end]
    if late:
        which = f"pilot.goals[{late[0]}]" + (f"…[{late[-1]}]" if len(late) > 1 else "")
        print(
            f"testbed: warning: {which} at t ≥ {scenario.pilot.goals[late[0]].t_s:g} s come "
            f"after the run's end ({end:g} s): not sent",
            file=sys.stderr,
        )
