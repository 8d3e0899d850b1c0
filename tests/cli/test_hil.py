"""``testbed hil`` on bad input: one line on stderr naming the option, exit code 2.

(The successful one- and two-computer runs are exercised in tests/test_hil_run.py.)
"""

from __future__ import annotations

import threading
from pathlib import Path

import pytest

from testbed.cli.hil import format_hil_summary
from testbed.cli.main import main

MISSING = "/dev/does-not-exist-testbed"


def exit_code(argv: list[str]) -> int:
    """``main``'s return code, or the code argparse exits with on a parse error."""
    try:
        return main(argv)
    except SystemExit as stop:
        return int(stop.code or 0)


@pytest.mark.parametrize(
    ("argv", "option"),
    [
        (["hil"], "--operator-port"),
        (["hil", "--operator-port", "loop://"], "--vehicle-port"),
        (["hil", "--operator-port", "loop://", "--vehicle-port", "loop://"], "--vehicle-port"),
        (["hil", "--port", "loop://"], "--port"),
        (["hil", "vehicle"], "--port"),
        (["hil", "operator", "--port", "loop://", "--operator-port", "x"], "--operator-port"),
        (["hil", "vehicle", "--port", "loop://", "--baud", "0"], "--baud"),
        (["hil", "vehicle", "--port", "loop://", "--m64-channel", "9"], "--m64-channel"),
        (["hil", "vehicle", "--port", "loop://", "--modem", "s300"], "--modem"),
        (["hil", "vehicle", "--port", "loop://", "--duration", "5"], "--duration"),
        (["hil", "vehicle", "--port", "loop://", "--seed", "-1"], "--seed"),
        (["hil", "vehicle", "--port", "loop://", "--set", "link.bogus=1"], "--set"),
        (["hil", "vehicle", "s100-teleop-v1", "m64-teleop-v1", "--port", "x"], "m64-teleop-v1"),
        (["hil", "vehicle", "--port", MISSING], "--port"),
    ],
)
def test_bad_input_is_one_line_naming_the_option(
    argv: list[str], option: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert exit_code(argv) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert err.count("\n") == 1 and option in err
    assert "Traceback" not in err


def test_a_port_that_fails_to_open_closes_the_one_already_open(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "runs" / "hil"
    argv = ["hil", "--operator-port", "loop://", "--vehicle-port", MISSING, "--out", str(out)]
    assert main(argv) == 2
    _, err = capsys.readouterr()
    assert err.startswith("testbed: error: --vehicle-port: cannot open")
    assert not (tmp_path / "runs").exists()  # the --out it made is removed again
    alive = [t.name for t in threading.enumerate() if t.name.startswith("serial:loop://")]
    assert alive == []  # the operator's reader and writer were stopped and joined


def test_summary_shows_what_is_unknown_as_n_a() -> None:
    nan = float("nan")
    side = {"frames_sent": 20, "frames_delivered": nan, "per": nan}
    metrics = {
        "scenario": "s100-teleop-v1",
        "sim_s": 12.0,
        "link": {"uplink": side, "downlink": {**side, "frames_delivered": 19}},
        "command_lag_s": {"mean": nan, "p95": nan},
        "hil": {
            "mode": "operator",
            "modem": "s100",
            "added_latency_ms": {"p50": 0.5, "p95": 0.9, "max": 2.0},
            "round_trip_s": {"mean": 0.3364},
            "reopens": 1,
            "garbage_bytes": 7,
        },
    }
    text = format_hil_summary(metrics, Path("out"))
    assert "(operator, s100)" in text
    assert "sent 20, delivered n/a, PER n/a" in text
    assert "delivered 19" in text
    assert "command lag mean n/a" in text and "round trip mean 336 ms" in text
    assert "p50 0.50 ms p95 0.90 ms max 2.00 ms; reopens 1; garbage 7 B" in text
