"""A link model factory is called with the run's LinkConfig first: one written without that
parameter, whose first parameter its model_args also name, is told so in one line (it read
"multiple values for argument 'answer'", naming link.model_args, not the missing config)."""

from __future__ import annotations

from pathlib import Path

import pytest

from testbed.cli.main import main

FACTORY = """
class Says:
    def __init__(self, answer):
        self.answer = answer
"""


def test_a_link_model_factory_without_its_config_parameter_is_one_line_saying_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "nocfg.py").write_text(FACTORY)
    scenario = tmp_path / "nocfg.toml"
    scenario.write_text(
        'schema = 1\nid = "nocfg-v1"\ndescription = "x"\nduration_s = 30.0\n[link]\n'
        'preset = "s100"\nmodel = "nocfg.py:Says"\nmodel_args = { answer = "fine" }\n'
    )
    assert main(["run", str(scenario), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert f"{scenario}: link.model: {tmp_path / 'nocfg.py'}:Says cannot take (config, " in err
    assert "its parameter 'answer' is given the run's config first" in err
