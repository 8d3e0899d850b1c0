"""testbed.config: strict TOML → frozen dataclass loading and --set overrides."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import pytest

from testbed.config import (
    ConfigError,
    FieldError,
    apply_overrides,
    build,
    built_from_text,
    check,
    load_toml,
)


@dataclass(frozen=True, slots=True)
class Inner:
    rate_hz: float = 10.0
    names: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        check(self.rate_hz > 0, "rate_hz", f"must be > 0, got {self.rate_hz}")


@dataclass(frozen=True, slots=True)
class Outer:
    kind: Literal["a", "b"]
    count: int = 1
    enabled: bool = False
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    limit: float | None = None
    inner: Inner = field(default_factory=Inner)


def test_build_converts_and_defaults() -> None:
    cfg = build(Outer, {"kind": "a", "offset": [1, 2, 3.5], "inner": {"rate_hz": 5}})
    assert cfg == Outer(kind="a", offset=(1.0, 2.0, 3.5), inner=Inner(rate_hz=5.0))
    assert isinstance(cfg.offset[0], float)


@pytest.mark.parametrize(
    ("data", "fragment"),
    [
        ({"kind": "a", "bogus": 1}, "f.toml: bogus: unknown key"),
        ({"kind": "c"}, "f.toml: kind: expected one of"),
        ({}, "f.toml: kind: required key missing"),
        ({"kind": "a", "count": 1.5}, "f.toml: count: expected an integer"),
        ({"kind": "a", "count": True}, "f.toml: count: expected an integer"),
        ({"kind": "a", "enabled": 1}, "f.toml: enabled: expected true or false"),
        ({"kind": "a", "offset": [1, 2]}, "f.toml: offset: expected 3 values"),
        ({"kind": "a", "inner": {"rate_hz": -1}}, "f.toml: inner.rate_hz: must be > 0"),
        ({"kind": "a", "inner": {"rate": 1}}, "f.toml: inner.rate: unknown key"),
        ({"kind": "a", "limit": "x"}, "f.toml: limit: expected a number"),
        ({"kind": "a", "limit": 10**400}, "f.toml: limit: a 1329-bit integer, beyond any float"),
        ({"kind": "a", "inner": 3}, "f.toml: inner: expected a table"),
    ],
)
def test_build_rejects_with_file_and_key(data: dict[str, object], fragment: str) -> None:
    with pytest.raises(ConfigError) as info:
        build(Outer, data, source="f.toml")
    assert fragment in str(info.value)
    assert "\n" not in str(info.value)


def test_overrides_are_typed_toml_values() -> None:
    data = apply_overrides({"kind": "a"}, ["count=3", "inner.rate_hz=2.5", "kind=b", "limit=1e-3"])
    assert build(Outer, data) == Outer(kind="b", count=3, limit=1e-3, inner=Inner(rate_hz=2.5))


def test_override_bad_value_and_unknown_key_are_errors() -> None:
    with pytest.raises(ConfigError, match="count: expected an integer"):
        build(Outer, apply_overrides({"kind": "a"}, ["count=abc"]), source="--set")
    with pytest.raises(ConfigError, match=r"inner\.nope: unknown key"):
        build(Outer, apply_overrides({"kind": "a"}, ["inner.nope=1"]), source="--set")
    with pytest.raises(ConfigError, match="expected KEY=VALUE"):
        apply_overrides({}, ["novalue"])


def test_override_does_not_mutate_input() -> None:
    data = {"kind": "a", "inner": {"rate_hz": 1.0}}
    apply_overrides(data, ["inner.rate_hz=2"])
    assert data["inner"] == {"rate_hz": 1.0}


def test_load_toml_errors_name_the_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"missing\.toml: file not found"):
        load_toml(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("a = [1,\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=r"bad\.toml: malformed TOML"):
        load_toml(bad)


def test_field_error_carries_key() -> None:
    err = FieldError("x", "bad")
    assert err.key == "x" and str(err) == "x: bad"


def test_load_toml_reads_the_file_each_time_and_hands_out_a_new_dict(tmp_path: Path) -> None:
    """Parsed texts are kept (a sweep's check loads the same files once per grid point), but a
    file edited between two loads is read as it is now, and a caller's changes to what it got
    reach no other caller."""
    path = tmp_path / "m.toml"
    path.write_text('name = "a"\n[t]\nx = [1.0, 2.0]\n')
    first = load_toml(path)
    first["t"]["x"].append(3.0)
    assert load_toml(path) == {"name": "a", "t": {"x": [1.0, 2.0]}}
    path.write_text('name = "b"\n[t]\nx = [1.0, 2.0]\n')
    assert load_toml(path)["name"] == "b"


def test_a_value_built_from_a_file_is_built_once_per_text_and_again_after_an_edit(
    tmp_path: Path,
) -> None:
    """built_from_text: the same text (and options) is not built again; an edit of the file,
    other options, or an error (raised each time, never kept) are."""
    path = tmp_path / "f.toml"
    path.write_text("x = 1\n", encoding="utf-8")
    built: list[int] = []

    def make() -> int:
        value = int(load_toml(path)["x"])
        built.append(value)
        if value < 0:
            raise ConfigError(f"{path}: x: must be >= 0")
        return value

    assert [built_from_text("t", path, make) for _ in range(3)] == [1, 1, 1]
    assert built == [1]
    assert built_from_text("t", path, make, "other option") == 1 and built == [1, 1]
    path.write_text("x = 2\n", encoding="utf-8")
    assert built_from_text("t", path, make) == 2 and built == [1, 1, 2]
    path.write_text("x = -1\n", encoding="utf-8")
    for _ in range(2):
        with pytest.raises(ConfigError, match="must be >= 0"):
            built_from_text("t", path, make)
    assert built == [1, 1, 2, -1, -1]
