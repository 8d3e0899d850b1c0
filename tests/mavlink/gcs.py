"""A simulated-time harness for the endpoint: a real vehicle behind it, pymavlink in front.

:class:`SimGcs` builds the default scenario's :class:`~testbed.vehicle.vehicle.Vehicle` and a
:class:`~testbed.mavlink.VehicleEndpoint` piloting it, and plays a ground station whose packets
are encoded and decoded by pymavlink's own ``ardupilotmega`` dialect (not the testbed's
wrapper): every step feeds the queued bytes, advances the vehicle one frame period and decodes
what the endpoint queued. :class:`SimGateway` is the same through the s100 gateway's teleop
codec. No sockets, no wall clock.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.common.teleop import TeleopOperatorEnd, TeleopVehicleEnd
from testbed.ecs import Origin
from testbed.mavlink import EndpointOptions, VehicleEndpoint
from testbed.mavlink.shore import ShoreEndpoint
from testbed.protocol import decode_operator_message
from testbed.run.mavlink_gateway import GatewayStation, gateway_link_facts
from testbed.run.mavlink_run import endpoint_options
from testbed.run.scenario import load_scenario
from testbed.vehicle.vehicle import Vehicle

FRAME_S = 0.01


class _Null:
    def write(self, data: bytes) -> None:
        del data


NO_VEHICLE_FAILSAFE = (
    "vehicle.failsafe.hold_after_s=86399",
    "vehicle.failsafe.surface_after_s=86400",
)
"""The vehicle's own stale-command failsafe off, as in a MAVLink run (ArduSub's FS_* rule)."""


class SimGcs:
    """A ground station (sysid ``sysid``) in front of an endpoint on a simulated vehicle (the
    scenario's position fix removed unless ``position_fix``)."""

    def __init__(
        self, sysid: int = 255, overrides: Iterable[str] = (), *, position_fix: bool = True
    ) -> None:
        scenario = load_scenario("s100-teleop-v1", [*NO_VEHICLE_FAILSAFE, *overrides])
        config = scenario.vehicle
        if not position_fix:  # the scenario's position sensor removed
            sensors = dataclasses.replace(config.sensors, position=None)
            config = dataclasses.replace(config, sensors=sensors)
        self.vehicle = Vehicle(config, np.random.default_rng(0))
        vehicle = self.vehicle
        options = endpoint_options(config, vehicle.thruster_config)  # as a MAVLink run's
        self.endpoint = VehicleEndpoint(
            vehicle.world, vehicle.entity, vehicle.operator_entity, options
        )
        self.channel = self.endpoint.open_channel("test")
        self.mav = self.make_sender(sysid)
        self._decoder = mav.MAVLink(None)
        self._decoder.robust_parsing = True
        self.packets: list[bytes] = []
        self.messages: list[Any] = []
        self._pending = bytearray()
        self._target_s = 0.0

    @staticmethod
    def make_sender(sysid: int, compid: int = 190) -> mav.MAVLink:
        return mav.MAVLink(_Null(), srcSystem=sysid, srcComponent=compid)

    def close(self) -> None:
        self.vehicle.close()

    @property
    def now_s(self) -> float:
        return self.vehicle.time_s

    def send(self, *messages: Any, sender: mav.MAVLink | None = None) -> None:
        """Queue messages (pymavlink message objects) for the next step."""
        for message in messages:
            self._pending += message.pack(sender or self.mav)

    def send_bytes(self, data: bytes) -> None:
        self._pending += data

    def step(self) -> None:
        """One frame: deliver the queued bytes, advance, collect the replies."""
        data, self._pending = bytes(self._pending), bytearray()
        if data:
            self.endpoint.receive(self.channel, data, self.now_s)
        self._target_s += FRAME_S  # on the 10-ms grid (the vehicle's frames land near it)
        self.vehicle.advance(self._target_s)
        self.endpoint.update(self.now_s)
        for packet in self.channel.take():
            self.packets.append(packet)
            self.messages.extend(
                m for m in self._decoder.parse_buffer(packet) or [] if m.get_type() != "BAD_DATA"
            )

    def run(self, seconds: float, each: Callable[[int], Iterable[Any]] | None = None) -> None:
        """Step for ``seconds``; ``each(k)`` gives the messages to send at step ``k``."""
        for k in range(round(seconds / FRAME_S)):
            if each is not None:
                self.send(*each(k))
            self.step()

    def of(self, kind: str) -> list[Any]:
        return [m for m in self.messages if m.get_type() == kind]

    def last(self, kind: str) -> Any:
        found = self.of(kind)
        assert found, f"no {kind} received"
        return found[-1]

    def clear(self) -> None:
        self.messages.clear()
        self.packets.clear()

    # the ground station's usual messages

    def heartbeat(self) -> Any:
        return self.mav.heartbeat_encode(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 4)

    def sticks(self, x: int = 0, y: int = 0, z: int = 500, r: int = 0, buttons: int = 0) -> Any:
        return self.mav.manual_control_encode(1, x, y, z, r, buttons)

    def command(self, cmd: int, *params: float) -> Any:
        p = [*params, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0][:7]
        return self.mav.command_long_encode(1, 1, cmd, 0, *p)

    def arm(self, armed: bool = True) -> Any:
        return self.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1.0 if armed else 0.0)

    def set_mode(self, mode: int) -> Any:
        return self.mav.set_mode_encode(1, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode)

    def param_set(self, name: str, value: float) -> Any:
        return self.mav.param_set_encode(1, 1, name.encode(), value, mav.MAV_PARAM_TYPE_REAL32)

    def flying(self, x: int = 0, z: int = 500) -> Callable[[int], list[Any]]:
        """MANUAL_CONTROL at 25 Hz (every 4th frame), a heartbeat at 1 Hz."""

        def each(k: int) -> list[Any]:
            out = [self.sticks(x=x, z=z)] if k % 4 == 0 else []
            return out + ([self.heartbeat()] if k % 100 == 0 else [])

        return each

    def enter_guided(self) -> None:
        """Armed, depth held (ALT_HOLD, 2) for 1 s, then GUIDED (4) for 1 s (a heartbeat a
        second; the scenario's vehicle has a position fix)."""
        self.send(self.heartbeat(), self.arm(), self.set_mode(2))
        self.run(1.0, self.flying())
        self.send(self.set_mode(4))
        self.run(1.01, self.flying())
        assert self.last("HEARTBEAT").custom_mode == 4

    def truth_depth_m(self) -> float:
        return float(self.vehicle.truth.position_ned_m[2])

    def truth_surge_m_s(self) -> float:
        return float(self.vehicle.truth.velocity_m_s[0])


class SimGateway:
    """The gateway path in simulated time: pymavlink → :class:`ShoreEndpoint` on a gateway
    station → the teleop codec's orders, one per token gap, each crossing in ``up_s`` → the
    vehicle's teleop end on a real vehicle; its reply crosses back in ``down_s``."""

    GAP_S = 0.594  # s100's token gap
    UP_S = 0.140  # a 13-B order's crossing
    DOWN_S = 0.170  # a 20-B reply's crossing

    def __init__(self, boot_params: dict[str, float] | None = None) -> None:
        scenario = load_scenario("s100-teleop-v1", list(NO_VEHICLE_FAILSAFE))
        self.vehicle = Vehicle(scenario.vehicle, np.random.default_rng(0))
        self.station = GatewayStation()
        facts = gateway_link_facts(scenario)
        options = EndpointOptions(origin=Origin.LOCAL, param_overrides=dict(boot_params or {}))
        self.endpoint = ShoreEndpoint(self.station.world, self.station.entity, facts, options)
        self.channel = self.endpoint.open_channel("gcs")
        self.shore = TeleopOperatorEnd(self.station.world, self.station.entity)
        v = self.vehicle
        self.far = TeleopVehicleEnd(v.world, v.entity, v.operator_entity)
        self.mav = SimGcs.make_sender(255)
        self._decoder = mav.MAVLink(None)
        self.messages: list[Any] = []
        self.orders: list[object] = []
        self._pending = bytearray()
        self._in_flight: list[tuple[float, str, bytes]] = []
        self._next_order_s = 0.0
        self._t = 0.0
        self._k = 0
        self.yaw_r = 0  # the sticks' yaw (MANUAL_CONTROL r)

    def send(self, *messages: Any) -> None:
        for message in messages:
            self._pending += message.pack(self.mav)

    def run(self, seconds: float) -> None:
        for _ in range(round(seconds / FRAME_S)):
            t = self._t
            if self._k % 4 == 0:  # sticks at 25 Hz, a heartbeat at 1 Hz
                self.send(self.mav.manual_control_encode(1, 0, 0, 500, self.yaw_r, 0))
            if self._k % 100 == 0:
                self.send(self.mav.heartbeat_encode(6, 8, 0, 0, 4))
            self._k += 1
            data, self._pending = bytes(self._pending), bytearray()
            self.endpoint.receive(self.channel, data, t)
            if t >= self._next_order_s:
                self._next_order_s += self.GAP_S
                payload = self.shore.encode_order()
                self.orders.append(decode_operator_message(payload).order)  # type: ignore[union-attr]
                self._in_flight.append((t + self.UP_S, "order", payload))
            for item in [i for i in self._in_flight if i[0] <= t]:
                self._in_flight.remove(item)
                if item[1] == "order":
                    self.far.apply_order(item[2], t)
                    reply = self.far.encode_reply()
                    self._in_flight.append((t + self.DOWN_S, "reply", reply))
                else:
                    self.shore.apply_reply(item[2], t)
            self._t = t + FRAME_S
            self.vehicle.advance(self._t)
            self.endpoint.update(self._t)
            for packet in self.channel.take():
                self.messages.extend(
                    m
                    for m in self._decoder.parse_buffer(packet) or []
                    if m.get_type() != "BAD_DATA"
                )

    def last(self, kind: str) -> Any:
        return [m for m in self.messages if m.get_type() == kind][-1]
