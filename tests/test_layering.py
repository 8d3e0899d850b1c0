"""Imports flow one way: the layering table of DESIGN.md, enforced on every module.

| layer    | may import (testbed)                        | third party            |
|----------|---------------------------------------------|------------------------|
| config   | -                                           | -                      |
| protocol | config                                      | numpy                  |
| ecs      | config                                      | numpy                  |
| common   | ecs, protocol, config                       | numpy                  |
| channel  | protocol, config                            | numpy, simpy           |
| imaging  | config                                      | numpy, pywt            |
| vehicle  | common, ecs, protocol, imaging, config      | numpy, scipy, pybullet |
| operator | common, ecs, protocol, imaging, config      | numpy                  |
| hil      | protocol, config                            | numpy, serial          |
| mavlink  | ecs, protocol, config                       | numpy, pymavlink       |
| top      | anything (scenario, runner, sweep, report, cli) | anything           |

``common`` is the ECS paper's shared library: the components both nodes replicate and the link
codecs that carry them. Only ``testbed/vehicle/physics.py`` may import pybullet.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

PACKAGE_ROOT = Path(__file__).resolve().parents[1] / "testbed"

ALLOWED_INTERNAL: dict[str, set[str]] = {
    "config": set(),
    "protocol": {"config"},
    "ecs": {"config"},
    "common": {"ecs", "protocol", "config"},
    "channel": {"protocol", "config"},
    "imaging": {"config"},
    "vehicle": {"common", "ecs", "protocol", "imaging", "config"},
    "operator": {"common", "ecs", "protocol", "imaging", "config"},
    "hil": {"protocol", "config"},
    "mavlink": {"ecs", "protocol", "config"},
}
ALLOWED_THIRD_PARTY: dict[str, set[str]] = {
    "config": set(),
    "protocol": {"numpy"},
    "ecs": {"numpy"},
    "common": {"numpy"},
    "channel": {"numpy", "simpy"},
    "imaging": {"numpy", "pywt"},
    "vehicle": {"numpy", "scipy", "pybullet"},
    "operator": {"numpy"},
    "hil": {"numpy", "serial"},
    "mavlink": {"numpy", "pymavlink"},
}
PYBULLET_USERS = {"vehicle/physics.py"}


def layer_of(relative_path: str) -> str | None:
    """The layer a module belongs to, or None for top-level modules that may import anything."""
    first = relative_path.split("/")[0].removesuffix(".py")
    return first if first in ALLOWED_INTERNAL else None


def imported_modules(source: str) -> list[str]:
    """Absolute module names imported by ``source`` (relative imports resolve to the package)."""
    names: list[str] = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names.extend(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                names.append("testbed.<relative>")
            elif node.module:
                names.append(node.module)
    return names


def violations(relative_path: str, source: str) -> list[str]:
    """Arrows from this module that the layering table forbids."""
    layer = layer_of(relative_path)
    found: list[str] = []
    for name in imported_modules(source):
        root = name.split(".")[0]
        if root == "pybullet" and relative_path not in PYBULLET_USERS:
            found.append(f"{relative_path} imports pybullet (only vehicle/physics.py may)")
        if layer is None or root in sys.stdlib_module_names or root == "__future__":
            continue
        if root == "testbed":
            if name == "testbed.<relative>":
                continue  # relative imports stay inside the module's own package
            target = name.split(".")[1] if "." in name else ""
            if target != layer and target not in ALLOWED_INTERNAL[layer]:
                found.append(f"{relative_path} ({layer}) imports {name}")
        elif root not in ALLOWED_THIRD_PARTY[layer]:
            found.append(f"{relative_path} ({layer}) imports third-party {name}")
    return found


def all_modules() -> list[Path]:
    return sorted(PACKAGE_ROOT.rglob("*.py"))


def test_package_has_modules() -> None:
    assert len(all_modules()) > 5


@pytest.mark.parametrize("path", all_modules(), ids=lambda p: str(p.relative_to(PACKAGE_ROOT)))
def test_module_respects_layering(path: Path) -> None:
    relative = path.relative_to(PACKAGE_ROOT).as_posix()
    assert violations(relative, path.read_text(encoding="utf-8")) == []


def test_checker_catches_forbidden_arrows() -> None:
    assert violations("protocol/x.py", "import simpy") != []
    assert violations("protocol/x.py", "from testbed.channel import Medium") != []
    assert violations("ecs/world.py", "from testbed.vehicle import physics") != []
    assert violations("common/codec.py", "from testbed.vehicle import components") != []
    assert violations("operator/pilot.py", "from testbed.vehicle import components") != []
    assert violations("operator/pilot.py", "from testbed.common import components") == []
    assert violations("channel/medium.py", "import pybullet") != []
    assert violations("vehicle/allocation.py", "import pybullet") != []
    assert violations("vehicle/physics.py", "import pybullet") == []
    assert violations("channel/medium.py", "from testbed.protocol import crc16\nimport simpy") == []
    assert violations("cli.py", "import matplotlib\nfrom testbed.vehicle import physics") == []
