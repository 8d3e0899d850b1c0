"""A live session: the run's nodes in real time over the simulated link, a person piloting.

:func:`run_live` builds what :func:`~testbed.run.runner.run_scenario` builds — one medium with
both modems, the vehicle node (control, camera, pybullet physics) and the operator node — but
under ``simpy.rt.RealtimeEnvironment(strict=False)``, with a
:class:`~testbed.operator.live_pilot.LivePilot` as the operator station's pilot and three more
simpy processes:

* the poll (every ``poll_s``, 1 ms): drains the pilot's stick queue and the :class:`Hub`'s
  control messages and applies them (arm, mode, image settings, link changes, go-to), records
  how late it runs (scheduler lateness, as :func:`~testbed.run.hil_modem.run_poll`);
* the publisher (``publish_hz``, fixed rate): builds the console's state (operator's view,
  truth, link) as a finished dict and hands it to the hub;
* the run itself, until ``duration_s`` or Ctrl-C (a ``KeyboardInterrupt`` in this thread).

Nothing here runs on the server's thread and nothing on the server's thread calls simpy.

Live link controls (simulated link only), each recorded as a ``live`` event: bit error rate
(:meth:`~testbed.channel.Medium.set_ber`), a fixed inter-packet gap instead of the scenario's
policy (:class:`~testbed.live.intents.LiveIpg`), an outage from now
(:meth:`~testbed.channel.Medium.add_outage`), and the operator–vehicle distance (the operator's
modem is placed that far north of the vehicle; propagation delay and distance-dependent errors
follow from the medium's model). Image coder settings: the scenario's initial ones, then the
pilot's (its scheduled ``images.changes`` are not sent: a person is flying). A go-to point
(supervised control) becomes a ``PositionSetpoint`` with GUIDED requested at the depth the
operator knows: one ``GoTo`` order, flown by the vehicle's guidance (refused by a vehicle
without a position fix); any mode request ends it.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Generator, Mapping
from functools import partial
from typing import Any, cast

import numpy as np
import simpy
import simpy.rt

from testbed.channel import IpgPolicy, Medium, Trace
from testbed.ecs import Phase
from testbed.hil import LinkEndpoint
from testbed.live.console_state import console_state
from testbed.live.hub import Hub
from testbed.live.intents import MODES, LiveImageConsole, LiveIpg, LiveRequests
from testbed.live.messages import (
    Arm,
    GoToPoint,
    ImageRequest,
    LinkChange,
    Message,
    Outage,
    SetMode,
)
from testbed.live.monitor import LinkMonitor, latency_ms
from testbed.operator.live_pilot import LivePilot
from testbed.operator.station import OperatorStation, SessionPlan
from testbed.protocol import ImageSettings
from testbed.run.failures import reduce_run, run_error
from testbed.run.hil_metrics import hil_metrics
from testbed.run.hil_modem import POLL_S, FrameLedger, HilModem, poll_modems
from testbed.run.images import image_source_factory, settings_schedule
from testbed.run.interrupts import deferred_interrupts, interrupt_of
from testbed.run.link_log import LinkStateLog
from testbed.run.nodes import LinkModem, OperatorNode, VehicleNode
from testbed.run.observer import VehicleObserver
from testbed.run.plugin_calls import scenario_control_laws, scenario_link_model
from testbed.run.recorder import Recorder
from testbed.run.run_metrics import compute_metrics
from testbed.run.runner import RunResult, note_copies_lost_transmitting, tally_images
from testbed.run.scenario_config import Scenario
from testbed.run.wall_clock import SAMPLES_KEPT, rt_lateness_ns
from testbed.vehicle.resources import Controllers
from testbed.vehicle.vehicle import Vehicle

__all__ = ["GOTO_REFUSED", "PUBLISH_HZ", "LiveSession", "run_live"]

PUBLISH_HZ = 10.0
"""Rate of the console's state [Hz]."""
GOTO_REFUSED = "go-to refused: no vehicle state received yet (the depth to hold is unknown)"
GOTO_NO_FIX = (
    "go-to refused: this vehicle knows no position (no vehicle.sensors.position fix, no "
    "navigation), so it cannot fly to a point; run a scenario with one (e.g. s100-video-v1)"
)
SIMULATED_ONLY = "link controls act on the simulated link only (this session runs on HIL ports)"

_STICK_TOLERANCE = 0.01
"""Applied sticks this close to the pilot's count as his (the teleop codec's step is 1/127)."""


class LiveSession:
    """The nodes, the link and the live hooks of one session (see the module docstring).

    Args:
        scenario: the loaded scenario (token-passing teleop link; images optional).
        hub: the bridge to the server.
        seed: overrides the scenario's seed.
        pilot: the live pilot (a new one if None).
        endpoints: ``{"operator": …, "vehicle": …}``: run the link over these serial ports
            (hardware in the loop, :mod:`testbed.run.hil_modem`'s modems) instead of the
            simulated medium; the live link controls are then refused. Closed at the end.
        modem: the modem kind on the ports, for the record.
    """

    def __init__(
        self,
        scenario: Scenario,
        hub: Hub,
        *,
        seed: int | None = None,
        pilot: LivePilot | None,
        endpoints: Mapping[str, LinkEndpoint] | None = None,
        modem: str = "",
    ) -> None:
        self.scenario = scenario
        self.hub = hub
        self.seed = scenario.seed if seed is None else seed
        self.pilot = pilot or LivePilot()
        link_seed, vehicle_seed = np.random.SeedSequence(self.seed).spawn(2)
        self.env = simpy.rt.RealtimeEnvironment(factor=1.0, strict=False)
        env = self.env
        self.recorder = Recorder(trace=Trace())
        link = scenario.link
        self.medium: Medium | None = None
        self.ledger = FrameLedger()
        self.hil_modems: dict[str, HilModem] = {}
        self.endpoints = dict(endpoints or {})
        self.modem_kind = modem
        if endpoints is None:
            rng = np.random.default_rng(link_seed)
            model = scenario_link_model(scenario, self.seed)
            self.recorder.link_state = LinkStateLog.of(model)
            self.medium = Medium(env, link.channel, rng, self.recorder.trace, model=model)
        else:
            for role, peer in (("vehicle", "operator"), ("operator", "vehicle")):
                self.hil_modems[role] = HilModem(
                    env, role, peer, endpoints[role], trace=self.recorder.trace, ledger=self.ledger
                )
        self.distance_m: float | None = None  # operator–vehicle distance set live [m]
        self.vehicle_node = self._vehicle_node(np.random.default_rng(vehicle_seed))
        self.vehicle: Vehicle = self.vehicle_node.vehicle
        self.ipg = LiveIpg(link.ipg_policy) if link.mac == "token" else None
        self.operator_node = self._operator_node()
        self.station = self.operator_node.station
        self.requests = LiveRequests(self.station.entity)
        self.station.add_system(Phase.UPDATE, self.requests)
        self.monitor = LinkMonitor(self.recorder.trace)
        self.lateness_ns: deque[int] = deque(maxlen=SAMPLES_KEPT)
        self.link_changes: list[dict[str, Any]] = []
        self._coder: ImageSettings | None = None
        self._held = self.pilot.sticks
        self._change: tuple[float, tuple[float, ...]] | None = None
        self.stick_lags_s: list[float] = []
        """Per stick change the pilot made: taken in → first applied at the vehicle [s]."""

    # ------------------------------------------------------------------------------ building

    def _vehicle_node(self, rng: np.random.Generator) -> VehicleNode:
        scenario, env, recorder = self.scenario, self.env, self.recorder
        depth_law, attitude_law = scenario_control_laws(scenario, self.seed)  # before the vehicle
        modem = self._modem("vehicle", lambda: self.vehicle.truth.position_ned_m)
        images = scenario.images
        node = VehicleNode(
            env,
            partial(Vehicle, scenario.vehicle, rng),
            modem,
            codec=scenario.link.codec,
            token=scenario.link.mac == "token",
            downlink_rate_hz=scenario.link.downlink_rate_hz,
            recorder=recorder,
            snapshot_period_s=scenario.link.snapshot_period_s,
            image_source=image_source_factory(images) if images.enabled else None,
        )
        vehicle = node.vehicle
        vehicle.controllers.depth_law, vehicle.controllers.attitude_law = depth_law, attitude_law
        observer = VehicleObserver(
            recorder, self.pilot, vehicle.reference_velocity, scenario.metrics.sample_rate_hz
        )
        vehicle.schedule.add(Phase.POST_UPDATE, observer, name="record_vehicle")
        return node

    def _modem(self, role: str, position: Any) -> LinkModem:
        if self.medium is None:
            return self.hil_modems[role]
        return self.medium.attach(role, position)

    def _operator_position(self) -> tuple[float, float, float]:
        if self.distance_m is None:
            return self.scenario.link.operator_position_ned_m
        x, y, z = self.vehicle.truth.position_ned_m
        return (x + self.distance_m, y, z)

    def _operator_node(self) -> OperatorNode:
        scenario = self.scenario
        link, images, camera = scenario.link, scenario.images, scenario.vehicle.camera
        plan = SessionPlan(
            mode=scenario.operator.control_mode,
            arm_at_s=scenario.operator.arm_at_s,
            depth_m=scenario.operator.depth_m,
            precision=scenario.operator.precision,
        )
        console = None
        if images.enabled:
            console = LiveImageConsole(
                chunk_bytes=images.chunk_bytes,
                selective_repeat=images.selective_repeat,
                schedule=settings_schedule(images)[:1],  # then the pilot's, not the script's
                max_pixels=camera.width_px * camera.height_px,
            )
        self.image_console = console
        return OperatorNode(
            self.env,
            OperatorStation(self.pilot, plan),
            self._modem("operator", self._operator_position),
            codec=link.codec,
            # run_token_master only asks the policy for gap_after(size): LiveIpg has it
            ipg=cast("IpgPolicy | None", self.ipg),
            uplink_rate_hz=link.uplink_rate_hz,
            recorder=self.recorder,
            reply_odometry_s=self.vehicle_node.reply_odometry_s,
            snapshot_period_s=link.snapshot_period_s,
            console=console,
        )

    # ------------------------------------------------------------------------------ running

    def run(
        self, duration_s: float, poll_s: float = POLL_S, publish_hz: float = PUBLISH_HZ
    ) -> RunResult:
        """Run until ``duration_s`` [s] or Ctrl-C; the result has ``stopped`` set if
        interrupted (its metrics then cover the time reached).

        Raises:
            Exception: an error that ended the session part way (a control law of the user's
                raising), carrying what ran (:func:`~testbed.run.failures.partial_run`).
        """
        env = self.env
        env.process(self.vehicle_node.run())
        env.process(self.operator_node.run())
        env.process(self._poll(poll_s))
        env.process(self._publisher(1.0 / publish_hz))
        stopped: KeyboardInterrupt | None = None
        failed: Exception | None = None
        env.sync()  # the clock starts now, after the physics has loaded
        start = time.perf_counter()
        try:
            env.run(until=duration_s)
        except BaseException as error:  # Ctrl-C or SIGTERM (also wrapped): keep what ran
            # an error part way (a control law of the user's) keeps what ran too
            if (stopped := interrupt_of(error)) is None and (failed := run_error(error)) is None:
                self.vehicle.close()
                raise
        with deferred_interrupts() as closing:  # a second Ctrl-C: the session is ending anyway
            wall_s = time.perf_counter() - start
            self.vehicle.close()
        stopped = stopped or (closing[0] if closing else None)
        reached = duration_s if stopped is None and failed is None else float(env.now)

        def reduce(failure: str | None) -> RunResult:
            """What ran, reduced; ``failure`` is the error's line when one ended it."""
            if failure is not None:
                self.recorder.event(reached, "testbed", "failed", failure)
            metrics = self.metrics(reached, wall_s)
            return RunResult(self.scenario, self.seed, metrics, self.recorder, stopped, failure)

        return reduce_run(reduce, failed, reached, stopped)  # reduced whole, even on Ctrl-C now

    def _poll(self, period_s: float) -> Generator[simpy.Event, Any, None]:
        env = self.env
        while True:
            self.lateness_ns.append(rt_lateness_ns(self.env))
            poll_modems(self.hil_modems.values())
            self.pilot.drain()
            for kind, detail in self.hub.take_seat_events():  # who flies from now on
                self._event(kind, detail)
            for message, _ in self.hub.take():
                self.apply(message)
            self._watch_coder()
            self._watch_sticks()
            yield env.timeout(period_s)

    def _watch_sticks(self) -> None:
        """End-to-end lag: a change of the pilot's sticks → the vehicle applies them (within
        the teleop codec's 1/127 quantisation); a change superseded before it lands is not
        counted, nor one a vehicle under autonomy takes (it flies its mission, not sticks)."""
        held = self.pilot.sticks
        if held != self._held:
            self._held = held
            self._change = (self.env.now, held)
        if self._change is None:
            return
        controllers = self.vehicle.world.resource(Controllers)
        if controllers.autonomous:
            self._change = None
            return
        since, wanted = self._change
        applied = controllers.sticks
        if all(abs(a - w) <= _STICK_TOLERANCE for a, w in zip(applied, wanted, strict=True)):
            self.stick_lags_s.append(self.env.now - since)
            self._change = None

    def _publisher(self, period_s: float) -> Generator[simpy.Event, Any, None]:
        env = self.env
        while True:
            self.hub.publish(self.state())
            yield env.timeout(period_s)

    def _event(self, kind: str, detail: str) -> None:
        self.recorder.event(self.env.now, "live", kind, detail)
        self.hub.note(f"{self.env.now:.1f} s: {kind} {detail}")

    def apply(self, message: Message) -> None:
        """Act on one control message from the pilot (simulation thread)."""
        now = self.env.now
        if isinstance(message, Arm):
            self.requests.arm(message.armed)
            self._event("arm_request" if message.armed else "disarm_request", "")
        elif isinstance(message, SetMode):
            self.requests.mode(MODES[message.mode])
            self._event("mode_request", message.mode)
        elif isinstance(message, ImageRequest):
            self._image(message)
        elif isinstance(message, Outage | LinkChange) and self.medium is None:
            self._event("link_refused", SIMULATED_ONLY)
        elif isinstance(message, Outage):
            assert self.medium is not None
            self.medium.add_outage(now, now + message.duration_s)
            self._link_change("outage", message.duration_s)
        elif isinstance(message, LinkChange):
            assert self.medium is not None
            if message.key == "ber":
                self.medium.set_ber(message.value or 0.0)
            elif message.key == "gap_s" and self.ipg is not None:
                self.ipg.set_gap(message.value)
            elif message.key == "distance_m":
                self.distance_m = message.value
            self._link_change(message.key, message.value)
        elif isinstance(message, GoToPoint):
            self._go_to(message)

    def _go_to(self, message: GoToPoint) -> None:
        """Supervised control: fly to the clicked point at the depth the operator knows
        (refused, with a note, by a vehicle without a position fix: GUIDED would hold it in
        place with no target, silently)."""
        odometry = self.station.vehicle_odometry()
        vehicle = self.scenario.vehicle
        no_fix = vehicle.sensors.position is None and vehicle.navigation_in_use is None
        if odometry is None or no_fix:
            self._event("goto_refused", f"x={message.x:.2f} y={message.y:.2f} m")
            self.hub.note(GOTO_NO_FIX if no_fix else GOTO_REFUSED)
            return
        depth = odometry.position_ned_m[2]
        self.requests.goto((message.x, message.y, depth))
        self._event("goto_sent", f"x={message.x:.2f} y={message.y:.2f} z={depth:.2f} m")

    def _link_change(self, key: str, value: float | None) -> None:
        self.link_changes.append({"t_s": self.env.now, "key": key, "value": value})
        self._event(f"link_{key}", "scenario" if value is None else f"{value:g}")

    def _image(self, message: ImageRequest) -> None:
        if self.image_console is None:
            self.hub.note("image settings ignored: this scenario has no images")
            return
        x0, y0, x1, y1 = message.roi or (0, 0, 0, 0)
        shift = message.shift if message.roi else 0
        settings = ImageSettings(x0, y0, x1, y1, shift, True, message.budget)
        self.image_console.push(settings)
        self._event("image_settings_sent", _settings_text(settings))

    def _watch_coder(self) -> None:
        """Record when the vehicle's coder takes new settings (they reached it)."""
        images = self.vehicle_node.images
        if images is None or images.settings == self._coder:
            return
        self._coder = images.settings
        self.recorder.event(
            self.env.now, "vehicle", "image_settings", _settings_text(images.settings)
        )

    # ------------------------------------------------------------------------------ state

    def state(self) -> dict[str, Any]:
        """The console's state now (JSON-ready, built fresh; :func:`.console_state`)."""
        return console_state(self)

    def metrics(self, reached_s: float, wall_s: float) -> dict[str, Any]:
        """``metrics.json``: :func:`~testbed.run.run_metrics.compute_metrics`'s keys and
        ``live``."""
        payload = {
            "uplink": self.vehicle_node.port.payload_bytes,
            "downlink": self.operator_node.port.payload_bytes,
        }
        tally_images(self.recorder, self.vehicle_node, self.operator_node)
        if self.hil_modems:
            metrics = hil_metrics(
                self.scenario,
                self.seed,
                self.recorder,
                self.hil_modems,
                self.ledger,
                duration_s=reached_s,
                wall_s=wall_s,
                vehicle_node=self.vehicle_node,
                operator_node=self.operator_node,
                poll_s=POLL_S,
                modem=self.modem_kind,
                lateness_ns=self.lateness_ns,
            )
        else:
            metrics = compute_metrics(
                self.scenario,
                self.seed,
                self.recorder,
                sim_s=reached_s,
                wall_s=wall_s,
                energy_wh=self.vehicle_node.energy_wh,
                payload_bytes=payload,
            )
            note_copies_lost_transmitting(
                metrics, self.vehicle_node.port.modem, self.operator_node.port.modem
            )
        hub = self.hub
        metrics["live"] = {
            "session": "live",
            "inputs": hub.counters.as_dict(),
            "sticks_taken": self.pilot.taken,
            "dead_man_timeouts": self.pilot.timeouts,
            "input_to_intent_ms": latency_ms(self.pilot.latencies_ns),
            "browser_round_trip_ms": latency_ms(v * 1e6 for v in hub.round_trips_ms),
            "state_to_pixels_ms": latency_ms(v * 1e6 for v in hub.pixel_latencies_ms),
            "scheduler_lateness_ms": latency_ms(self.lateness_ns),
            "stick_to_vehicle_ms": latency_ms(v * 1e9 for v in self.stick_lags_s),
            "link_changes": self.link_changes,
            "image_settings_pushed": 0 if self.image_console is None else self.image_console.pushed,
        }
        return metrics


def _settings_text(settings: ImageSettings) -> str:
    return (
        f"roi={settings.x0},{settings.y0},{settings.x1},{settings.y1} "
        f"shift={settings.roi_shift} budget={settings.budget_bytes}"
    )


def run_live(
    scenario: Scenario,
    hub: Hub,
    *,
    seed: int | None = None,
    duration_s: float | None = None,
    pilot: LivePilot | None = None,
) -> RunResult:
    """Run a live session of ``scenario`` (see the module docstring) for ``duration_s`` [s]
    (None: the scenario's) or until Ctrl-C."""
    session = LiveSession(scenario, hub, seed=seed, pilot=pilot)
    return session.run(scenario.duration_s if duration_s is None else duration_s)
