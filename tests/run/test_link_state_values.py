"""What a link model's ``state`` may answer (``link_state.csv``, testbed/run/link_log.py): numpy's
numbers and bools as Python's (docs/channel.md: "a ``bool`` is written 0/1"), and what no float
holds as one line naming the model, exit 2, not a traceback.

Independent truth: the state below is a closed form of ``t_s`` (slowed from 12 s on), checked
against the ``t_s`` column the file itself carries; numpy's ``np.float64(t) >= 12.0`` is a
``numpy.bool`` (not a ``bool``), the type a model computing with numpy returns.
"""

from __future__ import annotations

import csv
import sys
import types
from pathlib import Path

import pytest

from testbed.channel.model import LinkModelError
from testbed.cli.main import main
from testbed.run.link_log import LinkStateLog
from tests.run.test_link_state_log import link_scenario, make_study

AT_S = 12.0
LINKS = """
import numpy as np

from testbed.channel import StandardLink


class Says:
    def __init__(self, config, answer):
        self.base, self.answer = StandardLink(config), answer

    def airtime_s(self, size_bytes, t_s):
        return self.base.airtime_s(size_bytes, t_s)

    def error_model(self, rng):
        return self.base.error_model(rng)

    def state(self, t_s):
        if self.answer == "numpy":
            t = np.float64(t_s)
            return {"slowed": t >= 12.0, "rate_bps": np.float32(1900.0), "frames": np.int64(3)}
        return {"rate_bps": 10**400}
"""


@pytest.fixture
def study(tmp_path: Path) -> Path:
    return make_study(tmp_path, LINKS)


def test_numpy_numbers_and_bools_are_written_as_numbers(study: Path) -> None:
    out = study / "out"
    code = main(["run", str(link_scenario(study, "numpy")), "--out", str(out), "--no-plots"])
    assert code == 0
    with (out / "link_state.csv").open(encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) > 100
    for row in rows:
        t_s = float(row["t_s"])
        assert float(row["slowed"]) == (1.0 if t_s >= AT_S else 0.0)
        assert (float(row["rate_bps"]), float(row["frames"])) == (1900.0, 3.0)


def test_a_number_no_float_holds_is_one_line_naming_the_model(
    study: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = study / "out"
    assert main(["run", str(link_scenario(study, "huge")), "--out", str(out), "--no-plots"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert f"link model Says ({study / 'saying_links.py'}): state(" in err
    assert "'rate_bps' is too large for a float" in err


def test_a_model_of_a_session_without_a_file_is_named_by_its_class(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A class defined in a REPL or ``python -c`` (its ``__main__`` has no ``__file__``, where
    ``inspect.getsourcefile`` raises OSError): the broken state's error names the class."""
    monkeypatch.setitem(sys.modules, "__main__", types.ModuleType("__main__"))
    fading = type("Fading", (), {"__module__": "__main__", "state": lambda self, t_s: [t_s]})
    log = LinkStateLog.of(fading())
    assert log is not None
    named = r"^link model Fading: state\(0\.5\) returned \[0\.5\]: expected a mapping"
    with pytest.raises(LinkModelError, match=named):
        log.record(0.5)
