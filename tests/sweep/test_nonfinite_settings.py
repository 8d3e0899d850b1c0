"""A sweep setting that is not a finite number (``link.max_range_m = inf``: unlimited, the one
kind a scenario key accepts) in ``--set`` or the grid: ``sweep.json`` and ``runs.jsonl`` stay
strict JSON (read here by a parser that refuses ``Infinity`` and ``NaN``), record the value as
its TOML spelling ``"inf"``, and ``--resume`` recognises it; a sweep started before, whose
``sweep.json`` has a bare ``Infinity``, resumes too.

Truths: a strict JSON parser, and the run of the grid's ``inf`` point made directly (a second
method). Sweeps here are 1–3 points × 1 seed of ``s100-teleop-v1`` for 8 simulated seconds, run
in this process as test_resume.py runs them.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from testbed.cli.main import main
from testbed.run.runner import run_scenario
from testbed.run.scenario import load_scenario
from testbed.sweep import execute_run

pytestmark = pytest.mark.usefixtures("no_sweep_plots")  # conftest.py: not their subject

SHORT = ["--set", "duration_s=8", "--set", "metrics.settle_s=1", "--workers", "1"]


@pytest.fixture(scope="module", autouse=True)
def _runs_in_this_process() -> Iterator[None]:
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(
            "testbed.sweep.runner.outcomes", lambda specs, *_: (execute_run(s) for s in specs)
        )
        yield


def _refuse(constant: str) -> Any:
    raise ValueError(f"not strict JSON: {constant}")


def strict(text: str) -> Any:
    """``text`` parsed as strict JSON: ``Infinity``, ``-Infinity`` and ``NaN`` refused."""
    return json.loads(text, parse_constant=_refuse)


def _sweep(folder: Path, grid: str) -> Path:
    path = folder / "s.toml"
    path.write_text(
        'schema = 1\nid = "range-v1"\ndescription = "d"\nscenario = "s100-teleop-v1"\n'
        f'metrics = ["link.uplink.per"]\nseeds = 1\n[grid]\n{grid}\n',
        encoding="utf-8",
    )
    return path


def test_strict_parser_refuses_what_json_dumps_writes_for_inf() -> None:
    with pytest.raises(ValueError, match="Infinity"):
        strict(json.dumps({"max_range_m": float("inf")}))


def test_an_inf_set_value_is_strict_json_and_resumes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path, out = _sweep(tmp_path, '"link.ber" = [0.0]'), tmp_path / "out"
    unlimited = [*SHORT, "--set", "link.max_range_m=inf", "--out", str(out)]
    assert main(["sweep", str(path), *unlimited]) == 0
    held = strict((out / "sweep.json").read_text())
    assert held["set"]["link"]["max_range_m"] == "inf"
    assert "link.max_range_m=inf" in held["overrides"]
    for line in (out / "runs.jsonl").read_text().splitlines():
        strict(line)
    capsys.readouterr()
    assert main(["sweep", str(path), *unlimited, "--resume"]) == 0
    assert "0 ran now" in capsys.readouterr().out
    finite = [*SHORT, "--set", "link.max_range_m=500", "--out", str(out), "--resume"]
    assert main(["sweep", str(path), *finite]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert "[set]/--set link.max_range_m: inf → 500.0" in err, err


def test_a_sweep_json_with_a_bare_infinity_from_before_resumes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """What the testbed wrote before (``json.dumps``' ``Infinity``) is the same sweep; the
    resume rewrites it strict."""
    path, out = _sweep(tmp_path, '"link.ber" = [0.0]'), tmp_path / "out"
    unlimited = [*SHORT, "--set", "link.max_range_m=inf", "--out", str(out)]
    assert main(["sweep", str(path), *unlimited]) == 0
    manifest = out / "sweep.json"
    text = manifest.read_text()
    manifest.write_text(text.replace('"max_range_m": "inf"', '"max_range_m": Infinity'))
    capsys.readouterr()
    assert main(["sweep", str(path), *unlimited, "--resume"]) == 0
    assert "0 ran now" in capsys.readouterr().out
    assert strict(manifest.read_text()) == strict(text)


def test_a_grid_over_inf_runs_records_strict_json_and_grows(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A grid ``link.max_range_m = [500.0, inf]`` (before: every run ran, then the journal's
    write raised ValueError and the sweep ended in a traceback): the journal and sweep.json
    are strict JSON, results.csv writes ``inf``, the ``inf`` row's metrics are those of the
    direct run; adding a grid value runs only it."""
    path = _sweep(tmp_path, '"link.max_range_m" = [500.0, inf]')
    out = tmp_path / "out"
    assert main(["sweep", str(path), *SHORT, "--out", str(out)]) == 0
    held = strict((out / "sweep.json").read_text())
    assert held["axes"] == [["link.max_range_m", [500.0, "inf"]]]
    rows = [strict(line) for line in (out / "runs.jsonl").read_text().splitlines()]
    assert [row["link.max_range_m"] for row in rows] == [500.0, "inf"]
    table = (out / "results.csv").read_text().splitlines()
    assert [line.split(",")[2] for line in table] == ["link.max_range_m", "500.0", "inf"]
    overrides = ["duration_s=8", "metrics.settle_s=1", "link.max_range_m=inf"]
    direct = run_scenario(load_scenario("s100-teleop-v1", overrides), seed=0).metrics
    assert rows[1]["status"] == "ok"
    assert rows[1]["link.uplink.frames_sent"] == direct["link"]["uplink"]["frames_sent"]
    assert rows[1]["command_lag_s.mean"] == direct["command_lag_s"]["mean"]

    path.write_text(path.read_text().replace("[500.0, inf]", "[500.0, 1000.0, inf]"))
    capsys.readouterr()
    assert main(["sweep", str(path), *SHORT, "--out", str(out), "--resume"]) == 0
    assert "1 ran now" in capsys.readouterr().out
    rows = [strict(line) for line in (out / "runs.jsonl").read_text().splitlines()]
    assert sorted((row["point"], row["link.max_range_m"]) for row in rows) == [
        (0, 500.0),
        (1, 1000.0),
        (2, "inf"),
    ]
