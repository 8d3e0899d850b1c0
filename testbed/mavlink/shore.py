"""The narrow-link gateway's shore side: the same MAVLink endpoint, piloting the operator's world.

:class:`ShoreEndpoint` is a :class:`~testbed.mavlink.VehicleEndpoint` given the operator
station's world: the intents it writes (``MovementCommand``, ``ArmRequest``, ``ModeRequest``,
``DepthSetpoint``, ``PositionSetpoint``) are the station's, which the node's link codec turns
into orders at the token rate (a GUIDED target as one ``GoTo``); the state it reports is the
copy the codec mirrored from the vehicle's replies (``Odometry``, ``Armed``, ``ActiveMode``,
origin REMOTE). Every MAVLink behaviour (parameters, modes, arming, sticks, failsafes, stream
rates, GUIDED's position target, the hold where GUIDED is entered) is the base class's;
parameters and mission requests are answered from the local table, so a ground station's
connection never waits on the link. When SET_ATTITUDE_TARGET lets go of GUIDED's position
target, no teleop order removes the vehicle's, so the shore writes a ``GoalCancel`` (the order
header's "cancel last order" bit), on which the vehicle drops it
(:meth:`ShoreEndpoint.release_position`).

What it adds is honesty about the link (:class:`LinkFacts`):

- telemetry carries the **state's** time: ``time_boot_ms`` of ATTITUDE, GLOBAL_POSITION_INT,
  VFR_HUD's source… is the estimated sample time of the last state received (its arrival less
  the reply's transit, ``arrival_correction_s``), SYSTEM_TIME the gateway's clock, so a ground
  station sees stale state as stale;
- NAMED_VALUE_FLOAT ``LinkAge`` = the state's age [s], :data:`LINK_AGE_RATE_HZ` on every link;
- STATUSTEXT: once per link on first contact, the link's name, bitrate and state period; a
  warning when the state is older than ``stale_after_s`` (repeated every
  :data:`STALE_REPEAT_S`), and a notice when it is fresh again;
- what the link's codec cannot carry is said, once a session, not dropped silently: over the
  teleop codec (:attr:`LinkFacts.carries_setpoints` False) a depth target more than
  :data:`DEPTH_KEPT_M` from the reported depth (SET_ATTITUDE_TARGET's thrust, integrated into
  a depth target; SET_POSITION_TARGET_GLOBAL_INT's depth in ALT_HOLD; FS_GCS_ENABLE 4's
  surface) and a roll or pitch target beyond :data:`LEVEL_DEG` stay on shore: the teleop
  orders (the paper's layouts) have no depth order and no roll or pitch (a ``KeepHeading``
  carries the heading only), a ``Move``'s heave stick is a rate the vehicle does not fly in
  GUIDED, and a ``GoTo`` carrying the depth would also pin the horizontal position and, re-sent
  as the depth moves, take every order slot. Nor does a yaw rate (a ``GoTo`` carries the
  heading it leads to, :mod:`~testbed.mavlink.guided_yaw`). STATUSTEXT "Depth targets do not
  cross the link", "Roll, pitch targets do not cross the link" or "Yaw rates do not cross the
  link"; ``metrics.json`` ``setpoints_not_sent``.

Before the first state arrives the vehicle reads disarmed, MANUAL, at the origin, with the
state time 0 (age = the gateway's uptime).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.common.components import (
    AttitudeSetpoint,
    DepthSetpoint,
    GoalCancel,
    Odometry,
    PositionSetpoint,
)
from testbed.common.geometry import euler_from_quat
from testbed.ecs import Entity, Origin, World
from testbed.mavlink.channel import Channel
from testbed.mavlink.endpoint import VehicleEndpoint
from testbed.mavlink.options import EndpointOptions
from testbed.mavlink.outbound import STATUSTEXT_LIMIT

__all__ = [
    "DEPTH_KEPT_M",
    "LEVEL_DEG",
    "LINK_AGE_RATE_HZ",
    "STALE_REPEAT_S",
    "LinkFacts",
    "ShoreEndpoint",
]

LINK_AGE_RATE_HZ = 2.0
"""NAMED_VALUE_FLOAT ``LinkAge`` rate [Hz]."""
STALE_REPEAT_S = 10.0
"""A stale-state warning is repeated this often while the state stays stale [s]."""
DEPTH_KEPT_M = 0.05
"""A depth target this close to the reported depth [m] asks for nothing the vehicle's own hold
does not do: over the teleop codec only one further away is said not to cross."""
LEVEL_DEG = 0.5
"""A roll or pitch target within this of level [deg] is the level attitude the vehicle holds."""


@dataclass(frozen=True, slots=True)
class LinkFacts:
    """What the gateway knows of the narrow link behind it (from the scenario's link model).

    Attributes:
        name: the link's name (channel preset, or the HIL modem).
        bitrate_bps: its bitrate [bit/s].
        state_period_s: expected time between state updates [s] (the token gap, or the
            vehicle's send period).
        arrival_correction_s: subtracted from the mirrored state's stamp to get its sample
            time [s]: the reply's transit (intrinsic delay + airtime) on a codec that stamps the
            state with its arrival (teleop), 0 on one that carries the sample time (change-set).
        stale_after_s: state older than this [s] is reported stale (STATUSTEXT warning).
        position_fix: the vehicle has a position fix (its scenario's sensors): GUIDED is
            accepted on shore, once a state has arrived, and its target sent as a ``GoTo`` (the
            teleop codec's state carries no sign of a fix, so the gateway knows it from the
            vehicle's configuration).
        carries_setpoints: the link's codec carries every intent the endpoint writes (the
            change-set codec replicates them all); False for the teleop codec, whose orders
            carry sticks, arm and mode flags, a heading (``KeepHeading``) and a go-to, but no
            depth target and no roll or pitch (module docstring).
    """

    name: str
    bitrate_bps: float
    state_period_s: float
    arrival_correction_s: float
    stale_after_s: float
    position_fix: bool = False
    carries_setpoints: bool = False

    @property
    def banner(self) -> str:
        """The first-contact STATUSTEXT (≤ 50 characters)."""
        rate = (
            f"{self.bitrate_bps / 1000:.3g} kbit/s"
            if self.bitrate_bps < 1e6
            else f"{self.bitrate_bps / 1e6:.3g} Mbit/s"
        )
        return f"Gateway {self.name} {rate}, state/{self.state_period_s:.2g}s"[:50]


class ShoreEndpoint(VehicleEndpoint):
    """The vehicle's MAVLink face on shore (module docstring).

    Args:
        world: the operator station's world.
        intents: the station's intents entity.
        link: what the gateway knows of the link.
        options: presentation options (``origin`` LOCAL: the station owns its intents).

    Attributes:
        link: the link facts.
        stale_warnings: stale-state STATUSTEXT warnings sent.
        setpoints_not_sent: the kinds of target ("depth", "roll_pitch", "yaw_rate") the ground
            station asked for that the link's codec cannot carry (module docstring).
        state_age_s: the reported state's age at the last :meth:`update` [s] (inf before any
            state arrived; ``LinkAge`` then reports the uptime).
    """

    def __init__(
        self, world: World, intents: Entity, link: LinkFacts, options: EndpointOptions
    ) -> None:
        super().__init__(world, intents, intents, options)
        self.link = link
        self.stale_warnings = 0
        self.setpoints_not_sent: set[str] = set()
        self.state_age_s = math.inf
        self._announced: set[int] = set()
        self._stale = False
        self._next_stale_warning_s = 0.0
        self._next_age_s = 0.0
        self._has_state = False
        self._cancels = 0

    def state_source(self, now_s: float) -> tuple[Entity, float]:
        """The mirrored vehicle entity and the estimated sample time of its state [s]."""
        del now_s
        for entity, odometry in self.world.query1(Odometry, origin=Origin.REMOTE):
            self._has_state = True
            return entity, odometry.sampled_s - self.link.arrival_correction_s
        return self.intents, 0.0  # nothing mirrored yet: no vehicle components on it

    def write(self, component: object) -> None:
        """The base class's write (an intent on the station's world, for the codec); a depth
        or a roll and pitch target the codec cannot carry is said once and noted (module
        docstring)."""
        super().write(component)
        if self.link.carries_setpoints:
            return
        if isinstance(component, DepthSetpoint):
            if abs(component.depth_m - self.snapshot_now().depth_m) > DEPTH_KEPT_M:
                self.setpoint_not_sent("depth", "Depth targets do not cross the link")
        elif isinstance(component, AttitudeSetpoint):
            roll, pitch, _ = euler_from_quat(component.quaternion_wxyz)
            if max(abs(roll), abs(pitch)) > math.radians(LEVEL_DEG):
                self.setpoint_not_sent("roll_pitch", "Roll, pitch targets do not cross the link")

    def setpoint_not_sent(self, kind: str, text: str) -> None:
        """Said once (the base class's), and ``kind`` noted in :attr:`setpoints_not_sent`."""
        self.setpoints_not_sent.add(kind)
        super().setpoint_not_sent(kind, text)

    def release_position(self) -> None:
        """The base class's (the station's position target removed), and over the teleop codec a
        :class:`~testbed.common.components.GoalCancel`: no order removes a target, so the order
        header's "cancel last order" bit tells the vehicle to let go of the ``GoTo`` it flies
        (the change-set codec replicates the removal itself)."""
        had_target = self.world.has(self.intents, PositionSetpoint)
        super().release_position()
        if had_target and not self.link.carries_setpoints:
            self._cancels += 1
            self.write(GoalCancel(self._cancels))

    @property
    def can_test_motors(self) -> bool:
        """False: the thrusters are across the narrow link, which carries no motor test."""
        return False

    @property
    def flies_moving_targets(self) -> bool:
        """False: a moving target would be a new ``GoTo`` in every token gap, leaving none for
        a ``Move``, the only order that carries a disarm or a mode change."""
        return False

    def has_position_estimate(self) -> bool:
        """Whether the vehicle behind the link has a fix (:attr:`LinkFacts.position_fix`) and
        the last update saw its state: before the first state arrives there is no position
        (GUIDED, entered, would hold the origin)."""
        return self.link.position_fix and self._has_state

    def queue_due(self, now_s: float) -> None:
        """The base class's, then the link's age and warnings (module docstring)."""
        super().queue_due(now_s)
        snapshot = self._snapshot
        state_s = 0.0 if snapshot is None else snapshot.time_s
        age = max(0.0, now_s - state_s)
        self.state_age_s = age if self._has_state else math.inf
        for channel in self.channels:
            if id(channel) not in self._announced and channel.wire.bytes_in > 0:
                self._announced.add(id(channel))
                self._text(channel, mav.MAV_SEVERITY_INFO, self.link.banner)
        if now_s >= self._next_age_s:
            self._next_age_s = max(self._next_age_s + 1.0 / LINK_AGE_RATE_HZ, now_s)
            name = b"LinkAge"
            link_age = mav.MAVLink_named_value_float_message(
                int(now_s * 1000) & 0xFFFFFFFF, name, age
            )
            for channel in self.channels:
                if not channel.high_latency:  # a high-latency link sends HIGH_LATENCY2 alone
                    self.queue(channel, link_age)
        stale = age > self.link.stale_after_s
        if stale and now_s >= self._next_stale_warning_s:
            self._next_stale_warning_s = now_s + STALE_REPEAT_S
            self.stale_warnings += 1
            self.statustext(mav.MAV_SEVERITY_WARNING, f"Link: vehicle state {age:.1f} s old")
        elif not stale and self._stale:
            self._next_stale_warning_s = 0.0
            self.statustext(mav.MAV_SEVERITY_NOTICE, f"Link: vehicle state fresh ({age:.1f} s)")
        self._stale = stale

    def _text(self, channel: Channel, severity: int, text: str) -> None:
        encoded = text.encode()[:STATUSTEXT_LIMIT]
        self.queue(channel, mav.MAVLink_statustext_message(severity, encoded, 0, 0))

    def counters(self) -> dict[str, object]:
        """The base counters, plus ``stale_warnings`` and ``link`` (the facts)."""
        out = super().counters()
        out["stale_warnings"] = self.stale_warnings
        out["setpoints_not_sent"] = sorted(self.setpoints_not_sent)
        link = self.link
        out["link"] = {
            "name": link.name,
            "bitrate_bps": link.bitrate_bps,
            "state_period_s": link.state_period_s,
            "arrival_correction_s": link.arrival_correction_s,
            "stale_after_s": link.stale_after_s,
            "position_fix": link.position_fix,
            "carries_setpoints": link.carries_setpoints,
        }
        return out
