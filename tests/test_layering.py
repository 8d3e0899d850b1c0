"""Imports flow one way: the layering table, enforced on every module of ``testbed/``.

The table below is the one source of the rules (the test parses it; the README copies it).
A row's layer is a subpackage (``testbed/<layer>/``) or a root module (``config``,
``__init__``, ``__main__``). A module may import its own layer, the layers its row names
(``X, Y and below``: X, Y and everything they may import) and the third-party packages its
row names; ``anything`` lifts the limit; ``-`` is nothing but the standard library. Relative
imports count as the absolute names they resolve to.

| layer    | may import (testbed)                               | third party                     |
|----------|----------------------------------------------------|---------------------------------|
| config   | -                                                  | -                               |
| protocol | config                                             | numpy                           |
| ecs      | config                                             | numpy                           |
| common   | ecs, protocol, config                              | numpy, numba                    |
| channel  | protocol, config                                   | numpy, simpy                    |
| imaging  | config                                             | numpy                           |
| vehicle  | common, ecs, protocol, imaging, config | numpy, scipy, numba, pybullet, py_trees |
| operator | common, ecs, protocol, imaging, config             | numpy                           |
| hil      | protocol, config                                   | numpy, serial                   |
| emulator | channel, protocol, config                          | numpy, simpy, serial            |
| mavlink  | common, ecs, protocol, hil, config                 | numpy, pymavlink                |
| run      | vehicle, operator, hil, mavlink, channel and below | numpy, scipy, simpy             |
| report   | run and below                                      | matplotlib, numpy               |
| sweep    | run and below                                      | numpy, scipy, distributed, tqdm |
| live     | run and below                                      | numpy, simpy, starlette, uvicorn |
| cli      | anything                                           | anything                        |
| __init__ | -                                                  | -                               |
| __main__ | cli                                                | -                               |

``mavlink`` reaches ``hil`` for its serial transport only, and never ``vehicle``: it pilots a world
through ``common``'s components. ``common`` is the ECS paper's shared library: the components both
nodes replicate and the link codecs that carry them. ``emulator`` does not import ``hil``: its modem
personalities are written independently of hil's adapters, so each checks the other. ``run`` does
not import ``emulator`` (a HIL run reaches it through serial ports) nor ``report``, ``sweep`` or
``cli``. Only ``testbed/vehicle/physics.py`` may import pybullet. ``sweep`` loads ``distributed``
(Dask) through ``importlib`` only when asked for a cluster.
"""

from __future__ import annotations

import ast
import sys
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import pytest

PACKAGE_ROOT = Path(__file__).resolve().parents[1] / "testbed"
PYBULLET_USERS = {"vehicle/physics.py"}
# Modules that break the table today; each test is xfail(strict=True) until the code is fixed.
KNOWN_VIOLATIONS: dict[str, str] = {}
ANYTHING = None  # a row's "anything"


@dataclass(frozen=True)
class Rule:
    """What one layer may import: testbed layers and third-party roots (None = anything)."""

    layers: frozenset[str] | None
    third_party: frozenset[str] | None


def parse_table(doc: str) -> dict[str, Rule]:
    """The layering table of ``doc`` (a Markdown table, rows in dependency order)."""
    rules: dict[str, Rule] = {}
    rows = [line for line in doc.splitlines() if line.startswith("|")][2:]  # header, rule
    for row in rows:
        names, internal, external = (cell.strip() for cell in row.strip("|").split("|"))
        layers = _cell(internal, rules, expand=True)
        third_party = _cell(external, rules, expand=False)
        for name in (n.strip() for n in names.split(",")):
            rules[name] = Rule(layers, third_party)
    return rules


def _cell(text: str, rules: dict[str, Rule], *, expand: bool) -> frozenset[str] | None:
    """One cell: ``-``, ``anything`` or a comma-separated list (``… and below`` expands)."""
    if text == "anything":
        return ANYTHING
    if text == "-":
        return frozenset()
    below = expand and text.endswith(" and below")
    found = {item.strip() for item in text.removesuffix(" and below").split(",")}
    for name in list(found) if below else []:
        layers = rules[name].layers
        assert layers is not ANYTHING, f"{name} may import anything: 'and below' is everything"
        found |= layers
    return frozenset(found)


RULES = parse_table(__doc__ or "")


def layer_of_path(relative_path: str) -> str:
    """The layer of a file under ``testbed/`` (``vehicle/physics.py`` → ``vehicle``)."""
    parts = relative_path.split("/")
    return parts[0] if len(parts) > 1 else parts[0].removesuffix(".py")


def layer_of_module(module: str) -> str:
    """The layer of an absolute ``testbed`` module name (``testbed`` itself → ``__init__``)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def module_name(relative_path: str) -> tuple[str, bool]:
    """``(absolute module name, is a package)`` of a file under ``testbed/``."""
    parts = ["testbed", *relative_path.removesuffix(".py").split("/")]
    if parts[-1] == "__init__":
        return ".".join(parts[:-1]), True
    return ".".join(parts), False


@cache
def known_modules() -> frozenset[str]:
    """Every module and package name of ``testbed/`` (to tell ``from p import module``)."""
    return frozenset(
        module_name(p.relative_to(PACKAGE_ROOT).as_posix())[0] for p in PACKAGE_ROOT.rglob("*.py")
    )


@dataclass(frozen=True)
class Import:
    """One imported module, resolved to its absolute name, and the function it sits in."""

    module: str
    line: int
    function: str | None  # the outermost enclosing def, None at module level


def resolve(node: ast.ImportFrom, module: str, is_package: bool) -> list[str]:
    """The absolute names a ``from … import …`` reaches, relative levels resolved.

    ``from p import name`` reaches ``p.name`` when that is a module of testbed, else ``p`` (the
    name is an attribute of ``p``).
    """
    if node.level:
        package = module.split(".") if is_package else module.split(".")[:-1]
        if node.level - 1 >= len(package):
            raise ValueError(f"{module}: relative import beyond the top-level package")
        base_parts = package[: len(package) - (node.level - 1)]
        base = ".".join(base_parts + ([node.module] if node.module else []))
    else:
        base = node.module or ""
    if not base.startswith("testbed"):
        return [base]
    return [
        f"{base}.{alias.name}" if f"{base}.{alias.name}" in known_modules() else base
        for alias in node.names
    ]


def imports_of(relative_path: str, source: str) -> list[Import]:
    """Every import of a module's source, resolved to absolute module names."""
    module, is_package = module_name(relative_path)
    found: list[Import] = []

    def visit(node: ast.AST, function: str | None) -> None:
        if isinstance(node, ast.Import):
            found.extend(Import(alias.name, node.lineno, function) for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            names = resolve(node, module, is_package)
            found.extend(Import(name, node.lineno, function) for name in dict.fromkeys(names))
        for child in ast.iter_child_nodes(node):
            if function is None and isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
                visit(child, child.name)
            else:
                visit(child, function)

    visit(ast.parse(source), None)
    return found


def violations(relative_path: str, source: str) -> list[str]:
    """Arrows from this module (a path under ``testbed/``) that the layering table forbids."""
    layer = layer_of_path(relative_path)
    if layer not in RULES:
        return [f"{relative_path}: layer {layer!r} has no row in the layering table"]
    rule = RULES[layer]
    found: list[str] = []
    for imp in imports_of(relative_path, source):
        root = imp.module.split(".")[0]
        where = f"{relative_path}:{imp.line} ({layer})"
        if root == "pybullet" and relative_path not in PYBULLET_USERS:
            found.append(f"{where} imports pybullet (only vehicle/physics.py may)")
        elif root == "testbed":
            target = layer_of_module(imp.module)
            if target in (layer, "__init__"):
                continue
            if target not in RULES:
                found.append(f"{where} imports {imp.module}: no such layer in the table")
            elif rule.layers is not ANYTHING and target not in rule.layers:
                found.append(f"{where} imports {imp.module} ({target})")
        elif (
            root not in sys.stdlib_module_names
            and root != "__future__"
            and rule.third_party is not ANYTHING
            and root not in rule.third_party
        ):
            found.append(f"{where} imports third-party {imp.module}")
    return found


def all_modules() -> list[Path]:
    return sorted(PACKAGE_ROOT.rglob("*.py"))


def _module_param(path: Path) -> object:
    relative = path.relative_to(PACKAGE_ROOT).as_posix()
    reason = KNOWN_VIOLATIONS.get(relative)
    marks = [pytest.mark.xfail(strict=True, reason=reason)] if reason else []
    return pytest.param(path, id=relative, marks=marks)


def test_package_has_modules() -> None:
    assert len(all_modules()) > 5


def test_table_names_only_its_own_layers_and_has_no_cycle() -> None:
    subpackages = {p.name for p in PACKAGE_ROOT.iterdir() if (p / "__init__.py").is_file()}
    assert subpackages - {"scenarios"} <= set(RULES), "a subpackage has no row"
    for name, rule in RULES.items():
        assert rule.layers is ANYTHING or rule.layers <= set(RULES), name
    order = list(RULES)  # rows are in dependency order: a row names only rows above it
    for name, rule in RULES.items():
        if rule.layers is not ANYTHING:
            assert all(order.index(dep) < order.index(name) for dep in rule.layers), name
    assert set(KNOWN_VIOLATIONS) <= {p.relative_to(PACKAGE_ROOT).as_posix() for p in all_modules()}


@pytest.mark.parametrize("path", [_module_param(p) for p in all_modules()])
def test_module_respects_layering(path: Path) -> None:
    relative = path.relative_to(PACKAGE_ROOT).as_posix()
    found = violations(relative, path.read_text(encoding="utf-8"))
    assert found == [], "\n".join(["layering violations:", *found])


def test_relative_imports_resolve_to_absolute_names() -> None:
    def names(path: str, source: str) -> list[str]:
        return [imp.module for imp in imports_of(path, source)]

    m64 = "emulator/personalities/m64.py"
    assert names(m64, "from .base import EOL") == ["testbed.emulator.personalities.base"]
    assert names(m64, "from . import base") == ["testbed.emulator.personalities.base"]
    assert names(m64, "from . import nothing") == ["testbed.emulator.personalities"]
    assert names(m64, "from ..ptys import ModemEmulator") == ["testbed.emulator.ptys"]
    assert names(m64, "from .. import ptys") == ["testbed.emulator.ptys"]
    assert names(m64, "from ...hil import adapters") == ["testbed.hil.adapters"]
    package = "emulator/personalities/__init__.py"
    assert names(package, "from .base import EOL") == ["testbed.emulator.personalities.base"]
    assert names(package, "from ..ptys import X") == ["testbed.emulator.ptys"]
    assert names("protocol/x.py", "from testbed import config") == ["testbed.config"]
    assert names("protocol/x.py", "import numpy as np") == ["numpy"]
    with pytest.raises(ValueError, match="beyond the top-level package"):
        names("protocol/x.py", "from .... import x")


def test_checker_catches_forbidden_arrows() -> None:
    # forbidden, relative and absolute
    assert violations("protocol/x.py", "from ..vehicle import physics") != []
    assert violations("protocol/x.py", "from testbed.vehicle import physics") != []
    assert violations("emulator/personalities/x.py", "from ...hil import adapters") != []
    assert violations("emulator/ptys.py", "from testbed.hil.adapters import S100Adapter") != []
    assert violations("ecs/world.py", "from testbed.vehicle import physics") != []
    assert violations("common/codec.py", "from testbed.vehicle import components") != []
    assert violations("operator/pilot.py", "from testbed.vehicle import components") != []
    assert violations("sweep/x.py", "from testbed.report import sweep_plots") != []
    assert violations("run/nodes.py", "from testbed.cli.main import main") != []
    assert violations("config.py", "from testbed.protocol import crc") != []
    assert violations("protocol/x.py", "import simpy") != []
    assert violations("imaging/x.py", "import pywt") != []
    assert violations("channel/medium.py", "import pybullet") != []
    assert violations("vehicle/allocation.py", "import pybullet") != []
    assert violations("cli/x.py", "import pybullet") != []
    assert violations("newlayer/x.py", "") != []  # a subpackage without a row
    assert violations("newroot.py", "") != []
    # run never reaches up to report, even lazily inside a function
    lazy = "def write_outputs():\n    from testbed.report.run_plots import write_plots\n"
    assert violations("run/runner.py", lazy) != []
    assert violations("run/runner.py", "from testbed.report import run_plots") != []
    # allowed
    assert violations("emulator/personalities/m64.py", "from .base import EOL") == []
    assert violations("emulator/personalities/m64.py", "from ..ptys import X") == []
    assert violations("operator/pilot.py", "from testbed.common import components") == []
    assert violations("vehicle/physics.py", "import pybullet") == []
    assert violations("channel/medium.py", "from ..protocol import crc16\nimport simpy") == []
    assert violations("report/x.py", "from testbed.channel import Trace\nimport matplotlib") == []
    assert violations("sweep/x.py", "from testbed.run.runner import run_scenario") == []
    assert violations("cli/x.py", "import matplotlib\nfrom testbed.sweep import run_sweep") == []
    assert violations("__main__.py", "from testbed.cli.main import main") == []
    assert violations("protocol/x.py", "import testbed\nfrom testbed import __version__") == []
