"""``testbed hil`` on bad input: one line on stderr naming the option, exit code 2.

(The successful one- and two-computer runs are exercised in tests/test_hil_run.py.)
"""

from __future__ import annotations

import os
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from testbed.cli.hil import format_hil_summary
from testbed.cli.main import main
from testbed.cli.options import open_modem_ports
from testbed.config import ConfigError

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
        (["hil", "vehicle", "--port", "loop://", "--modem", "m64", "--m64-channel", "9"], "--m64"),
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


@pytest.mark.parametrize(
    ("options", "message"),
    [  # checked before any port is opened (MISSING would fail there, naming --port)
        (["--duration", "1e300"], "--duration: must be in (10, 86400] s, got 1e+300"),
        (["--duration", "86401"], "--duration: must be in (10, 86400] s, got 86401"),
        (["--baud", "1000000000000"], "--baud: must be in [50, 12000000] bit/s, got 1000000000000"),
        (["--baud", "49"], "--baud: must be in [50, 12000000] bit/s, got 49"),
        (["--m64-channel", "3"], "--m64-channel: only used with --modem m64"),
        (
            ["--modem", "evologics", "--m64-channel", "4"],
            "--m64-channel: only used with --modem m64",
        ),
    ],
)
def test_out_of_range_or_unused_options_are_refused_before_the_ports(
    options: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["hil", "vehicle", "--port", MISSING, *options]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"testbed: error: {message}") and err.count("\n") == 1


@pytest.fixture
def pty_pair() -> Iterator[tuple[str, str]]:
    """Two real serial devices (the slave ends of two pseudo-terminals)."""
    fds = [os.openpty() for _ in range(2)]
    try:
        yield os.ttyname(fds[0][1]), os.ttyname(fds[1][1])
    finally:
        for pair in fds:
            for fd in pair:
                os.close(fd)


def test_a_baud_rate_pyserial_cannot_hold_is_one_line_not_an_overflow(
    pty_pair: tuple[str, str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    operator, vehicle = pty_pair
    argv = ["hil", "--operator-port", operator, "--vehicle-port", vehicle, "--out", str(tmp_path)]
    assert main([*argv, "--baud", "1000000000000"]) == 2  # pyserial: OverflowError at 2^31
    err = capsys.readouterr().err
    assert err == "testbed: error: --baud: must be in [50, 12000000] bit/s, got 1000000000000\n"


def test_an_overflow_or_value_error_from_pyserial_names_the_port_option(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from testbed import hil
    from testbed.hil import PortSettings

    def refuse(settings: PortSettings, **options: object) -> None:
        raise OverflowError("signed integer is greater than maximum")

    monkeypatch.setattr(hil, "open_endpoint", refuse)
    with pytest.raises(ConfigError, match=r"^--port: cannot open x: signed integer is greater"):
        open_modem_ports({"vehicle": ("--port", PortSettings("x", "s100", "vehicle"))})


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


def _summary_metrics(**link: float) -> dict[str, Any]:
    """A HIL run's metrics as the summary reads them (one endpoint per node)."""
    nan = float("nan")
    side = {"frames_sent": 20, "frames_delivered": nan, "per": nan, "frames_dropped": nan}
    endpoint = {"port_errors": 0, "reopen_failures": 0, "last_error": ""}
    return {
        "scenario": "s100-teleop-v1",
        "sim_s": 12.0,
        "link": {"uplink": {**side, **link}, "downlink": {**side, "frames_delivered": 19}},
        "command_lag_s": {"mean": nan, "p95": nan},
        "events": {"failsafe": nan},
        "hil": {
            "mode": "operator",
            "modem": "s100",
            "added_latency_ms": {"p50": 0.5, "p95": 0.9, "max": 2.0},
            "round_trip_s": {"mean": 0.3364},
            "reopens": 1,
            "garbage_bytes": 7,
            "endpoints": {"operator": endpoint},
        },
    }


def test_summary_shows_what_is_unknown_as_n_a() -> None:
    text = format_hil_summary(_summary_metrics(), Path("out"))
    assert "(operator, s100)" in text
    assert "sent 20, delivered n/a, PER n/a\n" in text
    assert "delivered 19" in text
    assert "command lag mean n/a" in text and "round trip mean 336 ms" in text
    assert "p50 0.50 ms p95 0.90 ms max 2.00 ms; port errors 0, reopens 1, failed reopens 0" in text
    assert "garbage 7 B" in text and "warning" not in text and "failsafe" not in text


def test_summary_says_when_a_port_died_frames_were_dropped_or_none_arrived() -> None:
    """A review killed the emulator mid-run: 26 of 43 orders dropped at the dead port, the
    vehicle surfaced, and the summary said 'PER 0.00 %', 'reopens 0' and nothing more."""
    metrics = _summary_metrics(
        frames_sent=43, frames_delivered=17, per=0.0, frames_dropped=26, drop_rate=26 / 43
    )
    metrics["link"]["downlink"].update(frames_sent=17, frames_delivered=0)
    metrics["events"]["failsafe"] = 1
    metrics["hil"]["endpoints"]["operator"].update(
        port_errors=1, reopen_failures=12, last_error="SerialException: could not open port"
    )
    text = format_hil_summary(metrics, Path("out"))
    assert "sent 43, delivered 17, PER 0.00 %, dropped 26 (60.5 %) at the sender" in text
    assert "port errors 1, reopens 1, failed reopens 12" in text
    assert "failsafe engaged 1 time(s)" in text
    assert "warning: no downlink frame arrived" in text
    assert "warning: a port failed 1 time(s): SerialException: could not open port" in text


def test_one_device_under_two_names_is_refused(tmp_path: Path) -> None:
    """A /dev/serial/by-id/... link beside the device it names: one modem, not two."""
    leader, follower = os.openpty()
    try:
        device = os.ttyname(follower)
        alias = tmp_path / "by-id-modem"
        alias.symlink_to(device)
        argv = ["hil", "--operator-port", device, "--vehicle-port", str(alias)]
        assert exit_code(argv) == 2
    finally:
        os.close(leader)
        os.close(follower)


def test_the_emulator_reports_its_counters_as_words(capsys: pytest.CaptureFixture[str]) -> None:
    """Its closing lines were Python reprs (``PortCounters(bytes_in=2685, …)``)."""
    assert main(["modem-emulator", "--duration", "0.2", "--preset", "m64", "--modem", "m64"]) == 0
    lines = capsys.readouterr().err.splitlines()
    assert "testbed: port A: bytes in 0, bursts 0, bursts dropped 0, deliveries 0, " in lines[-4]
    assert lines[-2:] == [
        "testbed: m64 modem A: nothing counted",
        "testbed: m64 modem B: nothing counted",
    ]


@pytest.mark.parametrize(
    ("url", "says"),
    [
        ("socket://host", "a socket:// URL needs a host and a port (host:port)"),
        ("socket://127.0.0.1:x", "a socket:// URL needs a host and a port (host:port)"),
        ("socket://127.0.0.1:99999", "a socket:// URL needs a host and a port (host:port)"),
        ("socket://[::1", "not a socket:// URL (Invalid IPv6 URL)"),  # raised a traceback
        ("socket://127.0.0.1:1?badopt=1", "unknown URL option 'badopt' (socket:// takes: logging)"),
    ],
)
def test_a_socket_url_without_its_port_or_with_an_unknown_option_is_named(
    url: str, says: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """pyserial's own words for these were "'<=' not supported between instances of 'int' and
    'NoneType'" and "'debug|info|warning|error'" (a HIL review)."""
    assert exit_code(["hil", "--operator-port", url, "--vehicle-port", "loop://"]) == 2
    assert capsys.readouterr().err == f"testbed: error: --operator-port: {url}: {says}\n"


LAW = """
class Hold:
    def reset(self):
        pass

    def update(self, target, depth, imu, dt_s):
        return (0.0, 0.0, 0.0)
"""


@pytest.mark.parametrize("mode", ["operator", "vehicle"])
def test_a_law_of_ones_own_that_only_operator_does_not_fly_is_one_warning_line(
    mode: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`hil operator` builds no vehicle, so a law the scenario names is not flown here: one
    warning line says so (it was silently unused). `hil vehicle` flies it: no warning."""
    (tmp_path / "my_laws.py").write_text(LAW)
    law = f"vehicle.control.depth={tmp_path / 'my_laws.py'}:Hold"
    argv = ["hil", mode, "--port", "loop://", "--set", law, "--set", "metrics.settle_s=0.1"]
    argv += ["--duration", "0.3", "--no-plots", "--out", str(tmp_path / "out")]
    assert main(argv) == 0
    warnings = [line for line in capsys.readouterr().err.splitlines() if "warning" in line]
    if mode == "operator":
        assert warnings == [
            "testbed: warning: vehicle.control.depth: not flown by `hil operator` (the vehicle "
            "node flies the laws of its own scenario, on its computer)"
        ]
    else:
        assert not [line for line in warnings if "vehicle.control" in line]
