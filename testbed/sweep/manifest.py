"""``sweep.json``: which sweep a results directory holds, what it read, and what may resume it.

:func:`manifest` is the file's content: the sweep id, its base scenario, the net effect of its
overrides (the file's ``[set]`` and ``--set``, parsed), its grid and seeds, the SHA-256 of every
input (the scenario file, packaged or not, and each user file it or a grid point names:
:attr:`~testbed.sweep.spec.Sweep.inputs`) and the testbed version. :func:`compare` tells a
resume what it may do: continue (the same sweep), grow (the same sweep with grid values or seeds
added: finished runs are kept), or refuse, naming each difference (``old → new``).

Values are compared parsed, not as text: ``0``, ``0.0`` and ``0e0`` are one value, the order of
independent overrides does not matter, and an inline table is the table it sets.

The file is strict JSON. A setting that is not a finite number (``link.max_range_m = inf``,
unlimited: the only kind a scenario key accepts) is written as its TOML spelling, the string
``"inf"`` (``"-inf"``, ``"nan"``), as ``overrides`` has it: a setting has a value, unlike a
metric with none (``null`` in ``metrics.json``), and the string keeps it for a reader and for
``--resume``, which compares both files' values in that form (a file written before, with a
bare ``Infinity``, resumes too).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import testbed
from testbed.config import apply_overrides
from testbed.sweep.keys import toml_literal
from testbed.sweep.spec import Sweep

__all__ = ["FORMAT", "Resumption", "canonical", "compare", "manifest", "manifest_text"]

FORMAT = 2
"""Version of ``sweep.json``'s layout (1: before input hashes, which a resume cannot check)."""


def canonical(value: Any) -> Any:
    """``value`` in the form two equal settings share, strict JSON's: numbers as floats (``30``
    = ``30.0``), a number that is not finite as its TOML spelling (``inf`` → ``"inf"``), tables
    with sorted keys, arrays as lists."""
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return value
    if isinstance(value, int | float):
        return float(value) if math.isfinite(value) else toml_literal(float(value))
    if isinstance(value, Mapping):
        return {str(k): canonical(value[k]) for k in sorted(value)}
    if isinstance(value, list | tuple):
        return [canonical(v) for v in value]
    return value


def key_of(value: Any) -> str:
    """A hashable, canonical text of ``value`` (to find a grid value among others)."""
    return json.dumps(canonical(value), sort_keys=True)


def manifest(sweep: Sweep) -> dict[str, Any]:
    """What ``sweep.json`` holds for ``sweep`` (see the module docstring)."""
    return {
        "format": FORMAT,
        "id": sweep.id,
        "scenario": sweep.scenario,
        "overrides": list(sweep.overrides),
        "set": canonical(apply_overrides({}, sweep.overrides)),
        "axes": [[key, [canonical(v) for v in values]] for key, values in sweep.axes],
        "seeds": list(sweep.seeds),
        "inputs": dict(sweep.inputs),
        "testbed": testbed.__version__,
    }


def manifest_text(sweep: Sweep) -> str:
    """``sweep.json``'s text: :func:`manifest` as indented strict JSON with sorted keys."""
    return json.dumps(manifest(sweep), indent=1, sort_keys=True, allow_nan=False) + "\n"


@dataclass(frozen=True, slots=True)
class Resumption:
    """What a resume may do with the sweep held in a directory.

    Attributes:
        differences: why it may not (``"seeds: 3 removed"``, ``"input /a.toml changed"``…);
            empty when it may.
        grown: the new sweep adds grid values or seeds to the held one, or lists a grid's
            values in another order (its finished runs are kept; their point numbers are
            renumbered by their grid values).
    """

    differences: tuple[str, ...]
    grown: bool


def _leaves(table: Any, prefix: str = "") -> dict[str, Any]:
    """``{dotted key: value}`` of a nested table (a non-table is one leaf)."""
    if not isinstance(table, dict) or not table:
        return {prefix.rstrip("."): table} if prefix else {}
    leaves: dict[str, Any] = {}
    for key, value in table.items():
        leaves.update(_leaves(value, f"{prefix}{key}."))
    return leaves


_NOT_FINITE = frozenset({"inf", "-inf", "nan"})
""":func:`canonical`'s spellings of the numbers that are not finite."""


def _shown(value: Any) -> str:
    if value is _ABSENT:
        return "(none)"
    if value in _NOT_FINITE:
        return str(value)  # a number, as TOML spells it
    try:
        return toml_literal(value)
    except TypeError:
        return repr(value)


_ABSENT = object()


def compare(held: Mapping[str, Any], new: Mapping[str, Any]) -> Resumption:
    """Compare a held ``sweep.json`` (a :func:`manifest`) with the new sweep's.

    Refused: another id, base scenario, override value, grid axis, a removed grid value or seed,
    a changed or missing input (by SHA-256) or another testbed version. Added grid values and
    seeds, and a grid's values listed in another order, are growth, not a difference.
    """
    out: list[str] = []
    for name in ("id", "scenario", "testbed"):
        if held.get(name) != new[name]:
            out.append(f"{name}: {held.get(name)} → {new[name]}")
    old_set, new_set = _leaves(canonical(held.get("set"))), _leaves(new["set"])
    for key in sorted(set(old_set) | set(new_set)):
        before, after = old_set.get(key, _ABSENT), new_set.get(key, _ABSENT)
        if before != after:
            out.append(f"[set]/--set {key}: {_shown(before)} → {_shown(after)}")
    grown = False
    old_axes = {key: values for key, values in held.get("axes") or []}
    new_axes = {key: values for key, values in new["axes"]}
    if list(old_axes) != list(new_axes):
        out.append(f"grid: axes {', '.join(old_axes)} → {', '.join(new_axes)}")
    else:
        for key, values in new_axes.items():
            kept = {key_of(v) for v in values}
            removed = [v for v in old_axes[key] if key_of(v) not in kept]
            if removed:
                out.append(f"grid.{key}: {', '.join(_shown(v) for v in removed)} removed")
            # values added, or the same ones in another order: point numbers move either way
            grown |= [key_of(v) for v in values] != [key_of(v) for v in old_axes[key]]
    old_seeds, new_seeds = held.get("seeds") or [], new["seeds"]
    removed_seeds = [s for s in old_seeds if s not in set(new_seeds)]
    if removed_seeds:
        out.append(f"seeds: {', '.join(map(str, removed_seeds))} removed")
    grown |= len(set(new_seeds) - set(old_seeds)) > 0
    old_inputs, new_inputs = held.get("inputs") or {}, new["inputs"]
    for path, digest in sorted(old_inputs.items()):
        now = new_inputs.get(path)
        if now is None:
            out.append(f"input {path}: no longer read")
        elif now != digest:
            out.append(f"input {path}: changed (SHA-256 {digest[:12]}… → {now[:12]}…)")
    return Resumption(tuple(out), grown)
