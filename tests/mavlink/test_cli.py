"""``testbed mavlink``: user mistakes are one line and exit 2; a short session writes the run's
results with the ``mavlink`` section."""

from __future__ import annotations

import json
import socket
from pathlib import Path

import pytest

from testbed.cli.main import main

NO_GCS = ["--gcs", "serial:/dev/no-such-port"]
"""A ground-station link that cannot be opened."""


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--link", "nope"], "--link: unknown preset 'nope'"),
        (["--operator-port", "/dev/null"], "--vehicle-port: required"),
        (["--gcs", "udpin:127.0.0.1:99999"], "--gcs: 'udpin:127.0.0.1:99999': expected"),
        (["--gcs", "udpout:nowhere"], "--gcs: 'udpout:nowhere': expected"),
        (["--gcs", "serial:/dev/no-such-port"], "--gcs: cannot open serial:/dev/no-such-port"),
        (["--duration", "-1"], "--duration: must be in (0, 86400] s, got -1"),
        (["--set", "vehicle.supply_voltage_v=99"], "vehicle.supply_voltage_v"),
        # checked before any link is opened: NO_GCS would fail there (the run never starts)
        ([*NO_GCS, "--duration", "1e300"], "--duration: must be in (0, 86400] s, got 1e+300"),
        ([*NO_GCS, "--modem", "m64"], "--modem: only used with --operator-port and --vehicle-port"),
        ([*NO_GCS, "--baud", "9600"], "--baud: only used with --operator-port and --vehicle-port"),
        ([*NO_GCS, "--rtscts"], "--rtscts: only used with --operator-port and --vehicle-port"),
        (
            [
                *NO_GCS,
                "--link",
                "s100",
                "--operator-port",
                "/dev/no-a",
                "--vehicle-port",
                "/dev/no-b",
            ],
            "--link: not with --operator-port and --vehicle-port",
        ),
        (
            [*NO_GCS, "--operator-port", "/dev/no-a", "--vehicle-port", "/dev/no-b", "--baud", "0"],
            "--baud: must be in [50, 12000000] bit/s, got 0",
        ),
        (
            ["--gcs", "serial:/dev/no-such-port,1000000000000"],  # pyserial: OverflowError
            "baud must be an integer in [50, 12000000], got '1000000000000'",
        ),
        (["--gcs", "bogus://x"], "--gcs: cannot open bogus://x: invalid URL"),  # a ValueError
        (  # every packet was handled twice (a MAVLink user's review)
            ["--gcs", "udpin:127.0.0.1:14599", "--gcs", "udpin:127.0.0.1:14599"],
            "--gcs: udpin:127.0.0.1:14599 is given more than once",
        ),
        ([*NO_GCS, "--param", "NO_SUCH=1"], "--param 'NO_SUCH=1': unknown ArduSub parameter"),
        ([*NO_GCS, "--param", "SYSID_THISMAV=0"], "SYSID_THISMAV = 0.0 refused (range [1, 255])"),
        ([*NO_GCS, "--param", "JS_GAIN_DEFAULT=nan"], "JS_GAIN_DEFAULT = nan refused"),
        ([*NO_GCS, "--param", "SYSID_THISMAV"], "--param 'SYSID_THISMAV': expected NAME=VALUE"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(
    argv: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(["mavlink", *argv, "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and message in err[0], err
    assert not (tmp_path / "out").exists()  # also when the error came after --out was made


def test_a_short_session_writes_the_run_outputs_and_the_mavlink_section(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "session"
    url = f"udpout:127.0.0.1:{free_udp_port()}"  # nobody listens: the vehicle talks alone
    code = main(["mavlink", "--gcs", url, "--duration", "1.5", "--out", str(out), "--no-plots"])
    assert code == 0
    assert "mavlink s100-teleop-v1" in capsys.readouterr().out
    metrics = json.loads((out / "metrics.json").read_text())
    assert set(metrics["files"]) == {"events.csv", "series.csv"}
    section = metrics["mavlink"]
    assert section["sent"]["HEARTBEAT"] == 2  # at 0 s and 1 s
    assert section["links"][url]["packets_out"] >= 10
    assert section["gcs_to_thruster_ms"]["n"] == 0  # no pilot
    assert metrics["sim_s"] == pytest.approx(1.5)


def test_boot_parameters_set_what_ardusub_reads_only_at_boot(tmp_path: Path) -> None:
    """``--param SYSID_THISMAV=2 --param JS_GAIN_DEFAULT=0.8``: the vehicle is system 2 from its
    first heartbeat and flies at gain 0.8 (the PilotGain it reports), which a PARAM_SET during
    a session does not change (ArduSub reads both once, at boot)."""
    from pymavlink.dialects.v20 import ardupilotmega as mav

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as gcs:
        gcs.bind(("127.0.0.1", 0))
        url = f"udpout:127.0.0.1:{gcs.getsockname()[1]}"
        argv = ["mavlink", "--gcs", url, "--duration", "1.5", "--no-plots"]
        boot = ["--param", "SYSID_THISMAV=2", "--param", "js_gain_default=0.8"]
        assert main([*argv, *boot, "--out", str(tmp_path / "out")]) == 0
        gcs.setblocking(False)
        parser = mav.MAVLink(None)
        messages = []
        while True:
            try:
                datagram = gcs.recv(65535)
            except BlockingIOError:
                break
            messages += parser.parse_buffer(datagram) or []
    heartbeats = [m for m in messages if m.get_type() == "HEARTBEAT"]
    assert heartbeats and {m.get_srcSystem() for m in heartbeats} == {2}
    gains = [m.value for m in messages if m.get_type() == "NAMED_VALUE_FLOAT"]
    assert gains and all(gain == pytest.approx(0.8) for gain in gains)


@pytest.mark.parametrize(
    ("law", "message"),
    [
        ("NoUpdate", "NoUpdate made a NoUpdate without update (expected a DepthLaw"),
        ("broken", "vehicle.control.depth: RuntimeError: bad gains"),
    ],
)
@pytest.mark.parametrize("link", [[], ["--link", "s100"]], ids=["direct", "gateway"])
def test_a_control_law_that_does_not_build_is_one_line_before_anything_runs(
    law: str, message: str, link: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """As `testbed run` says it (one line, exit 2), before the "running" line and before any
    results folder is left: it used to come after the session was announced as running."""
    (tmp_path / "my_laws.py").write_text(
        "class NoUpdate:\n    def reset(self):\n        pass\n\n\n"
        "def broken():\n    raise RuntimeError('bad gains')\n"
    )
    url = f"udpout:127.0.0.1:{free_udp_port()}"
    law_key = f"vehicle.control.depth={tmp_path / 'my_laws.py'}:{law}"
    argv = ["mavlink", *link, "--gcs", url, "--set", law_key, "--duration", "2"]
    code = main([*argv, "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and err[0].startswith("testbed: error: ") and message in err[0], err
    assert not (tmp_path / "out").exists()
    expected = main(["run", "--set", law_key, "--out", str(tmp_path / "run"), "--no-plots"])
    assert expected == 2 and capsys.readouterr().err.strip() == err[0]  # `testbed run`'s line


def test_serial1_protocol_43_makes_the_second_link_a_high_latency_one(tmp_path: Path) -> None:
    """``--gcs A --gcs B --param SERIAL1_PROTOCOL=43``: B is SERIAL1, a MAVLink High Latency
    port (ArduPilot's ``GCS_MAVLINK::init``: ``is_high_latency_link`` for protocol 43, fixed at
    boot; AP_SerialManager's SerialProtocol_MAVLinkHL). pymavlink on both: A gets the 1-Hz
    heartbeat and never HIGH_LATENCY2; B is silent until MAV_CMD_CONTROL_HIGH_LATENCY 1 (sent on
    A) enables it, then gets "High Latency enabled" and HIGH_LATENCY2 at 5 s — no heartbeat,
    no stream."""
    import threading

    from pymavlink.dialects.v20 import ardupilotmega as mav

    received: dict[str, list[bytes]] = {"a": [], "b": []}
    with (
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as a,
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as b,
    ):
        for s in (a, b):
            s.bind(("127.0.0.1", 0))
        a.settimeout(5.0)
        sender = mav.MAVLink(None, srcSystem=255, srcComponent=190)
        enable = sender.command_long_encode(
            1, 1, mav.MAV_CMD_CONTROL_HIGH_LATENCY, 0, 1, 0, 0, 0, 0, 0, 0
        ).pack(sender)

        def ground_station() -> None:  # answers A's first datagram with the enable
            data, peer = a.recvfrom(65535)
            received["a"].append(data)
            a.sendto(enable, peer)

        thread = threading.Thread(target=ground_station, daemon=True)
        thread.start()
        urls = [f"udpout:127.0.0.1:{s.getsockname()[1]}" for s in (a, b)]
        argv = ["mavlink", "--gcs", urls[0], "--gcs", urls[1], "--param", "SERIAL1_PROTOCOL=43"]
        try:
            code = main([*argv, "--duration", "6", "--no-plots", "--out", str(tmp_path / "o")])
        finally:
            thread.join()
        for key, s in (("a", a), ("b", b)):  # the rest waited in the sockets' buffers
            s.setblocking(False)
            while True:
                try:
                    received[key].append(s.recv(65535))
                except BlockingIOError:
                    break
    assert code == 0

    def decoded(key: str) -> list[str]:
        parser = mav.MAVLink(None)
        messages = [m for d in received[key] for m in parser.parse_buffer(d) or []]
        return [m.get_type() for m in messages]

    on_a, on_b = decoded("a"), decoded("b")
    assert "COMMAND_ACK" in on_a and on_a.count("HEARTBEAT") >= 5
    assert "HIGH_LATENCY2" not in on_a
    assert on_b.count("HIGH_LATENCY2") == 1  # due 5 s after the link opened
    assert set(on_b) == {"STATUSTEXT", "HIGH_LATENCY2"}  # the enable's text, then HL2 alone
