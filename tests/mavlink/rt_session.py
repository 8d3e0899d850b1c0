"""A real-time ground station for the gateway tests: pymavlink's ``mavutil`` on 127.0.0.1, the
run (:func:`~testbed.run.mavlink_gateway.run_gateway`) on a background thread behind a UDP link
(SITL's ``udpout``). Records when each stick packet was sent, so bounds can use the real
interval between them."""

from __future__ import annotations

import itertools
import threading
import time
from collections.abc import Callable
from typing import Any

from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.mavlink.links import UdpLink
from testbed.run.runner import RunResult

WAIT_S = 15.0  # only a broken endpoint or gateway waits this long


class GatewaySession:
    """The run on a thread (``run(links, stop)`` → RunResult: the vehicle's endpoint or the
    shore gateway); the ground station here."""

    def __init__(
        self, run: Callable[[list[Any], threading.Event], RunResult], wait_s: float = WAIT_S
    ) -> None:
        self.wait_s = wait_s  # how long :meth:`until` pumps before it gives up [s]
        self.gcs = mavutil.mavlink_connection(
            "udpin:127.0.0.1:0", source_system=255, source_component=190, dialect="ardupilotmega"
        )
        port = self.gcs.port.getsockname()[1]
        self.link = UdpLink(f"udpout:127.0.0.1:{port}", "127.0.0.1", port, listen=False)
        self.stop = threading.Event()
        self.result: RunResult | None = None
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, args=(run,), daemon=True)
        self.thread.start()
        self._last_heartbeat = 0.0
        self.sticks = (0, 0, 500, 0)
        self.stick_sent_s: list[float] = []
        self.latest: dict[str, Any] = {}
        self.seen: dict[str, list[tuple[float, Any]]] = {}

    def _run(self, run: Callable[[list[Any], threading.Event], RunResult]) -> None:
        try:
            self.result = run([self.link], self.stop)
        except BaseException as err:  # surfaced by finish()
            self.error = err

    def finish(self) -> RunResult:
        self.stop.set()
        self.thread.join(timeout=60.0)
        self.gcs.close()
        if self.error is not None:
            raise self.error
        assert self.result is not None
        return self.result

    def close(self) -> None:
        if self.thread.is_alive():
            self.stop.set()
            self.thread.join(timeout=60.0)

    def pump(self, seconds: float, *, heartbeats: bool = True, sticks: bool = True) -> None:
        """Be a ground station for ``seconds``: 25 Hz sticks, 1 Hz heartbeat (each unless
        switched off: a lost ground station, lost pilot input), read all."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.tick(heartbeats=heartbeats, sticks=sticks)
            self.wait(0.04)

    def tick(self, *, heartbeats: bool = True, sticks: bool = True) -> None:
        now = time.monotonic()
        if heartbeats and now - self._last_heartbeat >= 1.0:
            self.gcs.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 4)
            self._last_heartbeat = now
        if sticks and (not self.stick_sent_s or now - self.stick_sent_s[-1] >= 0.039):
            x, y, z, r = self.sticks
            self.gcs.mav.manual_control_send(1, x, y, z, r, 0)
            self.stick_sent_s.append(now)
        while (msg := self.gcs.recv_match(blocking=False)) is not None:
            self._keep(msg)

    def _keep(self, msg: Any) -> None:
        kind = msg.get_type()
        self.latest[kind] = msg
        self.seen.setdefault(kind, []).append((time.monotonic(), msg))

    def wait(self, seconds: float) -> None:
        msg = self.gcs.recv_match(blocking=True, timeout=seconds)
        if msg is not None:
            self._keep(msg)

    def until(self, what: Callable[[], Any], **pump: bool) -> Any:
        """Pump (:meth:`tick`'s switches) until ``what()`` is truthy; its value."""
        end = time.monotonic() + self.wait_s
        while time.monotonic() < end:
            self.tick(**pump)
            value = what()
            if value:
                return value
            self.wait(0.02)
        raise AssertionError(f"timed out waiting for the run's endpoint; {self.describe()}")

    def describe(self) -> str:
        """What the ground station last saw (for a failure's message: a loaded host that holds
        the orders back shows as failsafe texts and a vehicle that stopped short)."""
        hb = self.latest.get("HEARTBEAT")
        position = self.latest.get("LOCAL_POSITION_NED")
        texts = [m.text for _, m in self.seen.get("STATUSTEXT", [])][-5:]
        sent = self.stick_sent_s
        return (
            f"heartbeat base_mode {None if hb is None else hb.base_mode}, custom_mode "
            f"{None if hb is None else hb.custom_mode}; position "
            f"{None if position is None else (position.x, position.y, position.z)}; last texts "
            f"{texts}; sticks {self.sticks}, {len(sent)} sent, longest gap "
            f"{self.max_stick_gap_s() if len(sent) > 1 else None} s"
        )

    def heartbeat(self, check: Callable[[Any], bool], **pump: bool) -> Any:
        self.latest.pop("HEARTBEAT", None)

        def found() -> Any:
            hb = self.latest.get("HEARTBEAT")
            return hb if hb is not None and check(hb) else None

        return self.until(found, **pump)

    def ack(self, command: int) -> int:
        def found() -> Any:
            msg = self.latest.pop("COMMAND_ACK", None)
            return msg if msg is not None and msg.command == command else None

        return int(self.until(found).result)

    def max_stick_gap_s(self) -> float:
        sent = self.stick_sent_s
        return max(b - a for a, b in itertools.pairwise(sent))
