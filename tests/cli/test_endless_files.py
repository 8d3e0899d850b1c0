"""A configuration path that never ends: ``testbed run /dev/zero``, ``testbed sweep /dev/zero``.

Every configuration file (scenario, sweep, preset, model, layout, mission…) is read by
``testbed.config.read_text``, which read the whole file: a device that never ends was read
until the kernel killed the process for its memory (exit 137, not a line). It now reads at
most ``MAX_CONFIG_CHARS`` and says so in one line, exit 2.

The child runs under a 4-GiB address-space limit, so the unbounded read ends in a
``MemoryError`` within seconds instead of exhausting the test machine's memory.
"""

from __future__ import annotations

import resource
import subprocess
import sys
from pathlib import Path

import pytest

ADDRESS_SPACE_B = 4 * 2**30  # numba's and LLVM's mappings need ≈ 1–2 GiB; the read needs less


def _limited() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE_B, ADDRESS_SPACE_B))


def _error_line(args: list[str], cwd: Path) -> str:
    """``python -m testbed ARGS`` in ``cwd`` under the address-space limit: its one stderr line,
    checked to be the only one and exit 2."""
    done = subprocess.run(
        [sys.executable, "-m", "testbed", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=300.0,
        preexec_fn=_limited,
    )
    assert done.returncode == 2, done.stderr[-2000:]
    lines = done.stderr.splitlines()
    assert len(lines) == 1, lines
    return lines[0]


@pytest.mark.parametrize("command", ["run", "sweep"])
def test_an_endless_configuration_file_is_one_line_exit_2(command: str, tmp_path: Path) -> None:
    line = _error_line([command, "/dev/zero", "--out", f"{tmp_path}/out"], tmp_path)
    assert line.startswith("testbed: error: /dev/zero: cannot read: ")
    assert line.endswith(" characters, not a configuration file")


SCENARIO = """\
schema = 1
id = "endless-v1"
description = "a scenario whose {key} is a link to a device that never ends"
duration_s = 10.0
[link]
preset = "s100"
{table}
"""


@pytest.mark.parametrize(
    ("key", "table", "link"),
    [
        ("vehicle.model", '[vehicle]\nmodel = "model.toml"', "model.toml"),
        ("link.preset", "", "preset.json"),
        ("recorded pilot's file", '[pilot]\nkind = "recorded"\nfile = "sticks.csv"', "sticks.csv"),
    ],
)
def test_a_scenarios_data_file_linked_to_an_endless_device_is_one_line_exit_2(
    key: str, table: str, link: str, tmp_path: Path
) -> None:
    """The scenario's own file is finite; a file it names beside it is a link to /dev/zero.
    Before, the scenario's check read that file whole (its text keys the parse cache, its
    digest is recorded) before the build could name it: a ``MemoryError`` traceback, exit 1."""
    (tmp_path / link).symlink_to("/dev/zero")
    text = SCENARIO.format(key=key, table=table)
    if link == "preset.json":
        text = text.replace('preset = "s100"', 'preset = "preset.json"')
    (tmp_path / "endless.toml").write_text(text)
    line = _error_line(["run", "endless.toml", "--out", "out", "--no-plots"], tmp_path)
    assert line.startswith("testbed: error: endless.toml: ") and link in line, line
