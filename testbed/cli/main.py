"""Command-line interface: ``testbed run|link|sweep|plot|modem-emulator|hil|scenarios``.

Each subcommand parses its arguments, builds frozen configs through :mod:`testbed.config`, runs,
prints results to stdout and logs to stderr. A user's mistake (unknown key, bad value, missing
file) prints one line to stderr and returns exit code 2, never a traceback.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn

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
    _add_run_parser(sub)
    _add_link_parser(sub)
    _add_sweep_parser(sub)
    _add_plot_parser(sub)
    _add_modem_emulator_parser(sub)
    _add_hil_parser(sub)
    scenarios = sub.add_parser("scenarios", help="list the packaged scenarios")
    scenarios.set_defaults(handler=_list_scenarios)
    return parser


def _add_set_option(parser: argparse.ArgumentParser, help_text: str) -> None:
    """The repeatable ``--set KEY=VALUE`` override option, collected in ``args.overrides``."""
    parser.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE", help=help_text
    )


def _add_run_parser(sub: argparse._SubParsersAction[_Parser]) -> None:
    """``testbed run``: one end-to-end teleoperation run of a scenario."""
    run = sub.add_parser(
        "run",
        help="simulate one scenario end to end and write metrics, events and plots",
        description="Simulate a scenario: operator and vehicle, each with its ECS world, over "
        "the simulated link. Writes metrics.json, events.csv, series.csv and plots to --out.",
    )
    run.add_argument(
        "scenario",
        nargs="?",
        default="s100-teleop-v1",
        help="packaged scenario id or a .toml path (default: s100-teleop-v1; "
        "`testbed scenarios` lists them)",
    )
    _add_set_option(run, "override a scenario key, e.g. --set link.ber=1e-4 (repeatable)")
    run.add_argument("--seed", type=int, default=None, help="random seed (default: the scenario's)")
    run.add_argument(
        "--out", type=Path, default=None, help="output directory (default: runs/<id>-<time>/)"
    )
    run.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    run.set_defaults(handler=_run_scenario)


def _run_scenario(args: argparse.Namespace) -> int:
    """Handler of ``testbed run``: load, simulate, write, summarise."""
    import time

    from testbed.run.runner import run_scenario, write_outputs
    from testbed.run.scenario import load_scenario

    if args.seed is not None and args.seed < 0:
        raise ConfigError(f"--seed: must be ≥ 0, got {args.seed}")
    scenario = load_scenario(args.scenario, args.overrides)
    out = args.out
    if out is None:
        stamp = time.strftime("%Y%m%d-%H%M%S")
        out = Path("runs") / f"{scenario.id}-{stamp}"
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out: {out} exists and is not a directory")
    result = run_scenario(scenario, seed=args.seed)
    write_outputs(result, out, plots=not args.no_plots)
    print(format_summary(result.metrics, out))
    return EXIT_OK


def format_summary(metrics: dict[str, Any], out: Path) -> str:
    """A few lines a person reads after a run."""

    def ms(value: float | None) -> str:
        return "n/a" if value is None or value != value else f"{1000 * value:.0f} ms"

    up, down = metrics["link"]["uplink"], metrics["link"]["downlink"]
    lag, age = metrics["command_lag_s"], metrics["command_age_s"]
    yaw = metrics["attitude_error_deg"]["yaw"]
    lines = [
        f"{metrics['scenario']} seed {metrics['seed']}: {metrics['sim_s']:.0f} s simulated in "
        f"{metrics['wall_s']:.1f} s ({metrics['rtf']:.0f}x real time)",
        f"  uplink   {up['frames_delivered']}/{up['frames_sent']} frames, PER "
        f"{100 * up['per']:.2f} %, {up['goodput_bps']:.0f} bit/s",
        f"  downlink {down['frames_delivered']}/{down['frames_sent']} frames, PER "
        f"{100 * down['per']:.2f} %, {down['goodput_bps']:.0f} bit/s",
        f"  command lag mean {ms(lag['mean'])} p95 {ms(lag['p95'])}; command age mean "
        f"{ms(age['mean'])}; odometry age mean {ms(metrics['odometry_age_s']['mean'])}",
        f"  yaw error std {yaw['std']:.2f} deg; energy {metrics['energy_wh']:.3f} Wh",
    ]
    images = metrics.get("images")
    if images is not None:
        latency, psnr = images["latency_s"]["mean"], images["psnr_db"]["mean"]
        lines.append(
            f"  images {images['completed']}/{images['captured']} completed "
            f"({images['per_minute']:.1f}/min), latency mean "
            + ("n/a" if latency is None or latency != latency else f"{latency:.1f} s")
            + ", PSNR mean "
            + ("n/a" if psnr is None or psnr != psnr else f"{psnr:.1f} dB")
        )
    lines.append(f"  wrote {out}/")
    return "\n".join(lines)


def _list_scenarios(args: argparse.Namespace) -> int:
    """Handler of ``testbed scenarios``: one line per packaged scenario."""
    from testbed.run.scenario import load_scenario, scenario_names

    del args
    for name in scenario_names():
        print(f"{name:28s} {load_scenario(name).description.splitlines()[0]}")
    return EXIT_OK


def _add_link_parser(sub: argparse._SubParsersAction[_Parser]) -> None:
    """``testbed link``: one-way frame probe through the simulated channel (see channel.probe)."""
    link = sub.add_parser(
        "link",
        help="send frames one way through a simulated link and report PER, goodput, latency",
        description="Send frames one way through a simulated link (testbed.channel) and report "
        "what the receiver's frame decoder got: counts, PER, goodput and latency.",
    )
    link.add_argument("--preset", default="s100", help="link preset (default: s100)")
    _add_set_option(link, "override a link parameter, e.g. --set ber=1e-4 (repeatable)")
    link.add_argument("--frames", type=int, default=1000, help="frames to send (default: 1000)")
    link.add_argument(
        "--size", type=int, default=60, help="frame size in bytes, all included (default: 60)"
    )
    link.add_argument(
        "--interval", type=float, default=1.0, help="seconds between frames (default: 1)"
    )
    link.add_argument(
        "--distance", type=float, default=0.0, help="sender-receiver distance in m (default: 0)"
    )
    link.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    link.add_argument("--json", action="store_true", help="print one JSON object")
    link.set_defaults(handler=_run_link)


def _run_link(args: argparse.Namespace) -> int:
    """Handler of ``testbed link``: check the arguments, run the probe, print the result."""
    import json
    import math

    from testbed.channel.config import load_link_config
    from testbed.channel.probe import format_report, frame_size_limits, run_probe

    lo, hi = frame_size_limits()
    if args.frames < 1:
        raise ConfigError(f"--frames: must be ≥ 1, got {args.frames}")
    if not lo <= args.size <= hi:
        raise ConfigError(f"--size: a probe frame must be {lo}..{hi} bytes, got {args.size}")
    if not (args.interval > 0.0 and math.isfinite(args.interval)):
        raise ConfigError(f"--interval: must be > 0 s, got {args.interval}")
    if not (args.distance >= 0.0 and math.isfinite(args.distance)):
        raise ConfigError(f"--distance: must be ≥ 0 m, got {args.distance}")
    if args.seed < 0:
        raise ConfigError(f"--seed: must be ≥ 0, got {args.seed}")
    config = load_link_config(args.preset, args.overrides)
    result = run_probe(
        config,
        frames=args.frames,
        frame_bytes=args.size,
        interval_s=args.interval,
        seed=args.seed,
        distance_m=args.distance,
    )
    if args.json:
        print(json.dumps(result.to_json_dict()))
    else:
        print(format_report(result))
    return EXIT_OK


def _add_sweep_parser(sub: argparse._SubParsersAction[_Parser]) -> None:
    """``testbed sweep``: a grid of runs on local processes or a Dask cluster (testbed.sweep)."""
    sweep = sub.add_parser(
        "sweep",
        help="run a scenario sweep (grid × seeds) locally or on a Dask cluster, resumable",
        description="Run every (grid point, seed) of a sweep file as an independent run. Writes "
        "runs.jsonl, results.csv (one row per run) and aggregate.csv (per point) to --out. "
        "Exit 0 when every run succeeded, 1 when some failed (listed), 2 on bad input.",
    )
    sweep.add_argument("sweep", help="packaged sweep id (e.g. ber-vs-lag-v1) or a sweep .toml path")
    _add_set_option(
        sweep, "override a scenario key in every run, e.g. --set duration_s=30 (repeatable)"
    )
    sweep.add_argument(
        "--workers", type=int, default=None, help="worker processes (default: one per core)"
    )
    sweep.add_argument(
        "--dask",
        default=None,
        metavar="ADDRESS|local",
        help="run on a dask.distributed scheduler (tcp://host:8786) or a LocalCluster ('local')",
    )
    sweep.add_argument(
        "--out", type=Path, default=None, help="results directory (default: sweeps/<id>/)"
    )
    sweep.add_argument(
        "--resume", action="store_true", help="continue the sweep in --out, skipping done runs"
    )
    sweep.set_defaults(handler=_run_sweep)


def _run_sweep(args: argparse.Namespace) -> int:
    """Handler of ``testbed sweep``: load and check the sweep, run it, summarise."""
    from testbed.sweep.core import format_summary, load_sweep, run_sweep

    if args.workers is not None and args.workers < 1:
        raise ConfigError(f"--workers: must be ≥ 1, got {args.workers}")
    if args.workers is not None and args.dask not in (None, "local"):
        raise ConfigError("--workers: a remote --dask cluster brings its own workers")
    sweep = load_sweep(args.sweep, args.overrides)
    out = args.out if args.out is not None else Path("sweeps") / sweep.id
    summary = run_sweep(sweep, out, workers=args.workers, dask=args.dask, resume=args.resume)
    print(format_summary(sweep, summary))
    if any(key.rsplit(".", 1)[-1] == "ber" for key, _ in sweep.axes):
        from testbed.report.sweep_plots import plot_ber_sweep

        paths = plot_ber_sweep(out / "results.csv", out)
        print(f"  plots: {', '.join(path.name for path in paths)}")
    return EXIT_OK if not summary.failed else 1


def _add_plot_parser(sub: argparse._SubParsersAction[_Parser]) -> None:
    """``testbed plot``: any results.csv column against another (testbed.report.sweep_plots)."""
    plot = sub.add_parser(
        "plot",
        help="plot one column of a sweep's results.csv against another",
        description="Scatter a metric of every successful run against a grid key or another "
        "metric, with the median per x and 95 %% t-intervals of the mean; one colour per --hue "
        "value. Writes a PNG (default: RESULTS' folder, <y>_vs_<x>.png).",
    )
    plot.add_argument("results", type=Path, help="a results.csv written by testbed sweep")
    plot.add_argument("--x", required=True, metavar="KEY", help="x column, e.g. link.ber")
    plot.add_argument(
        "--y", required=True, metavar="METRIC", help="y column, e.g. command_age_s.mean"
    )
    plot.add_argument("--hue", default=None, metavar="KEY", help="colour by this column")
    plot.add_argument("--out", type=Path, default=None, help="PNG path")
    plot.set_defaults(handler=_run_plot)


def _run_plot(args: argparse.Namespace) -> int:
    """Handler of ``testbed plot``: check the columns, draw, print the path."""
    from testbed.report.sweep_plots import default_plot_name, plot_pair

    out = args.out
    if out is None:
        out = args.results.parent / default_plot_name(args.x, args.y)
    print(plot_pair(args.results, args.x, args.y, args.hue, out))
    return EXIT_OK


def _add_modem_emulator_parser(sub: argparse._SubParsersAction[_Parser]) -> None:
    """``testbed modem-emulator``: two PTYs joined by the simulated link (testbed.emulator.ptys)."""
    emu = sub.add_parser(
        "modem-emulator",
        help="open two pseudo-terminals joined in real time by a simulated link",
        description="Open two pseudo-terminals, A and B, joined in real time by the channel "
        "model (bitrate, delay, bit errors, buffer), print their paths and run until Ctrl-C. "
        "Bytes written on one port with no idle gap longer than 3 ms are one transmission "
        "(--modem transparent); with --modem evologics or m64 each port speaks that modem's "
        "serial protocol instead (AT*SENDIM/RECVIM, wcq/wrp).",
    )
    emu.add_argument("--preset", default="s100", help="link preset (default: s100)")
    emu.add_argument(
        "--modem",
        choices=("transparent", "evologics", "m64"),
        default="transparent",
        help="the modems' serial interface: transparent (S100 style, default), evologics "
        "(S2C data mode; port A address 1, B address 2) or m64 (Water Linked; A role a, "
        "B role b, channel 4)",
    )
    _add_set_option(emu, "override a link parameter, e.g. --set ber=0 (repeatable)")
    emu.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    emu.add_argument(
        "--time-factor",
        type=float,
        default=1.0,
        help="wall seconds per simulated second (default: 1, real time)",
    )
    emu.add_argument(
        "--distance", type=float, default=0.0, help="distance between the modems in m (default: 0)"
    )
    emu.add_argument(
        "--duration",
        type=float,
        default=None,
        help="stop after this many seconds (default: run until Ctrl-C)",
    )
    emu.set_defaults(handler=_run_modem_emulator)


def _run_modem_emulator(args: argparse.Namespace) -> int:
    """Handler of ``testbed modem-emulator``: print the two paths, run, report counters."""
    import contextlib
    import math
    import threading

    from testbed.channel.config import load_link_config
    from testbed.emulator.ptys import ModemEmulator

    if not (args.time_factor > 0.0 and math.isfinite(args.time_factor)):
        raise ConfigError(f"--time-factor: must be > 0, got {args.time_factor}")
    if not (args.distance >= 0.0 and math.isfinite(args.distance)):
        raise ConfigError(f"--distance: must be ≥ 0 m, got {args.distance}")
    if args.duration is not None and not args.duration >= 0.0:
        raise ConfigError(f"--duration: must be ≥ 0 s, got {args.duration}")
    if args.seed < 0:
        raise ConfigError(f"--seed: must be ≥ 0, got {args.seed}")
    config = load_link_config(args.preset, args.overrides)
    with ModemEmulator(
        config,
        seed=args.seed,
        time_factor=args.time_factor,
        distance_m=args.distance,
        modem=args.modem,
    ) as emulator:
        path_a, path_b = emulator.paths
        print(f"A {path_a}\nB {path_b}", flush=True)
        print(
            f"testbed: {config.name} link, {config.bitrate_bps:g} bit/s, intrinsic delay "
            f"{1000 * config.intrinsic_delay_s:.1f} ms, BER {config.ber:g}, "
            f"{args.modem} modems; Ctrl-C stops",
            file=sys.stderr,
        )
        with contextlib.suppress(KeyboardInterrupt):
            threading.Event().wait(args.duration)
        for name, counters in zip("AB", emulator.counters, strict=True):
            print(f"testbed: port {name}: {counters}", file=sys.stderr)
        modem_counters = emulator.personality_counters
        if modem_counters is not None:
            for name, counts in zip("AB", modem_counters, strict=True):
                print(f"testbed: {args.modem} modem {name}: {counts}", file=sys.stderr)
    return EXIT_OK


def _add_hil_parser(sub: argparse._SubParsersAction[_Parser]) -> None:
    """``testbed hil``: the nodes in real time over serial modems (testbed.cli.hil)."""
    from testbed.cli.hil import add_hil_arguments

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


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI. Returns the process exit code (0 ok, 2 bad input)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        code: int = args.handler(args)
    except ConfigError as err:
        print(f"testbed: error: {err}", file=sys.stderr)
        return EXIT_USAGE
    except BrokenPipeError:  # e.g. `testbed run | head`: the reader left, nothing to report
        sys.stderr.close()
        return EXIT_OK
    return code
