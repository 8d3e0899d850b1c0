"""The three-phase schedule: ordered lists of plain system functions, and how ticks advance.

A system is a plain function ``verb_noun(world: World) -> None``. Each frame runs the phases in
order, and within a phase the systems in the order they were added:

- ``PRE_UPDATE`` ingests: sensors, inbound frames, inbound replication;
- ``UPDATE`` decides: pilot, control, allocation;
- ``POST_UPDATE`` responds: actuation, outbound replication.

Tick rule (Bevy's): **the schedule advances the world tick once after every system it runs.**
For each system, :meth:`Schedule.run` sets ``world.last_run_tick`` to that system's previous run
tick (0 before its first run), calls it (its writes are stamped with the current world tick),
records the current tick as its new run tick, then calls ``world.advance()``. So every system run
owns a distinct tick, and "changed since this system last ran" (``changed_tick > last_run_tick``)
sees every change made after that system's previous run started and before this one, exactly
once:

- a change written in UPDATE of frame k is seen by a POST_UPDATE system in frame k (its last run
  was in frame k-1, earlier) and by a PRE_UPDATE system in frame k+1 (its last run, in frame k,
  came before the write), and by neither again afterwards;
- a system does not see its own writes of a previous run (they carry its last run tick), but
  does see them within the same run;
- writes made between frames (a node ingesting before ``run``) carry a tick no system has run at
  yet, so every system sees them in the next frame.

World ticks therefore count system runs, not frames: after a frame the tick has grown by the
number of systems. Nodes need not call ``world.advance()`` themselves (an extra call is harmless:
ticks only need to grow). This module knows nothing of replication or time.
"""

from __future__ import annotations

import enum
from collections.abc import Callable

from testbed.ecs.world import World

__all__ = ["Phase", "Schedule", "System"]

System = Callable[[World], None]
"""A system: a plain function ``verb_noun(world) -> None``."""


class Phase(enum.IntEnum):
    """Frame phases, run in this order.

    PRE_UPDATE ingests inputs (sensors, inbound frames and replication); UPDATE decides (pilot,
    control, allocation); POST_UPDATE responds (actuation, outbound replication).
    """

    PRE_UPDATE = 0
    UPDATE = 1
    POST_UPDATE = 2


class _Entry:
    """One added system and its previous run tick."""

    __slots__ = ("last_run", "name", "phase", "system")

    def __init__(self, phase: Phase, system: System, name: str) -> None:
        self.phase = phase
        self.system = system
        self.name = name
        self.last_run = 0


class Schedule:
    """Systems in three ordered phases, run once per frame against one world."""

    __slots__ = ("_entries", "_names", "_order", "_world")

    def __init__(self) -> None:
        self._entries: dict[Phase, list[_Entry]] = {phase: [] for phase in Phase}
        self._names: set[str] = set()
        self._order: list[_Entry] | None = None
        self._world: World | None = None

    def add(self, phase: Phase, system: System, *, name: str | None = None) -> None:
        """Append ``system`` to ``phase`` (it runs after the systems already there).

        Args:
            phase: the phase to run in.
            system: a function taking the world.
            name: a unique name (default: the function's ``__name__``).

        Raises:
            TypeError: ``phase`` is not a :class:`Phase` or ``system`` is not callable.
            ValueError: the name is already used in this schedule.
        """
        if not isinstance(phase, Phase):
            raise TypeError(f"phase must be a Phase, got {phase!r}")
        if not callable(system):
            raise TypeError(f"system must be callable, got {system!r}")
        label = name if name is not None else getattr(system, "__name__", repr(system))
        if label in self._names:
            raise ValueError(f"a system named {label!r} is already in this schedule")
        self._names.add(label)
        self._entries[phase].append(_Entry(phase, system, label))
        self._order = None

    def names(self, phase: Phase | None = None) -> list[str]:
        """System names in run order (of one phase, or of the whole frame)."""
        return [entry.name for entry in self._run_order() if phase is None or entry.phase == phase]

    def last_run_tick(self, name: str) -> int:
        """The tick at which the named system last ran (0 if never).

        Raises:
            KeyError: no system of that name.
        """
        for entry in self._run_order():
            if entry.name == name:
                return entry.last_run
        raise KeyError(f"no system named {name!r} in this schedule")

    def run(self, world: World) -> None:
        """Run one frame: every system once, phase by phase, advancing the tick after each.

        ``world.last_run_tick`` is restored afterwards, also when a system raises (the failing
        system's run tick is then not recorded, so it sees the same changes on its next run).

        Raises:
            ValueError: this schedule already ran on a different world (run ticks are per world).
        """
        if self._world is None:
            self._world = world
        elif self._world is not world:
            raise ValueError("this schedule already runs another world; make one per world")
        saved = world.last_run_tick
        order = self._order if self._order is not None else self._run_order()
        # Hot loop (every frame of every node): the tick is read and advanced in place rather
        # than through ``World.tick``/``World.advance`` (the same package; same effect).
        try:
            for entry in order:
                world.last_run_tick = entry.last_run
                entry.system(world)
                entry.last_run = world._tick  # a system may have advanced it itself
                world._tick += 1
        except BaseException:
            world._tick += 1  # the failing system's run still owns a tick; its run tick is kept
            raise
        finally:
            world.last_run_tick = saved

    def _run_order(self) -> list[_Entry]:
        order = self._order
        if order is None:
            order = self._order = [e for phase in Phase for e in self._entries[phase]]
        return order
