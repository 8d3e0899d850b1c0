"""Every packaged scenario is deterministic: the same seed writes the same files, byte for byte.

Each scenario runs twice, shortened, in this process; ``write_run`` (no plots) writes
``metrics.json``, ``events.csv`` and ``series.csv`` for each run, and the two sets must be
identical but for the wall-clock lines of ``metrics.json`` (``wall_s``, ``rtf``). The test is
parametrized over :func:`~testbed.run.scenario_files.scenario_names`, so a new scenario is covered
as soon as it is packaged. A scenario is shortened by :data:`DEFAULT_SHORTENING`; one whose
events (faults, image changes) fall after that window gets its own entry in :data:`SHORTENING`
that moves them inside it (a ConfigError from the loader says which key is out of range).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from testbed.run.outputs import write_run
from testbed.run.runner import run_scenario
from testbed.run.scenario import load_scenario
from testbed.run.scenario_files import scenario_names

WALL_CLOCK_KEYS = ("wall_s", "rtf")
OUTPUTS = ("metrics.json", "events.csv", "series.csv")
# 20 s covers arming (≤ 1 s), the pilot's start (≤ 5 s) and a shortened settle time.
DEFAULT_SHORTENING = ["duration_s=20", "metrics.settle_s=5"]
SHORTENING: dict[str, list[str]] = {
    "s100-outage-v1": [*DEFAULT_SHORTENING, "faults.link_outages=[{start_s=12.0, end_s=14.0}]"],
    "s100-thruster-failure-v1": [
        *DEFAULT_SHORTENING,
        'faults.thrusters=[{t_s=12.0, thruster="LateralFrontLeft", mode="dead"}]',
    ],
    "s100-video-v1": [  # 40 s: 3 images captured, 2 completed; the ROI change moved to 25 s
        "duration_s=40",
        "metrics.settle_s=5",
        "images.changes=[{t_s=25.0, budget_bytes=600, roi=[40, 30, 119, 89], roi_shift=4}]",
    ],
}


def run_and_write(name: str, out: Path, seed: int | None = None) -> dict[str, bytes]:
    """Run the shortened scenario ``name`` and return its written outputs, wall clock removed."""
    scenario = load_scenario(name, SHORTENING.get(name, DEFAULT_SHORTENING))
    write_run(run_scenario(scenario, seed=seed), out)
    files = {file: (out / file).read_bytes() for file in OUTPUTS}
    lines = files["metrics.json"].splitlines(keepends=True)
    kept = [line for line in lines if not line.lstrip().startswith(_quoted(WALL_CLOCK_KEYS))]
    assert len(lines) - len(kept) == len(WALL_CLOCK_KEYS), "wall_s and rtf: one line each"
    files["metrics.json"] = b"".join(kept)
    return files


def _quoted(keys: tuple[str, ...]) -> tuple[bytes, ...]:
    return tuple(f'"{key}":'.encode() for key in keys)


@pytest.mark.parametrize("name", scenario_names())
def test_same_seed_writes_identical_outputs(name: str, tmp_path: Path) -> None:
    first = run_and_write(name, tmp_path / "first")
    second = run_and_write(name, tmp_path / "second")
    for file in OUTPUTS:
        assert first[file] == second[file], f"{name}: {file} differs between two same-seed runs"
    assert first["series.csv"].count(b"\n") > 10, "the shortened run recorded a series"


def test_shortening_names_packaged_scenarios() -> None:
    assert set(SHORTENING) <= set(scenario_names())


def test_another_seed_changes_the_run(tmp_path: Path) -> None:
    # s100-teleop-v1 draws link bit errors and sensor noise from the seed.
    seed0 = run_and_write("s100-teleop-v1", tmp_path / "seed0", seed=0)
    seed1 = run_and_write("s100-teleop-v1", tmp_path / "seed1", seed=1)
    assert seed0["series.csv"] != seed1["series.csv"]
    assert seed0["metrics.json"] != seed1["metrics.json"]
