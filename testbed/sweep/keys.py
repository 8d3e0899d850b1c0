"""A sweep file's tables as scenario keys, and grid values written back as TOML.

:func:`flatten_section` turns the file's ``[set]`` or ``[grid]`` into dotted scenario keys
(``link.ber``), nested tables and quoted dotted keys alike, refusing a key given twice; in the
grid a table with ``scale`` (or any plain value) is a range, one value. :func:`fixed_and_swept`
and :func:`override_keys` find a key both fixed and swept; :func:`repeated_value` a grid value
given twice. :func:`toml_literal` writes a value so that ``--set`` parsing reads it back
exactly: grid values travel to the runs that way. No file is read here
(:mod:`testbed.sweep.spec` loads the sweep).
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from testbed.config import ConfigError, parse_override
from testbed.run.plugins import TABLE_VALUE_KEYS

__all__ = [
    "DuplicateKeyError",
    "fixed_and_swept",
    "flatten_section",
    "override_keys",
    "repeated_value",
    "toml_literal",
]


def toml_literal(value: Any) -> str:
    """``value`` as a TOML value, so it survives ``--set``-style parsing exactly."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)  # repr round-trips floats; TOML reads inf, nan, 1e-05
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(toml_literal(v) for v in value) + "]"
    if isinstance(value, Mapping):
        items = ", ".join(f"{json.dumps(str(k))} = {toml_literal(v)}" for k, v in value.items())
        return "{" + items + "}"
    raise TypeError(f"cannot write {value!r} as TOML")  # TOML data holds no other types


def _flatten_table(
    table: Mapping[str, Any], prefix: str = "", *, keep_empty: bool = False
) -> dict[str, Any]:
    """Nested tables → dotted keys; a table with a ``scale`` key is a range, not a level. An
    empty table is dropped, or with ``keep_empty`` (the grid) kept as a value (the grid refuses
    it), and so is a table :func:`_is_range` takes for a range without ``scale``. Outside the
    grid a table at a :data:`~testbed.run.plugins.TABLE_VALUE_KEYS` key is one value (a
    factory's arguments, set whole)."""
    flat: dict[str, Any] = {}
    for key, value in table.items():
        dotted = f"{prefix}{key}"
        whole = not keep_empty and dotted in TABLE_VALUE_KEYS
        level = (
            isinstance(value, Mapping)
            and not whole
            and not (_is_range(value) if keep_empty else "scale" in value)
        )
        inner = (
            _flatten_table(value, f"{dotted}.", keep_empty=keep_empty)
            if level and (value or not keep_empty)
            else {dotted: value}
        )
        for name, leaf in inner.items():
            if name in flat:  # "link.ber" = … and link.ber = …: two TOML keys, one sweep key
                raise DuplicateKeyError(name)
            flat[name] = leaf
    return flat


def flatten_section(
    table: Mapping[str, Any], name: str, source: str, *, keep_empty: bool = False
) -> dict[str, Any]:
    """:func:`_flatten_table` of the sweep file's ``[name]``, a key given twice one line."""
    try:
        return _flatten_table(table, keep_empty=keep_empty)
    except DuplicateKeyError as err:
        raise ConfigError(
            f"{source}: {name}.{err.key}: given twice (a quoted dotted key and a nested one "
            "name the same setting)"
        ) from None


class DuplicateKeyError(ValueError):
    """A sweep key given twice in one table (a quoted dotted key and a nested one): the
    caller names the file and the table."""

    def __init__(self, key: str) -> None:
        super().__init__(key)
        self.key = key


def _is_range(table: Mapping[str, Any]) -> bool:
    """A grid table that is a range, not a level of nested keys: it has ``scale``, or a value
    that is neither a table nor an array (a level holds only those: ``start = 1.0`` is a
    range's, one whose ``scale`` is missing)."""
    return "scale" in table or any(not isinstance(v, Mapping | list) for v in table.values())


def fixed_and_swept(fixed: Iterable[str], swept: Sequence[str]) -> tuple[str, str] | None:
    """The first ``(fixed key, swept key)`` pair that sets the same scenario value (the same
    key, or one inside the other: ``link`` and ``link.ber``), or None. The grid point's
    override comes last, so a fixed value there would be silently lost."""
    for key in fixed:
        for axis in swept:
            if key == axis or key.startswith(f"{axis}.") or axis.startswith(f"{key}."):
                return key, axis
    return None


def override_keys(overrides: Sequence[str]) -> list[str]:
    """The dotted scenario keys that ``KEY=VALUE`` overrides set (an inline table's leaves)."""
    keys: list[str] = []
    for text in overrides:
        path, value = parse_override(text)
        keys.extend(_flatten_table({".".join(path): value}))
    return keys


def repeated_value(values: Sequence[Any]) -> Any | None:
    """The first value of a grid list equal to an earlier one (numbers by value: ``0`` and
    ``0.0`` are one point), or None."""
    seen: set[Any] = set()
    for value in values:
        number = isinstance(value, int | float) and not isinstance(value, bool)
        key = ("number", float(value)) if number else ("value", toml_literal(value))
        if key in seen:
            return value
        seen.add(key)
    return None
