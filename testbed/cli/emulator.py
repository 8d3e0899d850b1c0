"""``testbed modem-emulator``: two pseudo-terminals joined in real time by a simulated link."""

from __future__ import annotations

import argparse
import dataclasses
import sys

from testbed.cli.options import (
    EXIT_OK,
    Subparsers,
    add_set_option,
    check_distance,
    check_duration,
    check_seed,
    exit_code_of,
    link_config_option,
)
from testbed.config import ConfigError

__all__ = ["add_modem_emulator_parser"]


def add_modem_emulator_parser(sub: Subparsers) -> None:
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
    add_set_option(emu, "override a link parameter, e.g. --set ber=0 (repeatable)")
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
        help="stop after this many seconds, at most 86400 (default: run until Ctrl-C)",
    )
    emu.set_defaults(handler=_run_modem_emulator)


def _run_modem_emulator(args: argparse.Namespace) -> int:
    """Handler of ``testbed modem-emulator``: print the two paths, run, report counters."""
    import math
    import threading

    from testbed.emulator.ptys import ModemEmulator

    if not (args.time_factor > 0.0 and math.isfinite(args.time_factor)):
        raise ConfigError(f"--time-factor: must be > 0, got {args.time_factor}")
    check_distance(args.distance)
    if args.duration is not None:
        check_duration(args.duration, low_open=False, note=" (omit it to run until Ctrl-C)")
    check_seed(args.seed)
    config = link_config_option(args.preset, args.overrides)
    with ModemEmulator(
        config,
        seed=args.seed,
        time_factor=args.time_factor,
        distance_m=args.distance,
        modem=args.modem,
    ) as emulator:
        stopped: KeyboardInterrupt | None = None
        try:  # Ctrl-C (or SIGTERM) is how it usually ends, at any moment from here on
            path_a, path_b = emulator.paths
            print(f"A {path_a}\nB {path_b}", flush=True)
            print(
                f"testbed: {config.name} link, {config.bitrate_bps:g} bit/s, intrinsic delay "
                f"{1000 * config.intrinsic_delay_s:.1f} ms, BER {config.ber:g}, "
                f"{args.modem} modems; Ctrl-C stops",
                file=sys.stderr,
            )
            threading.Event().wait(args.duration)
        except KeyboardInterrupt as interrupt:
            stopped = interrupt
        for name, counters in zip("AB", emulator.counters, strict=True):
            print(f"testbed: port {name}: {_counts(dataclasses.asdict(counters))}", file=sys.stderr)
        modem_counters = emulator.personality_counters
        if modem_counters is not None:
            for name, counts in zip("AB", modem_counters, strict=True):
                print(f"testbed: {args.modem} modem {name}: {_counts(counts)}", file=sys.stderr)
    if stopped is not None:
        print("testbed: interrupted; the emulator closed its ports", file=sys.stderr)
        return exit_code_of(stopped)
    return EXIT_OK


def _counts(counts: dict[str, int]) -> str:
    """``key value, …`` of a counter set, as a person reads it."""
    text = ", ".join(f"{key.replace('_', ' ')} {value}" for key, value in counts.items())
    return text or "nothing counted"
