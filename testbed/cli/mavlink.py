"""``testbed mavlink``: the simulated vehicle speaks ArduSub; a real ground station drives it.

Usage::

    testbed mavlink [SCENARIO] [--gcs URL]... [--link PRESET] [--operator-port P --vehicle-port P]
                    [--duration S] [--out DIR] [options]

Runs the scenario's vehicle in real time with an ArduSub-compatible MAVLink endpoint as its
pilot (:func:`testbed.run.mavlink_run.run_mavlink`). With ``--link PRESET`` (any channel
preset: ``s100``, ``m64``, ``s2c``, ``tether``) both nodes run in real time over that simulated
link with the scenario's codec and medium access, and the endpoint is a gateway on the operator
node (:func:`testbed.run.mavlink_gateway.run_gateway`); ``--operator-port`` and
``--vehicle-port`` (with ``--modem``, ``--baud``, ``--rtscts`` as in ``testbed hil``) put the
two nodes' frames through real serial modems instead: not with ``--link``, and those three
options only with the ports (an option that would be ignored is an error). ``--duration`` is at
most a day (86400 s), as in ``testbed run``. ``--gcs`` (repeatable) names a link:
``udpout:HOST:PORT`` (default ``udpout:127.0.0.1:14550``, where QGroundControl and MAVProxy
listen), ``udpin:HOST:PORT``, ``tcpin:HOST:PORT`` or ``serial:PORT[,BAUD]`` / a pyserial URL;
addresses are 127.0.0.1 unless given; the n-th link (from 0) is ArduPilot's SERIALn, so
``--param SERIAL1_PROTOCOL=43`` makes the second a MAVLink High Latency link (docs/mavlink.md).
Options: ``--param NAME=VALUE`` (repeatable, boot values), ``--set K=V`` (repeatable),
``--seed``, ``--force``, ``--no-plots``.

Outputs are those of ``testbed run`` (``metrics.json`` last, ``events.csv``, ``series.csv``,
plots), plus ``metrics.json``'s ``mavlink`` section
(:func:`~testbed.run.mavlink_run.mavlink_metrics`).
``--out`` is checked before any port is opened. A bad option, a control law of one's own
that does not build (``[vehicle.control]``, the line ``testbed run`` prints) or a link that
cannot be opened prints one line and exits 2, before the session is announced; Ctrl-C or
SIGTERM ends the session with one line, keeping what ran (exit 130 / 143).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

from testbed.cli.options import (
    Subparsers,
    add_set_option,
    check_baud,
    check_duration,
    check_only_with,
    check_seed,
    format_value,
    open_modem_ports,
    warn_token_cycle,
)
from testbed.config import ConfigError

__all__ = ["add_mavlink_parser", "format_mavlink_summary", "run_mavlink_command"]

_DEFAULT_GCS = "udpout:127.0.0.1:14550"
_MODEMS = ("s100", "evologics", "m64", "raw")  # = testbed.hil.MODEM_KINDS


def add_mavlink_parser(sub: Subparsers) -> None:
    """``testbed mavlink``: a ground station drives the simulated vehicle over MAVLink."""
    parser = sub.add_parser(
        "mavlink",
        help="run the vehicle in real time as an ArduSub MAVLink vehicle for a ground station",
        description="Run the scenario's simulated vehicle in real time behind an "
        "ArduSub-compatible MAVLink endpoint (system 1, component 1, MAVLink 2), so "
        "QGroundControl, MAVProxy or pymavlink can arm it, change modes and fly it. Writes "
        "what `testbed run` writes, plus MAVLink counters and the GCS-to-thruster latency.",
    )
    parser.add_argument(
        "scenario",
        nargs="?",
        default="s100-teleop-v1",
        help="packaged scenario id or a .toml path (its vehicle is used; default: s100-teleop-v1)",
    )
    parser.add_argument(
        "--gcs",
        action="append",
        default=[],
        metavar="URL",
        help=f"ground-station link (repeatable; default {_DEFAULT_GCS}): udpout:HOST:PORT, "
        "udpin:HOST:PORT, tcpin:HOST:PORT, serial:PORT[,BAUD]; the n-th (from 0) is SERIALn: "
        "--param SERIALn_PROTOCOL=43 makes it a high-latency link",
    )
    parser.add_argument(
        "--duration",
        type=float,
        default=None,
        help="seconds to run, at most 86400 (default: the scenario's)",
    )
    parser.add_argument(
        "--link",
        default=None,
        metavar="PRESET",
        help="gateway through the narrow link: both nodes in real time over this channel preset "
        "(s100, m64, s2c, tether), MAVLink on the operator node; not with the modem ports",
    )
    parser.add_argument(
        "--operator-port", default=None, help="gateway over real modems: the operator's port"
    )
    parser.add_argument(
        "--vehicle-port", default=None, help="gateway over real modems: the vehicle's port"
    )
    parser.add_argument(
        "--modem",
        choices=_MODEMS,
        default=None,
        help="modem on the ports, with --operator-port/--vehicle-port only (default: s100)",
    )
    parser.add_argument(
        "--baud",
        type=int,
        default=None,
        help="modem port speed [bit/s], 50..12000000, with the ports only (default by modem)",
    )
    parser.add_argument(
        "--rtscts", action="store_true", help="RTS/CTS flow control, with the modem ports only"
    )
    add_set_option(parser, "override a scenario key, e.g. --set vehicle.thrusters=bluerov2-heavy")
    parser.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="an ArduSub parameter's value at boot (repeatable), e.g. SYSID_THISMAV=2 or "
        "JS_GAIN_DEFAULT=0.8: those ArduSub reads only at boot take a PARAM_SET at the next boot",
    )
    parser.add_argument("--seed", type=int, default=None, help="random seed (vehicle sensors)")
    parser.add_argument(
        "--out", type=Path, default=None, help="output directory (default: runs/mavlink-…)"
    )
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    parser.add_argument(
        "--force", action="store_true", help="write into a non-empty --out, replacing results"
    )
    parser.set_defaults(handler=run_mavlink_command)


def run_mavlink_command(args: argparse.Namespace) -> int:
    """Handler of ``testbed mavlink``: check, open the links, run in real time, write."""
    from testbed.cli.run import finish_run, report_failed_run
    from testbed.mavlink.links import open_link, parse_url
    from testbed.run.failures import partial_run
    from testbed.run.mavlink_run import run_mavlink
    from testbed.run.outputs import claimed_out_dir, write_run
    from testbed.run.plugin_calls import scenario_control_laws
    from testbed.run.scenario import load_scenario

    ports = {"operator": args.operator_port, "vehicle": args.vehicle_port}
    hil = any(ports.values())
    if hil and not all(ports.values()):
        missing = "--vehicle-port" if args.operator_port else "--operator-port"
        raise ConfigError(f"{missing}: required with the other modem port")
    if hil and args.operator_port == args.vehicle_port:
        raise ConfigError("--vehicle-port: must differ from --operator-port")
    if hil and args.link is not None:
        raise ConfigError(
            "--link: not with --operator-port and --vehicle-port (the modems are the link)"
        )
    given = {"--modem": args.modem is not None, "--baud": args.baud is not None}
    given["--rtscts"] = args.rtscts
    check_only_with(given, hil, "--operator-port and --vehicle-port")
    check_baud(args.baud)
    modem = args.modem or "s100"
    overrides = list(args.overrides)
    if args.link is not None:
        from testbed.channel import preset_names

        if args.link not in preset_names():
            raise ConfigError(
                f"--link: unknown preset {args.link!r}; one of {', '.join(preset_names())}"
            )
        overrides.insert(0, f"link.preset={args.link}")
    gateway = args.link is not None or hil
    urls = args.gcs or [_DEFAULT_GCS]
    for url in urls:
        try:
            parse_url(url)
        except ValueError as err:
            raise ConfigError(f"--gcs: {err}") from None
    repeated = sorted({url for url in urls if urls.count(url) > 1})
    if repeated:  # two links on one address: every packet handled twice
        raise ConfigError(f"--gcs: {repeated[0]} is given more than once")
    check_seed(args.seed)
    boot_params = _boot_params(args.param)
    scenario = load_scenario(args.scenario, overrides)
    warn_token_cycle(scenario)
    duration = scenario.duration_s if args.duration is None else args.duration
    check_duration(duration)
    out = args.out
    if out is None:
        out = Path("runs") / f"mavlink-{scenario.id}-{time.strftime('%Y%m%d-%H%M%S')}"
    with claimed_out_dir(out, force=args.force):
        # a control law of one's own that does not build is bad input, one line as in
        # `testbed run`, before a link opens or anything runs (the run makes its laws afresh)
        scenario_control_laws(scenario, scenario.seed if args.seed is None else args.seed)
        links: list[Any] = []
        try:
            for url in urls:
                try:
                    links.append(open_link(url))
                except (OSError, ValueError, LookupError, OverflowError) as err:  # pyserial's
                    reason = " ".join(str(err).split()) or type(err).__name__
                    raise ConfigError(f"--gcs: cannot open {url}: {reason}") from None
        except BaseException:
            for link in links:
                link.close()
            raise
        endpoints: dict[str, Any] = {}
        if hil:
            endpoints = _open_modems(args, modem, ports, links)
        where = ", ".join(urls)
        if gateway:
            via = f"{modem} modems" if hil else f"the {scenario.link.preset} link"
            what = f"gateway to the vehicle through {via} ({scenario.link.codec})"
        else:
            what = "ArduSub vehicle (sysid 1)"
        print(
            f"testbed: mavlink: {what} on {where}; running {duration:g} s, Ctrl-C ends early",
            file=sys.stderr,
            flush=True,
        )
        try:
            if gateway:
                from testbed.run.mavlink_gateway import run_gateway

                result = run_gateway(
                    scenario,
                    links,
                    seed=args.seed,
                    duration_s=duration,
                    hil=endpoints or None,
                    modem=modem if hil else "",
                    boot_params=boot_params,
                )
            else:
                result = run_mavlink(
                    scenario, links, seed=args.seed, duration_s=duration, boot_params=boot_params
                )
        except Exception as error:  # part way (a control law of the user's): keep what ran
            if (partial := partial_run(error)) is None:
                raise
            write_run(partial, out)
            return report_failed_run(error, out, duration)
        return finish_run(
            result, out, plots=not args.no_plots, planned_s=duration, summary=format_mavlink_summary
        )


def _boot_params(given: list[str]) -> dict[str, float]:
    """``--param NAME=VALUE`` values, checked against ArduSub's table (one line naming the
    option and the parameter for an unknown name or a value it refuses)."""
    from testbed.mavlink.params import ParamTable

    table = ParamTable()
    values: dict[str, float] = {}
    for text in given:
        name, sep, raw = text.partition("=")
        name = name.strip().upper()
        if not sep or not name:
            raise ConfigError(f"--param {text!r}: expected NAME=VALUE")
        try:
            values[name] = table.boot_value(name, float(raw))
        except ValueError as err:  # not a number, an unknown name, a refused value
            raise ConfigError(f"--param {text!r}: {err}") from None
    return values


def _open_modems(
    args: argparse.Namespace, modem: str, ports: dict[str, str], links: list[Any]
) -> dict[str, Any]:
    """The two HIL modem endpoints (on failure the links and what opened are closed)."""
    from testbed.hil import PortSettings

    try:
        return open_modem_ports(
            {
                role: (
                    f"--{role}-port",
                    PortSettings(url, modem, role, args.baud, args.rtscts),
                )
                for role, url in ports.items()
            }
        )
    except BaseException:
        for link in links:
            link.close()
        raise


def format_mavlink_summary(metrics: dict[str, Any], out: Path) -> str:
    """A few lines a person reads after a MAVLink session (NaN shows as n/a)."""

    def ms(value: float | None) -> str:
        return format_value(value, digits=1, unit=" ms")

    section = metrics["mavlink"]
    latency = section["gcs_to_thruster_ms"]
    rejected = section["rejected"]
    rejected_text = ", ".join(f"{k} {v}" for k, v in rejected.items()) or "none"
    sent = sum(section["sent"].values())
    lines = [
        f"mavlink {metrics['scenario']}: {metrics['sim_s']:.1f} s in real time",
        f"  received {sum(section['received'].values())} messages, accepted "
        f"{section['accepted']}, pilot inputs {section['pilot_inputs']}; rejected: "
        f"{rejected_text}",
        f"  sent {sent} packets; failsafes {section['failsafes'] or 'none'}",
        f"  GCS-to-thruster p50 {ms(latency['p50'])} p95 {ms(latency['p95'])} max "
        f"{ms(latency['max'])} (n {latency['n']})",
    ]
    if section.get("gateway"):
        age = section["state_age_s"]
        lines.append(
            f"  vehicle state age on shore mean {ms(1000 * age['mean'])} p95 "
            f"{ms(1000 * age['p95'])}; stale warnings {section['stale_warnings']}"
        )
    lines.append(f"  wrote {out}/")
    return "\n".join(lines)
