"""``testbed live``'s bad input: one line on stderr and exit code 2, before any session."""

from __future__ import annotations

import socket
from pathlib import Path

import pytest

from testbed.cli.main import main

BOGUS = ["--set", "link.bogus=1"]


@pytest.mark.parametrize(
    ("args", "names"),
    [
        (["--port", "70000"], "--port"),
        (["--duration", "0"], "--duration"),
        (["--seed", "-1"], "--seed"),
        (["no-such-scenario"], "unknown scenario"),
        (["--set", "link.bogus=1"], "bogus"),
        (["--duration", "1e300"], "--duration: must be in (0, 86400] s, got 1e+300"),
        # checked before the scenario is loaded (link.bogus would fail there, naming bogus)
        (["--modem", "m64", *BOGUS], "--modem: only used with --operator-port and --vehicle-port"),
        (["--operator-port", "/dev/no-a", *BOGUS], "--vehicle-port: required"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(
    args: list[str], names: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["live", "--out", str(tmp_path / "out"), *args]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and names in err


def test_a_port_in_use_is_one_line_and_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        assert main(["live", "--port", str(port), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--port" in err
