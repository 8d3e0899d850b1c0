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


@pytest.mark.parametrize(
    ("law", "message"),
    [
        ("NoUpdate", "NoUpdate made a NoUpdate without update (expected a DepthLaw"),
        ("broken", "vehicle.control.depth: RuntimeError: bad gains"),
    ],
)
@pytest.mark.parametrize("ports", ["console", "modems"])
def test_a_control_law_that_does_not_build_is_one_line_before_any_port_is_opened(
    law: str,
    message: str,
    ports: str,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """``testbed run``'s line (exit 2), before the console's port is bound and before the
    modems' ports are opened: with the console's port taken, or modem ports that do not exist,
    the law is what is reported (it used to be the port, the law never read), and nothing is
    announced or left behind."""
    (tmp_path / "my_laws.py").write_text(
        "class NoUpdate:\n    def reset(self):\n        pass\n\n\n"
        "def broken():\n    raise RuntimeError('bad gains')\n"
    )
    law_key = f"vehicle.control.depth={tmp_path / 'my_laws.py'}:{law}"
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        opened = (
            ["--port", str(port)]
            if ports == "console"
            else ["--port", "0", "--operator-port", "/dev/no-a", "--vehicle-port", "/dev/no-b"]
        )
        argv = ["live", *opened, "--set", law_key, "--duration", "2", "--no-plots"]
        code = main([*argv, "--out", str(tmp_path / "out")])
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and err[0].startswith("testbed: error: ") and message in err[0], err
    assert captured.out == ""  # no "console on" line
    assert not (tmp_path / "out").exists()
    scenario = "s100-video-v1"  # testbed live's default
    run = ["run", scenario, "--set", law_key, "--out", str(tmp_path / "run"), "--no-plots"]
    assert main(run) == 2 and capsys.readouterr().err.strip() == err[0]  # `testbed run`'s line
