"""Resources: the singletons a world holds, one per type (a physics handle, an allocator, an RNG).

:class:`Resources` is the resource half of :class:`~testbed.ecs.world.World` (its base class):
a value is stored under its own type and read back by that type. Resources carry no change ticks
and do not replicate. No entities or components here; the standard library only.
"""

from __future__ import annotations

from typing import Any, TypeVar

__all__ = ["Resources"]

C = TypeVar("C")


class Resources:
    """Singletons keyed by their type; the base class of :class:`~testbed.ecs.world.World`."""

    __slots__ = ("_resources",)

    def __init__(self) -> None:
        self._resources: dict[type[Any], object] = {}

    def insert_resource(self, resource: object) -> None:
        """Store ``resource`` under its type, replacing any previous one of that type."""
        self._resources[type(resource)] = resource

    def resource(self, cls: type[C]) -> C:
        """The resource of type ``cls``.

        Raises:
            KeyError: no resource of that type was inserted.
        """
        try:
            return self._resources[cls]  # type: ignore[return-value]  # keyed by its type
        except KeyError:
            raise KeyError(
                f"no resource of type {cls.__qualname__} in this world; "
                f"insert it with world.insert_resource(...)"
            ) from None

    def has_resource(self, cls: type[Any]) -> bool:
        """Whether a resource of type ``cls`` was inserted."""
        return cls in self._resources

    def remove_resource(self, cls: type[Any]) -> bool:
        """Remove the resource of type ``cls``; return whether there was one."""
        return self._resources.pop(cls, None) is not None
