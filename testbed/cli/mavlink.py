"""``testbed mavlink``: the simulated vehicle speaks ArduSub; a real ground station drives it.

Usage::

    testbed mavlink [SCENARIO] [--gcs URL]... [--duration S] [--out DIR] [options]

Runs the scenario's vehicle in real time with an ArduSub-compatible MAVLink endpoint as its
pilot (:func:`testbed.run.mavlink_run.run_mavlink`). ``--gcs`` (repeatable) names a link:
``udpout:HOST:PORT`` (default ``udpout:127.0.0.1:14550``, where QGroundControl and MAVProxy
listen), ``udpin:HOST:PORT``, ``tcpin:HOST:PORT`` or ``serial:PORT[,BAUD]`` / a pyserial URL;
addresses are 127.0.0.1 unless given. Options: ``--set K=V`` (repeatable), ``--seed``,
``--force``, ``--no-plots``. ``--link`` (the narrow-link gateway) is refused: not yet.

Outputs are those of ``testbed run`` (``metrics.json`` last, ``events.csv``, ``series.csv``,
plots), plus ``metrics.json``'s ``mavlink`` section
(:func:`~testbed.run.mavlink_run.mavlink_metrics`).
``--out`` is checked before any port is opened. A bad option or a link that cannot be opened
prints one line and exits 2; Ctrl-C or SIGTERM ends the session with one line, keeping what ran
(exit 130 / 143).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from typing import Any

from testbed.cli.options import Subparsers, add_set_option, check_seed
from testbed.config import ConfigError

__all__ = ["add_mavlink_parser", "format_mavlink_summary", "run_mavlink_command"]

_DEFAULT_GCS = "udpout:127.0.0.1:14550"


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
        "udpin:HOST:PORT, tcpin:HOST:PORT, serial:PORT[,BAUD]",
    )
    parser.add_argument(
        "--duration", type=float, default=None, help="seconds to run (default: the scenario's)"
    )
    parser.add_argument(
        "--link", default=None, help="the narrow-link gateway (not implemented yet: refused)"
    )
    add_set_option(parser, "override a scenario key, e.g. --set vehicle.thrusters=bluerov2-heavy")
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
    from testbed.cli.run import finish_run
    from testbed.mavlink.links import open_link, parse_url
    from testbed.run.mavlink_run import run_mavlink
    from testbed.run.outputs import prepare_out_dir
    from testbed.run.scenario import load_scenario

    if args.link is not None:
        raise ConfigError(
            "--link: the MAVLink gateway through the narrow link is not implemented yet; "
            "run without --link (the ground station talks to the vehicle directly)"
        )
    urls = args.gcs or [_DEFAULT_GCS]
    for url in urls:
        try:
            parse_url(url)
        except ValueError as err:
            raise ConfigError(f"--gcs: {err}") from None
    check_seed(args.seed)
    scenario = load_scenario(args.scenario, args.overrides)
    duration = scenario.duration_s if args.duration is None else args.duration
    if not (math.isfinite(duration) and duration > 0.0):
        raise ConfigError(f"--duration: must be > 0 s, got {duration:g}")
    out = args.out
    if out is None:
        out = Path("runs") / f"mavlink-{scenario.id}-{time.strftime('%Y%m%d-%H%M%S')}"
    prepare_out_dir(out, force=args.force)
    links: list[Any] = []
    try:
        for url in urls:
            try:
                links.append(open_link(url))
            except OSError as err:
                reason = " ".join(str(err).split()) or type(err).__name__
                raise ConfigError(f"--gcs: cannot open {url}: {reason}") from None
    except BaseException:
        for link in links:
            link.close()
        raise
    print(
        f"testbed: mavlink: ArduSub vehicle (sysid 1) on {', '.join(urls)}; running "
        f"{duration:g} s, Ctrl-C ends early",
        file=sys.stderr,
        flush=True,
    )
    result = run_mavlink(scenario, links, seed=args.seed, duration_s=duration)
    return finish_run(
        result, out, plots=not args.no_plots, planned_s=duration, summary=format_mavlink_summary
    )


def format_mavlink_summary(metrics: dict[str, Any], out: Path) -> str:
    """A few lines a person reads after a MAVLink session (NaN shows as n/a)."""

    def ms(value: float | None) -> str:
        return "n/a" if value is None or value != value else f"{value:.1f} ms"

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
        f"  wrote {out}/",
    ]
    return "\n".join(lines)
