"""A link model's own state beside the run (``link_state.csv``, testbed/run/link_log.py): a model
with ``state(t_s)`` has it sampled with the series rows; asking changes nothing the link does;
a state that breaks the contract is one line naming the model."""

from __future__ import annotations

import csv
import json
import textwrap
from pathlib import Path

import numpy as np
import pytest

from testbed.channel import StandardLink, load_link_config
from testbed.channel.model import LinkModelError
from testbed.cli.main import main
from testbed.run import load_scenario, run_scenario, write_run
from tests.run.test_plugins import _scenario_text

S100_BPS = load_link_config("s100").bitrate_bps
AT_S = 12.0


class SlowsDown:
    """The preset's link, its bit rate divided by ``factor`` from ``at_s`` on (no state)."""

    def __init__(self, factor: float) -> None:
        self.base = StandardLink(load_link_config("s100"))
        self.factor = factor

    def bitrate_bps(self, t_s: float) -> float:
        return S100_BPS / (self.factor if t_s >= AT_S else 1.0)

    def airtime_s(self, size_bytes: int, t_s: float) -> float:
        return size_bytes * 8.0 / self.bitrate_bps(t_s)

    def error_model(self, rng: np.random.Generator) -> object:
        return self.base.error_model(rng)


class SlowsDownAndSays(SlowsDown):
    """The same link, saying its bit rate and whether it is slowed."""

    def state(self, t_s: float) -> dict[str, object]:
        return {"bitrate_bps": self.bitrate_bps(t_s), "slowed": t_s >= AT_S}


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(encoding="utf-8") as handle:
        return list(csv.DictReader(handle))


def test_the_models_state_is_written_beside_the_series_and_asking_changes_nothing(
    tmp_path: Path,
) -> None:
    """The bit rate the model says at each series instant is the step it flies (S100's, then
    a third from 12 s), at exactly the series rows' times; the run with a model that has no
    ``state`` writes the same series.csv and events.csv byte for byte, and no link_state.csv."""
    scenario = load_scenario("s100-teleop-v1", ["duration_s=30"])
    said = tmp_path / "said"
    silent = tmp_path / "silent"
    write_run(run_scenario(scenario, link_model=SlowsDownAndSays(3.0)), said)
    write_run(run_scenario(scenario, link_model=SlowsDown(3.0)), silent)

    state, series = _rows(said / "link_state.csv"), _rows(said / "series.csv")
    assert list(state[0]) == ["t_s", "bitrate_bps", "slowed"]
    assert [row["t_s"] for row in state] == [row["t_s"] for row in series]
    assert len(state) >= 30 * 20  # metrics.sample_rate_hz 20 over 30 s
    for row in state:
        slowed = float(row["t_s"]) >= AT_S
        assert float(row["bitrate_bps"]) == pytest.approx(S100_BPS / (3.0 if slowed else 1.0))
        assert row["slowed"] == ("1" if slowed else "0")
    assert "link_state.csv" in json.loads((said / "metrics.json").read_text())["files"]

    assert not (silent / "link_state.csv").exists()
    for name in ("series.csv", "events.csv"):
        assert (said / name).read_bytes() == (silent / name).read_bytes(), name
    # nor the link's counters
    assert (
        json.loads((said / "metrics.json").read_text())["link"]
        == json.loads((silent / "metrics.json").read_text())["link"]
    )


LINKS = """
from testbed.channel import StandardLink


class Says:
    def __init__(self, config, answer):
        self.base, self.answer = StandardLink(config), answer

    def airtime_s(self, size_bytes, t_s):
        return self.base.airtime_s(size_bytes, t_s)

    def error_model(self, rng):
        return self.base.error_model(rng)

    def state(self, t_s):
        if self.answer == "fine":
            return {"bitrate_bps": self.base.config.bitrate_bps}
        if self.answer == "text":
            return {"bitrate_bps": "fast"}
        if self.answer == "list":
            return [1.0]
        if self.answer == "renamed":
            return {"rate" if t_s > 5.0 else "bitrate_bps": 1.0}
        if self.answer == "t_s":
            return {"t_s": t_s}
"""


def make_study(tmp_path: Path, links: str) -> Path:
    """A folder holding ``saying_links.py`` (the source ``links``: a class ``Says(config,
    answer)``), for :func:`link_scenario`."""
    folder = tmp_path / "study"
    folder.mkdir()
    (folder / "saying_links.py").write_text(textwrap.dedent(links))
    return folder


@pytest.fixture
def study(tmp_path: Path) -> Path:
    return make_study(tmp_path, LINKS)


def link_scenario(study: Path, answer: str) -> Path:
    """A scenario file in ``study`` flying ``Says`` with its ``answer``."""
    link = f'model = "saying_links.py:Says"\nmodel_args = {{ answer = "{answer}" }}'
    path = study / f"{answer}.toml"
    path.write_text(_scenario_text('kind = "scripted"', link))
    return path


def test_a_model_named_in_a_scenario_file_has_its_state_written(study: Path) -> None:
    out = study / "out"
    assert main(["run", str(link_scenario(study, "fine")), "--out", str(out), "--no-plots"]) == 0
    rows = _rows(out / "link_state.csv")
    assert rows and {float(row["bitrate_bps"]) for row in rows} == {S100_BPS}


@pytest.mark.parametrize(
    ("answer", "why"),
    [
        ("text", "'bitrate_bps' is not a number"),
        ("list", "expected a mapping of names to numbers"),
        ("renamed", "expected the names ['bitrate_bps'] of its first answer"),
        ("t_s", "names must be non-empty strings other than 't_s'"),
    ],
)
def test_a_state_that_breaks_the_contract_is_one_line_naming_the_model_and_keeps_what_ran(
    study: Path, answer: str, why: str, capsys: pytest.CaptureFixture[str]
) -> None:
    out = study / "out"
    assert main(["run", str(link_scenario(study, answer)), "--out", str(out), "--no-plots"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert f"link model Says ({study / 'saying_links.py'}): state(" in err
    assert why in err
    if answer == "renamed":  # broken at 5 s: what ran until then is kept, its state too
        assert json.loads((out / "metrics.json").read_text())["complete"] is False
        times = [float(row["t_s"]) for row in _rows(out / "link_state.csv")]
        assert times and max(times) <= 5.0 + 0.05
    else:  # broken at the first sample, t = 0: nothing ran to keep
        assert not (out / "metrics.json").exists()
    with pytest.raises(LinkModelError):
        run_scenario(load_scenario(str(link_scenario(study, answer))))
