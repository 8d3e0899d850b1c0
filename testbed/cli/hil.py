"""``testbed hil``: a scenario's nodes in real time with their frames through serial modems.

Usage (any pyserial URL as a port: ``/dev/ttyUSB0``, ``socket://host:9200``, ``rfc2217://…``)::

    testbed hil [SCENARIO] --operator-port P1 --vehicle-port P2 [--modem M] [options]
    testbed hil vehicle [SCENARIO] --port P [--modem M] [options]
    testbed hil operator [SCENARIO] --port P [--modem M] [options]

The first form runs the operator and the simulated vehicle on this computer, each on its own
modem (the paper's Fig. 4a); the other two run one node each, for two computers. Options:
``--set K=V`` (repeatable), ``--seed``, ``--duration S`` (at most a day, 86400 s, as ``testbed
run``), ``--out DIR``, ``--force``, ``--baud``, ``--rtscts``, ``--m64-channel`` (with ``--modem
m64`` only: an option that would be ignored is an error), ``--no-plots``. Outputs are those of
``testbed run`` (``metrics.json``, ``events.csv``, ``series.csv``, plots), written as ``testbed
run`` writes them (:func:`testbed.run.outputs.write_run`: ``metrics.json`` last, with
``"complete"`` and ``"files"``), plus the ``hil`` section of ``metrics.json`` (see
:func:`testbed.run.hil_metrics.hil_metrics`).

``--out`` is checked before any port is opened (creatable, writable, empty unless
``--force``). Ctrl-C or SIGTERM ends a session at any time, even before ``metrics.settle_s``:
what ran is written, marked ``"complete": false`` with the ``sim_s`` reached (no plots), and
the command ends with one line, ``testbed: interrupted at t = … s of … s; partial results in
DIR``, and exit code 130 (SIGINT) or 143 (SIGTERM).

A user's mistake (a bad option, a port that cannot be opened, e.g. ``bogus://x``) prints one
line naming the option and exits 2 (the CLI's :class:`~testbed.config.ConfigError` path).
This module is wired into :mod:`testbed.cli.main`; heavy imports happen only when the command
runs.
"""

from __future__ import annotations

import argparse
import functools
import os
import sys
import time
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from testbed.cli.options import (
    Subparsers,
    check_baud,
    check_duration,
    check_only_with,
    check_seed,
    format_value,
    open_modem_ports,
)
from testbed.cli.run_summary import loss_note
from testbed.config import ConfigError

if TYPE_CHECKING:
    from testbed.hil import LinkEndpoint
    from testbed.run.scenario_config import Scenario

__all__ = ["add_hil_arguments", "add_hil_parser", "format_hil_summary", "run_hil_command"]

_MODES = ("vehicle", "operator")
_MODEMS = ("s100", "evologics", "m64", "raw")  # = testbed.hil.MODEM_KINDS (checked in tests)


def add_hil_parser(sub: Subparsers) -> None:
    """``testbed hil``: the nodes in real time over serial modems."""
    hil = sub.add_parser(
        "hil",
        help="run a scenario in real time with its frames through serial modems",
        description="Hardware in the loop: run the operator and the simulated vehicle in real "
        "time, their frames through real (or emulated) modems on serial ports or any pyserial "
        "URL. `testbed hil --operator-port P1 --vehicle-port P2` runs both nodes here; `testbed "
        "hil vehicle|operator --port P` runs one node, its peer on another computer. Writes "
        "what `testbed run` writes, plus the software's added latency.",
        usage="testbed hil [vehicle|operator] [SCENARIO] (--operator-port P1 --vehicle-port P2 "
        "| --port P) [--modem M] [options]",
    )
    add_hil_arguments(hil)


def add_hil_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``testbed hil`` arguments to ``parser`` and set its handler."""
    parser.add_argument(
        "words",
        nargs="*",
        metavar="[vehicle|operator] [SCENARIO]",
        help="run one node only (two computers), and/or the scenario: a packaged id or a "
        ".toml path (default: s100-teleop-v1)",
    )
    parser.add_argument("--operator-port", default=None, help="the operator's modem port")
    parser.add_argument("--vehicle-port", default=None, help="the vehicle's modem port")
    parser.add_argument(
        "--port", default=None, help="this node's modem port (with `hil vehicle|operator`)"
    )
    parser.add_argument(
        "--modem", choices=_MODEMS, default="s100", help="modem on the port(s) (default: s100)"
    )
    parser.add_argument(
        "--baud",
        type=int,
        default=None,
        help="port speed in bit/s, 50..12000000 (default by modem: s100 9600, evologics 19200, "
        "m64 115200)",
    )
    parser.add_argument(
        "--rtscts", action="store_true", help="RTS/CTS hardware flow control (S100: unpaced)"
    )
    parser.add_argument(
        "--log-bytes",
        action="store_true",
        help="record every byte each port read and wrote, with its time, in ports.csv",
    )
    parser.add_argument(
        "--m64-channel",
        type=int,
        default=None,
        help="Water Linked channel 1-7, with --modem m64 only (default: 4)",
    )
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a scenario key, e.g. --set operator.arm_at_s=2 (repeatable)",
    )
    parser.add_argument("--seed", type=int, default=None, help="random seed (vehicle sensors)")
    parser.add_argument(
        "--duration",
        type=float,
        default=None,
        help="seconds to run, at most 86400 (default: the scenario's)",
    )
    parser.add_argument(
        "--out", type=Path, default=None, help="output directory (default: runs/hil-…)"
    )
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    parser.add_argument(
        "--force",
        action="store_true",
        help="write into a non-empty --out, replacing the results there",
    )
    parser.set_defaults(handler=run_hil_command)


def _words(words: list[str]) -> tuple[str, str]:
    """``(mode, scenario)`` from the positional words; mode ``both`` when none is named."""
    mode = "both"
    if words and words[0] in _MODES:
        mode, words = words[0], words[1:]
    if len(words) > 1:
        raise ConfigError(f"hil: unexpected argument {words[1]!r} (one scenario at most)")
    return mode, words[0] if words else "s100-teleop-v1"


def _warn_laws_not_here(scenario: Scenario) -> None:
    """One ``testbed: warning:`` line on stderr when ``[vehicle.control]`` names a law of the
    user's own and only the operator node runs here: the vehicle node, on the other computer,
    flies the laws its own scenario names (``metrics.json``'s ``inputs`` still records them)."""
    laws = [f"vehicle.control.{name}" for name in scenario.control_laws.targets()]
    if laws:
        print(
            f"testbed: warning: {' and '.join(laws)}: not flown by `hil operator` (the vehicle "
            "node flies the laws of its own scenario, on its computer)",
            file=sys.stderr,
        )


def _ports(args: argparse.Namespace, mode: str) -> dict[str, tuple[str, str]]:
    """Role → (option name, URL), checked against the mode."""
    pair = {
        "operator": ("--operator-port", args.operator_port),
        "vehicle": ("--vehicle-port", args.vehicle_port),
    }
    if mode == "both":
        if args.port is not None:
            raise ConfigError("--port: only with `testbed hil vehicle|operator`")
        for option, url in pair.values():
            if not url:
                raise ConfigError(
                    f"{option}: required (or run one node: `testbed hil vehicle|operator --port P`)"
                )
        if _same_device(args.operator_port, args.vehicle_port):
            raise ConfigError(
                f"--vehicle-port: must differ from --operator-port ({args.vehicle_port} and "
                f"{args.operator_port} are the same device)"
            )
        return pair
    for option, url in pair.values():
        if url is not None:
            raise ConfigError(f"{option}: not with `testbed hil {mode}`; use --port")
    if not args.port:
        raise ConfigError(f"--port: required with `testbed hil {mode}`")
    return {mode: ("--port", args.port)}


def _same_device(a: str, b: str) -> bool:
    """Whether two port names are one port: the same text, or two paths to one device (a
    ``/dev/serial/by-id/…`` link and the ``/dev/ttyUSB0`` it points to)."""
    if a == b:
        return True
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):  # a URL (socket://, loop://) or a path to nothing yet
        return False


def run_hil_command(args: argparse.Namespace) -> int:
    """Handler of ``testbed hil``: check, open the ports, run in real time, write, summarise."""
    from testbed.cli.run import finish_run, report_failed_run
    from testbed.hil import PortSettings
    from testbed.run.failures import partial_run
    from testbed.run.outputs import claimed_out_dir, write_run
    from testbed.run.realtime import run_hil
    from testbed.run.scenario import load_scenario

    mode, scenario_name = _words(args.words)
    ports = _ports(args, mode)
    check_baud(args.baud)
    check_only_with(
        {"--m64-channel": args.m64_channel is not None}, args.modem == "m64", "--modem m64"
    )
    if args.m64_channel is not None and not 1 <= args.m64_channel <= 7:
        raise ConfigError(f"--m64-channel: must be 1..7, got {args.m64_channel}")
    check_seed(args.seed)
    scenario = load_scenario(scenario_name, args.overrides)
    duration = scenario.duration_s if args.duration is None else args.duration
    settle = scenario.metrics.settle_s
    check_duration(duration, low_s=settle, low_note=" (above the scenario's metrics.settle_s)")
    if mode == "operator":
        _warn_laws_not_here(scenario)
    out = args.out
    if out is None:
        out = Path("runs") / f"hil-{scenario.id}-{mode}-{time.strftime('%Y%m%d-%H%M%S')}"
    with claimed_out_dir(out, force=args.force):  # before any port is opened or any time is spent
        modem, baud, rtscts = args.modem, args.baud, args.rtscts
        channel = {} if args.m64_channel is None else {"m64_channel": args.m64_channel}
        endpoints = open_modem_ports(
            {
                role: (option, PortSettings(url, modem, role, baud, rtscts, **channel))
                for role, (option, url) in ports.items()
            },
            log_bytes=args.log_bytes,
        )
        where = ", ".join(f"{role} on {url}" for role, (_, url) in ports.items())
        clock_start_ns: list[int] = []

        def announce() -> None:  # once the nodes are built and the real-time clock starts
            clock_start_ns.append(time.perf_counter_ns())
            print(
                f"testbed: hil {mode}: {where} ({args.modem}); running {duration:g} s, "
                "Ctrl-C ends early",
                file=sys.stderr,
                flush=True,
            )

        ports_used = {  # what a rerun needs beside the scenario's inputs
            "baud": baud,
            "rtscts": rtscts,
            "m64_channel": args.m64_channel,
            "duration_s": duration,
        }
        extras = None
        if args.log_bytes:
            start_ns = clock_start_ns[0] if clock_start_ns else 0
            extras = {"ports.csv": functools.partial(write_port_log, endpoints, start_ns)}
        try:
            result = run_hil(
                scenario,
                endpoints,
                seed=args.seed,
                duration_s=duration,
                modem=args.modem,
                on_start=announce,
            )
        except Exception as error:  # part way (a pilot of the user's): keep what ran
            if (partial := partial_run(error)) is None:
                raise
            partial.metrics["hil"]["ports"] = ports_used
            write_run(partial, out, extras=extras)
            return report_failed_run(error, out, duration)
        result.metrics["hil"]["ports"] = ports_used
        return finish_run(
            result,
            out,
            plots=not args.no_plots,
            planned_s=duration,
            summary=format_hil_summary,
            extras=extras,
        )


def write_port_log(endpoints: Mapping[str, LinkEndpoint], start_ns: int, path: Path) -> None:
    """``ports.csv``: every byte each port read and wrote (``--log-bytes``), one row per read
    or write in time order: ``t_s`` (from the run's clock start; setup writes before it are
    negative), ``port`` (the node), ``dir`` (``in`` read, ``out`` written), ``bytes`` (count),
    ``hex`` (the bytes)."""
    rows = sorted(
        (t_ns, role, direction, data)
        for role, endpoint in endpoints.items()
        for t_ns, direction, data in endpoint.transport.byte_log or ()
    )
    with path.open("w", encoding="utf-8", newline="") as out:
        out.write("t_s,port,dir,bytes,hex\n")
        for t_ns, role, direction, data in rows:
            out.write(
                f"{(t_ns - start_ns) / 1e9:.6f},{role},{direction},{len(data)},{data.hex()}\n"
            )


def _last_errors(reports: Iterable[dict[str, Any]]) -> str:
    """The endpoints' last port errors, ``; ``-joined."""
    return "; ".join(r["last_error"] for r in reports if r["last_error"])


def format_hil_summary(metrics: dict[str, Any], out: Path) -> str:
    """A few lines a person reads after a HIL run (NaN shows as n/a)."""

    def ms(value: float | None, digits: int = 0) -> str:
        return format_value(value, 1000.0, digits, " ms")

    def count(value: float | None) -> str:
        return format_value(value, digits=0)

    def percent(value: float | None) -> str:
        return format_value(value, 100.0, 2, " %")

    def losses(direction: dict[str, Any]) -> str:  # the simulated run's words where known
        known = json_ready(direction)  # NaN, not known here: None, as in metrics.json
        return "" if known["frames_dropped"] is None else loss_note(known)

    from testbed.run.outputs import json_ready

    hil = metrics["hil"]
    up, down = metrics["link"]["uplink"], metrics["link"]["downlink"]
    added = hil["added_latency_ms"]
    lag, rtt = metrics["command_lag_s"], hil["round_trip_s"]
    reports = hil["endpoints"].values()
    errors = sum(r["port_errors"] for r in reports)
    failures = sum(r["reopen_failures"] for r in reports)
    lines = [
        f"hil {metrics['scenario']} ({hil['mode']}, {hil['modem']}): "
        f"{metrics['sim_s']:.1f} s in real time",
        f"  uplink   sent {count(up['frames_sent'])}, delivered {count(up['frames_delivered'])}"
        f", PER {percent(up['per'])}{losses(up)}",
        f"  downlink sent {count(down['frames_sent'])}, delivered "
        f"{count(down['frames_delivered'])}, PER {percent(down['per'])}{losses(down)}",
        f"  command lag mean {ms(lag['mean'])} p95 {ms(lag['p95'])}; round trip mean "
        f"{ms(rtt['mean'])}",
        f"  added latency p50 {ms(added['p50'] / 1000, 2)} p95 {ms(added['p95'] / 1000, 2)} "
        f"max {ms(added['max'] / 1000, 2)}; port errors {errors}, reopens {hil['reopens']}, "
        f"failed reopens {failures}; garbage {hil['garbage_bytes']} B",
    ]
    failsafe = metrics["events"].get("failsafe")
    if failsafe and failsafe == failsafe:  # not NaN: the vehicle runs here
        lines.append(f"  failsafe engaged {failsafe} time(s) (events.csv: when)")
    for name, direction in (("uplink", up), ("downlink", down)):
        if direction["frames_sent"] and direction["frames_delivered"] == 0:
            lines.append(
                f"  warning: no {name} frame arrived: check --modem, the ports (not one device) "
                "and that a reply fits the gap (docs/hil.md)"
            )
    if errors:
        lines.append(f"  warning: a port failed {errors} time(s): {_last_errors(reports)}")
    lines.append(f"  wrote {out}/")
    return "\n".join(lines)
