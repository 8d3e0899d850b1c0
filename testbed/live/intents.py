"""The operator-side hooks a person drives live: arming and modes, coder settings, the gap.

Each is a small object the live session (:mod:`testbed.live.session`) calls from the
simulation's thread only:

* :class:`LiveRequests` — an UPDATE system of the operator station that writes the arm/disarm
  and mode requests the pilot clicked (fresh :class:`~testbed.common.components.ArmRequest`
  sequence numbers, so a request after a failsafe disarm asks again) and go-to points (a
  :class:`~testbed.common.components.PositionSetpoint` with GUIDED requested: the teleop codec
  sends one ``GoTo`` order, the vehicle flies it); the link codec turns them into orders, as
  for a scripted session;
* :class:`LiveImageConsole` — the operator's :class:`~testbed.operator.video.ImageConsole` that
  also takes coder settings pushed at any time (an ROI drag), sent as the next gap's
  ``ImageSettings`` order and repeated until acknowledged, exactly as scheduled ones;
* :class:`LiveIpg` — the token master's inter-packet-gap policy, replaceable while running.
"""

from __future__ import annotations

from testbed.channel import IpgPolicy
from testbed.channel.mac import Fixed
from testbed.common.components import ArmRequest, ControlMode, ModeRequest, PositionSetpoint
from testbed.ecs import Entity, World
from testbed.operator.video import ImageConsole
from testbed.protocol import ImageSettings

__all__ = ["MODES", "LiveImageConsole", "LiveIpg", "LiveRequests"]

MODES = {
    "manual": ControlMode.MANUAL,
    "stabilize": ControlMode.STABILIZE,
    "depth_hold": ControlMode.DEPTH_HOLD,
}
"""Browser mode names → control modes."""

_FIRST_ARM_SEQ = 100
"""Live arm requests number from here (the session plan's own request is 1)."""


class LiveRequests:
    """UPDATE system: the pilot's arm and mode requests, written once each when made.

    Args:
        entity: the operator's intent entity (:attr:`OperatorStation.entity`).

    Attributes:
        asked: the mode last asked for here (a mode request, or GUIDED by a go-to), from the
            moment it was asked, before the operator frame that sends it; None before any.
    """

    def __init__(self, entity: Entity) -> None:
        self._entity = entity
        self._arm: bool | None = None
        self._mode: ControlMode | None = None
        self._goto: tuple[float, float, float] | None = None
        self._seq = _FIRST_ARM_SEQ
        self.asked: ControlMode | None = None

    def arm(self, armed: bool) -> None:
        """Ask to arm (True) or disarm (False) at the next operator frame."""
        self._arm = armed

    def mode(self, mode: ControlMode) -> None:
        """Ask for ``mode`` at the next operator frame."""
        self._mode = self.asked = mode

    def goto(self, position_ned_m: tuple[float, float, float]) -> None:
        """Ask the vehicle to fly to ``position_ned_m`` [m, NED; z = depth] in GUIDED (keeping
        its heading) at the next operator frame; another mode request ends it."""
        self._goto = position_ned_m
        self._mode, self.asked = None, ControlMode.GUIDED

    def __call__(self, world: World) -> None:
        if self._goto is not None:
            world.set(self._entity, PositionSetpoint(self._goto))
            world.set(self._entity, ModeRequest(ControlMode.GUIDED))
            self._goto = None
        if self._mode is not None:
            world.set(self._entity, ModeRequest(self._mode))
            self._mode = None
        if self._arm is not None:
            self._seq += 1
            world.set(self._entity, ArmRequest(self._arm, self._seq))
            self._arm = None


class LiveImageConsole(ImageConsole):
    """An image console that also sends settings pushed live (:meth:`push`).

    A pushed setting replaces any pending one (the newest wins) and goes out as the next
    ``ImageSettings`` order, resent until a reply acknowledges it.

    Attributes:
        pushed: settings pushed so far.
    """

    def __init__(
        self,
        *,
        chunk_bytes: int = 40,
        selective_repeat: bool = True,
        schedule: list[tuple[float, ImageSettings]] | None = None,
        max_pixels: int,
    ) -> None:
        super().__init__(
            chunk_bytes=chunk_bytes,
            selective_repeat=selective_repeat,
            schedule=schedule or [],
            max_pixels=max_pixels,
        )
        self._pushed: ImageSettings | None = None
        self.pushed = 0

    def push(self, settings: ImageSettings) -> None:
        """Send ``settings`` as soon as possible."""
        self._pushed = settings
        self.pushed += 1

    def settings_due(self, now_s: float) -> ImageSettings | None:
        """The scheduled settings due, unless settings were pushed since (those win)."""
        due = super().settings_due(now_s)
        if self._pushed is None:
            return due
        self._pending, self._pushed = self._pushed, None
        self._sent_with_bit = None
        return self._pending


class LiveIpg:
    """Inter-packet gap policy the pilot can override: a fixed gap [s] or the scenario's.

    Args:
        base: the scenario's policy.
    """

    def __init__(self, base: IpgPolicy) -> None:
        self.base = base
        self.policy: IpgPolicy = base

    def set_gap(self, gap_s: float | None) -> None:
        """A fixed gap of ``gap_s`` [s] from the next slot on, or None for the scenario's."""
        self.policy = self.base if gap_s is None else Fixed(gap_s)

    def gap_after(self, size_bytes: int) -> float:
        """The gap [s] after a slot whose largest frame was ``size_bytes`` [B]."""
        return self.policy.gap_after(size_bytes)
