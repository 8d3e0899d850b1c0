"""``testbed live``: a person flies the vehicle through the simulated link, in a browser.

Usage::

    testbed live [SCENARIO] [--set K=V] [--port 8000] [--host 127.0.0.1] [--duration S]
                 [--seed N] [--out DIR] [--force] [--no-plots]
                 [--operator-port P1 --vehicle-port P2 [--modem M]]

Runs the scenario's nodes in real time (:mod:`testbed.live.session`) with a live pilot and
serves the console on ``http://HOST:PORT/`` (:mod:`testbed.live.server`; ``--port 0`` picks a
free port). The first line on stdout is ``testbed live: console on URL``. Default scenario:
``s100-video-v1`` (the S100 teleop link with the camera on); its scripted pilot and scheduled
image settings are replaced by the person at the console. With ``--operator-port`` and
``--vehicle-port`` (any pyserial URL, e.g. the PTYs of ``testbed modem-emulator``) the link is
real: each node's frames go through its modem as in ``testbed hil`` (``--modem``, default
s100, only with the ports: an option that would be ignored is an error), ``metrics.json`` gets
``testbed hil``'s ``hil`` section, and the console's link controls (BER, gap, outage,
distance) are refused — they act on the simulated link only. ``--duration`` is at most a day
(86400 s), as in ``testbed run``.

Ctrl-C (or SIGTERM, or ``--duration`` reached) ends the session and writes what ``testbed run``
writes (``metrics.json``, ``events.csv``, ``series.csv``, plots unless ``--no-plots``) with
a ``live`` section in ``metrics.json``; a session ended by Ctrl-C is marked ``"complete":
false`` with the ``sim_s`` it reached, and the command ends with one line,
``testbed live: session ended at t = … s; results in DIR``, exit code 130 (SIGTERM: 143;
``--duration`` reached: 0), as every command that Ctrl-C ends.

A user's mistake (bad option, a port that cannot be bound, a control law of one's own in
``[vehicle.control]`` that does not build: the line ``testbed run`` prints) is one line and exit
code 2, before any port is opened or the console announced.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

from testbed.cli.options import (
    EXIT_OK,
    Subparsers,
    add_set_option,
    check_duration,
    check_only_with,
    check_seed,
    exit_code_of,
    open_modem_ports,
    warn_token_cycle,
)
from testbed.config import ConfigError

__all__ = ["DEFAULT_SCENARIO", "add_live_parser"]

DEFAULT_SCENARIO = "s100-video-v1"
_MODEMS = ("s100", "evologics", "m64", "raw")  # = testbed.hil.MODEM_KINDS
_BOTH_PORTS = "--operator-port and --vehicle-port"


def add_live_parser(sub: Subparsers) -> None:
    """``testbed live``: real-time session piloted from a browser console."""
    live = sub.add_parser(
        "live",
        help="fly the vehicle yourself through the simulated link, from a browser console",
        description="Live teleoperation: the scenario's nodes in real time over the simulated "
        "link, piloted from a web console (keyboard or gamepad) that shows the operator's "
        "delayed view, the physics truth and the link. Ctrl-C ends it and writes the outputs.",
    )
    live.add_argument(
        "scenario",
        nargs="?",
        default=DEFAULT_SCENARIO,
        help=f"packaged scenario id or a .toml path (default: {DEFAULT_SCENARIO})",
    )
    add_set_option(live, "override a scenario key, e.g. --set link.ber=1e-4 (repeatable)")
    live.add_argument("--host", default="127.0.0.1", help="address to serve on (default: local)")
    live.add_argument("--port", type=int, default=8000, help="console port (default 8000; 0: any)")
    live.add_argument(
        "--duration",
        type=float,
        default=3600.0,
        help="session length [s], at most 86400 (default 3600; Ctrl-C ends it earlier)",
    )
    live.add_argument("--seed", type=int, default=None, help="random seed (default: scenario's)")
    live.add_argument("--out", type=Path, default=None, help="output directory")
    live.add_argument("--force", action="store_true", help="write into a non-empty --out")
    live.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    live.add_argument("--operator-port", default=None, help="HIL: the operator's modem port")
    live.add_argument("--vehicle-port", default=None, help="HIL: the vehicle's modem port")
    live.add_argument(
        "--modem",
        choices=_MODEMS,
        default=None,
        help="HIL: modem on the ports, with --operator-port/--vehicle-port only (default: s100)",
    )
    live.set_defaults(handler=_run_live)


def _bind_option(err: OSError) -> str:
    """The option a failed bind is about: ``--host`` when the address is unknown or not this
    machine's, ``--port`` otherwise (in use, privileged)."""
    import errno
    import socket

    if isinstance(err, socket.gaierror) or err.errno == errno.EADDRNOTAVAIL:
        return "--host"
    return "--port"


def _run_live(args: argparse.Namespace) -> int:
    """Handler of ``testbed live``."""
    from testbed.cli.run import report_failed_run
    from testbed.live.hub import Hub
    from testbed.live.server import ConsoleServer, bind
    from testbed.live.session import LiveSession
    from testbed.run.failures import partial_run
    from testbed.run.interrupts import deferred_interrupts
    from testbed.run.outputs import claimed_out_dir, write_run
    from testbed.run.plugin_calls import scenario_control_laws
    from testbed.run.scenario import load_scenario

    check_seed(args.seed)
    if not 0 <= args.port <= 65535:
        raise ConfigError(f"--port: must be 0..65535, got {args.port}")
    check_duration(args.duration)
    ports = _port_options(args)
    modem = args.modem or "s100"
    scenario = load_scenario(args.scenario, args.overrides)
    warn_token_cycle(scenario)
    out = args.out or Path("runs") / f"{scenario.id}-live-{time.strftime('%Y%m%d-%H%M%S')}"
    with claimed_out_dir(out, force=args.force):
        # a control law of one's own that does not build is bad input, one line as in
        # `testbed run`, before the console's port or a modem's is opened (the session makes
        # its laws afresh)
        scenario_control_laws(scenario, scenario.seed if args.seed is None else args.seed)
        try:
            sock = bind(args.host, args.port)
        except OSError as err:
            option = _bind_option(err)
            raise ConfigError(
                f"{option}: cannot serve on {args.host}:{args.port} ({err})"
            ) from None
        try:
            endpoints = _open_ports(ports, modem)
            hub = Hub()
            session = LiveSession(
                scenario, hub, seed=args.seed, pilot=None, endpoints=endpoints, modem=modem
            )
        except BaseException:
            sock.close()
            raise
        server = ConsoleServer(hub, session.pilot, sock, host=args.host)
        server.start()
        print(f"testbed live: console on {server.url}", flush=True)
        try:
            result = session.run(args.duration)
        except Exception as error:  # part way (a control law of the user's): keep what ran
            if (partial := partial_run(error)) is None:
                raise
            write_run(partial, out)
            return report_failed_run(error, out, args.duration)
        finally:
            with deferred_interrupts() as late:  # a second Ctrl-C: the session is ending
                server.stop()
        cut: list[KeyboardInterrupt] = []
        plots = None
        try:
            if not args.no_plots and not late:
                from testbed.report.run_plots import write_run_plots  # matplotlib: seconds

                plots = write_run_plots
        except KeyboardInterrupt as interrupt:  # a Ctrl-C while it loads: no plots
            cut.append(interrupt)
        try:
            write_run(result, out, plots=None if cut else plots)  # data and metrics.json whole
        except KeyboardInterrupt as interrupt:  # a Ctrl-C while writing: the plots cut short
            cut.append(interrupt)
        reached = result.metrics["sim_s"]
        kept = "results without plots" if (cut or late) and not args.no_plots else "results"
        print(
            f"testbed live: session ended at t = {reached:.1f} s; {kept} in {out}", file=sys.stderr
        )
        stopped = result.stopped or (late[0] if late else None) or (cut[0] if cut else None)
        return EXIT_OK if stopped is None else exit_code_of(stopped)


def _port_options(args: argparse.Namespace) -> dict[str, str] | None:
    """Role → URL of ``--operator-port``/``--vehicle-port`` (both or neither), or None for the
    simulated link; checked before anything is opened.

    Raises:
        ConfigError: one port without the other, the same port twice, ``--modem`` without them.
    """
    ports = {"operator": args.operator_port, "vehicle": args.vehicle_port}
    if not any(ports.values()):
        check_only_with({"--modem": args.modem is not None}, False, _BOTH_PORTS)
        return None
    for role, url in ports.items():
        if not url:
            raise ConfigError(f"--{role}-port: required with --{_other(role)}-port")
    if args.operator_port == args.vehicle_port:
        raise ConfigError("--vehicle-port: must differ from --operator-port")
    return ports


def _open_ports(ports: dict[str, str] | None, modem: str) -> dict[str, Any] | None:
    """The HIL endpoints of the ports (:func:`_port_options`), or None for the simulated link;
    a port that cannot be opened is a :class:`ConfigError` naming its option."""
    if ports is None:
        return None
    from testbed.hil import PortSettings

    return open_modem_ports(
        {role: (f"--{role}-port", PortSettings(url, modem, role)) for role, url in ports.items()}
    )


def _other(role: str) -> str:
    return "vehicle" if role == "operator" else "operator"
