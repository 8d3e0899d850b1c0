"""What the recorder keeps of a link model's own state: :class:`LinkStateLog`, the rows of
``link_state.csv``.

A link model of one's own (:class:`~testbed.channel.model.LinkModel`) may define
``state(t_s) -> Mapping[str, float]``: the figures it wants to see beside the run (the bit rate
in force, a fade's state, a rate adaptation's choice), by name. The run asks for them with each
series row (the first vehicle frame at or after each ``metrics.sample_rate_hz`` instant, the
same ``t_s`` as ``series.csv``) and writes them to ``link_state.csv``: ``t_s`` and the names in
the order of the first answer. A model without ``state`` is asked nothing and no file is
written. The values are numbers, Python's or numpy's (a ``bool``, numpy's too, is written 0/1;
NaN is allowed, for "no value");
the names are the first answer's, at every sample. Anything else, or a ``state`` that raises, is
a :class:`~testbed.channel.model.LinkModelError` naming the model's class and file (one line,
exit 2 on the command line; the run's rows until then are kept); a ``state`` that is not a
method is refused before the run. The model is asked at the
vehicle's frame, never by the medium, so asking changes nothing the link does, provided
``state`` draws no random numbers and changes nothing.
"""

from __future__ import annotations

import csv
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np

from testbed.channel.model import LinkModelError
from testbed.config import CSV_NUMBER_FORMAT, described_class, shown_line
from testbed.run.recorder import SeriesRows

__all__ = ["LinkStateLog"]


class LinkStateLog:
    """A link model's state over one run, one row per series sample.

    Args:
        model: the run's link model; :meth:`of` makes the log only for a model with ``state``.
    """

    __slots__ = ("_model", "_state", "columns", "rows")

    def __init__(self, model: object, state: Callable[[float], object]) -> None:
        self._model = model
        self._state = state
        self.columns: tuple[str, ...] = ()
        """``t_s`` and the state's names, once the first row is taken (empty before)."""
        self.rows: SeriesRows | None = None

    @classmethod
    def of(cls, model: object | None) -> LinkStateLog | None:
        """The empty log of ``model``, or None when it has no ``state``.

        Raises:
            LinkModelError: ``model`` has a ``state`` that is not callable (an attribute where
                the method belongs: silently never recorded, before).
        """
        if model is None or not hasattr(model, "state"):
            return None
        state = model.state
        if not callable(state):
            raise LinkModelError(
                f"link model {described_class(model)}: state is {shown_line(state)}, not a "
                "method: expected state(t_s) -> Mapping[str, float], or no attribute 'state'"
            )
        return cls(model, state)

    def record(self, t_s: float) -> None:
        """Append the model's state at vehicle time ``t_s`` [s].

        Raises:
            LinkModelError: ``state`` raised, or its answer is not a mapping of the first
                answer's names to numbers.
        """
        try:
            answer = self._state(t_s)
        except Exception as error:
            raise LinkModelError.raised(self._model, f"state({t_s!r})", error) from error
        if not isinstance(answer, Mapping):
            raise self._broken(t_s, answer, "expected a mapping of names to numbers")
        if self.rows is None:
            names = tuple(answer)
            if any(not isinstance(n, str) or not n or n == "t_s" for n in names):
                raise self._broken(t_s, answer, "names must be non-empty strings other than 't_s'")
            self.columns = ("t_s", *names)
            self.rows = SeriesRows(len(self.columns))
        names = self.columns[1:]
        if len(answer) != len(names) or any(n not in answer for n in names):
            raise self._broken(t_s, answer, f"expected the names {list(names)} of its first answer")
        row = [t_s]
        for name in names:
            value = answer[name]
            if not isinstance(value, int | float | np.integer | np.floating | np.bool_):
                raise self._broken(t_s, answer, f"{name!r} is not a number")
            try:
                row.append(float(value))
            except OverflowError:  # an int past a float's range (10**400)
                raise self._broken(t_s, answer, f"{name!r} is too large for a float") from None
        self.rows.append(row)

    def _broken(self, t_s: float, answer: object, why: str) -> LinkModelError:
        return LinkModelError.state(self._model, t_s, answer, why)

    def table(self) -> dict[str, np.ndarray]:
        """The rows as one array per column (read-only views, no copy); empty before the first
        row."""
        if self.rows is None:
            return {}
        table = self.rows.table()
        return {name: table[:, k] for k, name in enumerate(self.columns)}

    def write_csv(self, path: Path) -> None:
        """Write ``link_state.csv``: a header of :attr:`columns`, values to 6 significant
        digits (``nan`` for NaN), or only ``t_s`` when no row was taken."""
        with path.open("w", newline="", encoding="utf-8") as handle:
            writer = csv.writer(handle, lineterminator="\n")
            writer.writerow(self.columns or ("t_s",))
            for row in self.rows or ():
                writer.writerow([f"{v:{CSV_NUMBER_FORMAT}}" for v in row])
