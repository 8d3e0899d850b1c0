"""``testbed link``: a one-way frame probe through the simulated channel."""

from __future__ import annotations

import argparse

from testbed.cli.options import (
    EXIT_OK,
    Subparsers,
    add_set_option,
    check_distance,
    check_seed,
    link_config_option,
)
from testbed.config import ConfigError, parse_override

__all__ = ["add_link_parser"]


def add_link_parser(sub: Subparsers) -> None:
    """``testbed link``: one-way frame probe through the simulated channel (see channel.probe)."""
    link = sub.add_parser(
        "link",
        help="send frames one way through a simulated link and report PER, goodput, latency",
        description="Send frames one way through a simulated link (testbed.channel) and report "
        "what the receiver's frame decoder got: counts, PER, goodput and latency.",
    )
    link.add_argument("--preset", default="s100", help="link preset (default: s100)")
    add_set_option(link, "override a link parameter, e.g. --set ber=1e-4 (repeatable)")
    link.add_argument(
        "--frames", type=int, default=1000, help="frames to send, 1..1000000 (default: 1000)"
    )
    link.add_argument(
        "--size", type=int, default=60, help="frame size in bytes, all included (default: 60)"
    )
    link.add_argument(
        "--interval", type=float, default=1.0, help="seconds between frames (default: 1)"
    )
    link.add_argument(
        "--distance", type=float, default=0.0, help="sender-receiver distance in m (default: 0)"
    )
    link.add_argument(
        "--model",
        metavar="FILE.py:NAME",
        help="a link model of your own (or MODULE:NAME), made as NAME(link config, **args) "
        "(docs/channel.md, 'A link model of your own')",
    )
    link.add_argument(
        "--model-args",
        metavar="TOML",
        default="{}",
        help="its keyword arguments as a TOML inline table, e.g. '{bitrate_bps = 1400.0}'",
    )
    link.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    link.add_argument("--json", action="store_true", help="print one JSON object")
    link.set_defaults(handler=_run_link)


def _run_link(args: argparse.Namespace) -> int:
    """Handler of ``testbed link``: check the arguments, run the probe, print the result."""
    import dataclasses
    import json
    import math

    from testbed.channel.probe import MAX_FRAMES, format_report, frame_size_limits, run_probe

    lo, hi = frame_size_limits()
    if not 1 <= args.frames <= MAX_FRAMES:
        raise ConfigError(f"--frames: must be 1..{MAX_FRAMES} (one probe), got {args.frames}")
    if not lo <= args.size <= hi:
        raise ConfigError(f"--size: a probe frame must be {lo}..{hi} bytes, got {args.size}")
    if not (args.interval > 0.0 and math.isfinite(args.interval)):
        raise ConfigError(f"--interval: must be > 0 s, got {args.interval}")
    check_distance(args.distance)
    check_seed(args.seed)
    config = link_config_option(args.preset, args.overrides)
    model = None
    if args.model is not None:
        from testbed.run.plugin_calls import make_link_model
        from testbed.run.plugins import check_finite

        _, model_args = parse_override(f"model_args={args.model_args}")
        if not isinstance(model_args, dict):
            raise ConfigError(
                f"--model-args: expected a TOML inline table {{...}}, got {args.model_args}"
            )
        for name, value in model_args.items():
            check_finite(value, "--model-args", name)
        keys = ("--model", "--model-args")
        model = make_link_model(
            args.model, model_args, config, "testbed link", keys, seed=args.seed
        )
    elif args.model_args != "{}":
        raise ConfigError("--model-args: only used with --model")
    result = run_probe(
        config,
        frames=args.frames,
        frame_bytes=args.size,
        interval_s=args.interval,
        seed=args.seed,
        distance_m=args.distance,
        link_model=model,
    )
    if args.model is not None:  # named as the user named it, not by its imported module
        result = dataclasses.replace(result, link_model=args.model)
    if args.json:
        print(json.dumps(result.to_json_dict()))
    else:
        print(format_report(result))
    return EXIT_OK
