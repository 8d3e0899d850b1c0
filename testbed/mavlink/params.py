"""The vehicle's ArduSub parameter table: names, MAVLink types, values and accepted ranges.

The table is package data (``data/ardusub_params.csv``, attributed there): a realistic subset
of ArduSub's parameters, in ArduSub's order. :class:`ParamTable` serves the MAVLink parameter
protocol's reads and writes (:mod:`testbed.mavlink.endpoint` sends the messages): values are
floats on the wire whatever the type (ArduPilot's C-cast encoding), integer types are rounded
on write, non-finite values and values outside a row's range are refused. The endpoint reads
the parameters that take effect in the simulator (failsafes, joystick gain, system ids) from
the table each time it needs them, so a PARAM_SET acts at once.

Names are at most 16 characters (MAVLink's ``param_id``); ArduPilot 4.7's ``MAV_GCS_SYSID`` is
accepted as an alias of ArduSub 4.5's ``SYSID_MYGCS``. Standard library only.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass
from importlib import resources

__all__ = ["ALIASES", "PARAM_TYPES", "Param", "ParamTable", "load_params"]

PARAM_TYPES = {"INT8": 2, "INT16": 4, "INT32": 6, "REAL32": 9}
"""Table type → ``MAV_PARAM_TYPE`` (INT8 2, INT16 4, INT32 6, REAL32 9)."""
_INT_LIMITS = {"INT8": (-128, 127), "INT16": (-32768, 32767), "INT32": (-(2**31), 2**31 - 1)}
ALIASES = {"MAV_GCS_SYSID": "SYSID_MYGCS"}
"""Older parameter names accepted on read and write → the table's name."""
_RESOURCE = "ardusub_params.csv"


@dataclass(frozen=True, slots=True)
class Param:
    """One parameter row.

    Attributes:
        name: ArduSub name (≤ 16 characters).
        kind: ``INT8``, ``INT16``, ``INT32`` or ``REAL32``.
        value: boot value.
        low: smallest accepted value (−inf: none).
        high: largest accepted value (+inf: none).
        simulated: True if it takes effect in the simulator.
    """

    name: str
    kind: str
    value: float
    low: float = -math.inf
    high: float = math.inf
    simulated: bool = False

    @property
    def mav_type(self) -> int:
        """The ``MAV_PARAM_TYPE`` number."""
        return PARAM_TYPES[self.kind]


def load_params() -> tuple[Param, ...]:
    """The packaged table, in file order.

    Raises:
        ValueError: a malformed row (a packaging error, not user input).
    """
    text = resources.files("testbed.mavlink").joinpath("data", _RESOURCE).read_text("utf-8")
    lines = [line for line in text.splitlines() if line and not line.startswith("#")]
    rows: list[Param] = []
    for row in csv.DictReader(io.StringIO("\n".join(lines))):
        kind = row["type"]
        if kind not in PARAM_TYPES or not 0 < len(row["name"]) <= 16:
            raise ValueError(f"{_RESOURCE}: bad row {row}")
        rows.append(
            Param(
                row["name"],
                kind,
                float(row["value"]),
                float(row["min"]) if row["min"] else -math.inf,
                float(row["max"]) if row["max"] else math.inf,
                row["sim"] == "sim",
            )
        )
    if len({p.name for p in rows}) != len(rows):
        raise ValueError(f"{_RESOURCE}: duplicate names")
    return tuple(rows)


class ParamTable:
    """The live parameter values.

    Args:
        params: the rows (default: :func:`load_params`).
        overrides: boot values replacing the table's (e.g. ``FRAME_CONFIG`` from the vehicle's
            thruster layout), by name; unknown names raise ``KeyError``.

    Attributes:
        sets_accepted: PARAM_SETs that changed or confirmed a value.
        sets_refused: PARAM_SETs refused (unknown name, non-finite, out of range).
    """

    def __init__(
        self, params: tuple[Param, ...] | None = None, overrides: dict[str, float] | None = None
    ) -> None:
        self.params = load_params() if params is None else params
        self._index = {p.name: i for i, p in enumerate(self.params)}
        self._values = [p.value for p in self.params]
        self.sets_accepted = 0
        self.sets_refused = 0
        for name, value in (overrides or {}).items():
            self._values[self._index[name]] = float(value)

    def __len__(self) -> int:
        return len(self.params)

    def __getitem__(self, name: str) -> float:
        """The value of ``name`` (an alias too); ``KeyError`` if unknown (local misuse)."""
        return self._values[self._index[ALIASES.get(name, name)]]

    def index_of(self, name: str) -> int | None:
        """The index of ``name`` (or its alias), None if unknown."""
        return self._index.get(ALIASES.get(name, name))

    def entry(self, index: int) -> tuple[Param, float] | None:
        """Row ``index`` and its value, None if out of range."""
        if not 0 <= index < len(self.params):
            return None
        return self.params[index], self._values[index]

    def boot_value(self, name: str, value: float) -> float:
        """``value`` as ``name``'s value at boot, as PARAM_SET would take it (an integer's
        rounded).

        Raises:
            ValueError: an unknown name, or a value PARAM_SET refuses (non-finite, outside the
                row's range or the type's), the message saying which.
        """
        index = self.index_of(name)
        if index is None:
            raise ValueError(f"unknown ArduSub parameter {name!r}")
        probe = ParamTable(self.params)
        if probe.set(name, value) is None:
            param = self.params[index]
            raise ValueError(f"{name} = {value!r} refused (range [{param.low:g}, {param.high:g}])")
        return probe[name]

    def set(self, name: str, value: float) -> int | None:
        """Set ``name`` to ``value`` (an integer type's as ArduPilot's PARAM_SET takes it: 0.01
        added away from zero, then truncated, so 1.7 is 1 and 1.999 is 2).

        Returns:
            The parameter's index if accepted; None if refused (unknown name, non-finite
            value, outside the row's range or the type's), the value then unchanged.
        """
        index = self.index_of(name)
        if index is None or not math.isfinite(value):
            self.sets_refused += 1
            return None
        param = self.params[index]
        if param.kind in _INT_LIMITS:
            low, high = _INT_LIMITS[param.kind]
            value = float(math.trunc(value + math.copysign(0.01, value)))
            if not low <= value <= high:
                self.sets_refused += 1
                return None
        if not param.low <= value <= param.high:
            self.sets_refused += 1
            return None
        self._values[index] = value
        self.sets_accepted += 1
        return index
