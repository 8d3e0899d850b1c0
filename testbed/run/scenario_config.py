"""A scenario: everything one run needs apart from the seed, as one frozen dataclass.

:class:`Scenario` holds the header (versioned id, schema, duration, seed, trials) and the
sections: the link (a channel preset plus overrides, the codec, the medium access and the
operator's modem position), the vehicle (a :class:`~testbed.vehicle.vehicle_config.VehicleConfig`),
the operator's start-up requests, the pilot, the faults, the metric settings and the images.
Its ``__post_init__`` holds the checks that span sections (times inside ``duration_s``, the
run's size budget, images on a token-passing teleop link with a camera, an attitude pilot's
mode and setpoint rate); each failure is a :class:`~testbed.config.FieldError` naming the dotted
key, which the loader turns into the one-line error naming the file.

The sections' dataclasses and their own checks are in :mod:`testbed.run.sections` (images in
:mod:`testbed.run.images`); reading a scenario from TOML, with ``--set`` overrides, is
:func:`testbed.run.scenario.load_scenario`; the files a scenario names are
:mod:`testbed.run.scenario_files`. Nothing here reads a file.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from testbed.config import check, check_range
from testbed.run.images import ImagesSection
from testbed.run.sections import (
    MAX_DURATION_S,
    ControlLawsSection,
    FaultsSection,
    LinkSection,
    MetricsSection,
    OperatorSection,
    PilotSection,
)
from testbed.vehicle.vehicle_config import VehicleConfig

__all__ = [
    "ID_PATTERN",
    "MAX_PHYSICS_STEPS",
    "MAX_SERIES_ROWS",
    "MAX_TOKEN_SLOTS",
    "MAX_TRIALS",
    "SCHEMA_VERSION",
    "Scenario",
]

SCHEMA_VERSION = 1
"""The only scenario schema version the loader (:mod:`testbed.run.scenario`) reads."""

MAX_PHYSICS_STEPS = 100_000_000
"""Most physics steps a run may take (``duration_s / vehicle.physics_dt_s``): ≈ 1.3 h of wall
time at the ≈ 45 µs a step (with its share of the frames) costs on s100-teleop-v1. The
default step (1/240 s) allows the whole :data:`MAX_DURATION_S`."""
MAX_SERIES_ROWS = 10_000_000
"""Most series rows a run may record (``duration_s × min(metrics.sample_rate_hz,
vehicle.control_rate_hz)``, a row at most once a frame): ≈ 3.1 GB at 39 columns × 8 B."""
MAX_TRIALS = 100
"""Most trials (runs with consecutive seeds) one scenario may ask for."""
MAX_TOKEN_SLOTS = 10_000_000
"""Most token slots a fixed-gap run may hold (``duration_s / link.ipg_s``): the operator sends a
frame every gap whether or not the last one got through, so a gap of 1 ns on a 10-s run is
10¹⁰ frames queued (it ran for days, growing memory). 10⁷ slots is ≈ 10 min of wall time; the
whole :data:`MAX_DURATION_S` allows gaps from 8.64 ms."""

ID_PATTERN = re.compile(r"^[a-z0-9-]+-v[0-9]+$")
"""A versioned id (``s100-teleop-v1``): scenarios' and sweeps' (a sweep's names its default
results folder, so it can hold no path separator or ``..``)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class Scenario:
    """One run's configuration (the seed aside, which the CLI's ``--seed`` may override).

    Attributes:
        id: versioned id, ``^[a-z0-9-]+-v[0-9]+$`` (``s100-teleop-v1``).
        description: one line for listings and reports.
        schema: scenario schema version; only :data:`SCHEMA_VERSION` is accepted.
        duration_s: simulated time [s], in (0, :data:`MAX_DURATION_S`] (one day), with at
            most :data:`MAX_PHYSICS_STEPS` physics steps, :data:`MAX_TOKEN_SLOTS` fixed-gap
            token slots and :data:`MAX_SERIES_ROWS` series rows.
        seed: default seed, ≥ 0.
        trials: how many runs ``testbed run`` makes, with seeds ``seed, seed + 1, …``
            (:mod:`testbed.run.trials`), in [1, :data:`MAX_TRIALS`].
        link, vehicle, operator, pilot, faults, metrics, images: the sections.
        control_laws: ``[vehicle.control]``, the depth and attitude holds of the user's own
            (none: the packaged PIDs); not part of ``vehicle``, which loads no Python file.
        source: where it was loaded from (a path or ``package:<id>``), for messages; not a
            TOML key.
        overrides: the ``--set`` overrides applied on top of ``source``, in order.
        files: SHA-256 (hex) of each user file the run reads, by path: the scenario file and
            a link preset, model, thruster layout or mission given by path (packaged ones are
            named by the package's version); taken when the scenario loads.
    """

    id: str
    description: str
    schema: int
    duration_s: float
    seed: int = 0
    trials: int = 1
    link: LinkSection
    vehicle: VehicleConfig
    operator: OperatorSection = field(default_factory=OperatorSection)
    pilot: PilotSection = field(default_factory=PilotSection)
    control_laws: ControlLawsSection = field(default_factory=ControlLawsSection)
    faults: FaultsSection = field(default_factory=FaultsSection)
    metrics: MetricsSection = field(default_factory=MetricsSection)
    images: ImagesSection = field(default_factory=ImagesSection)
    source: str
    overrides: tuple[str, ...] = ()
    files: tuple[tuple[str, str], ...] = ()

    def __post_init__(self) -> None:
        check(
            ID_PATTERN.fullmatch(self.id) is not None,  # `$` alone lets a final newline in
            "id",
            f"must match {ID_PATTERN.pattern} (e.g. 's100-teleop-v1'), got {self.id!r}",
        )
        check(
            self.schema == SCHEMA_VERSION,
            "schema",
            f"unsupported schema version {self.schema} (supported: {SCHEMA_VERSION})",
        )
        check_range(self.duration_s, "duration_s", 0.0, MAX_DURATION_S, "s", low_open=True)
        check(self.seed >= 0, "seed", f"must be ≥ 0, got {self.seed}")
        check(
            1 <= self.trials <= MAX_TRIALS,
            "trials",
            f"must be an integer in [1, {MAX_TRIALS}], got {self.trials}",
        )
        self._check_budget()
        end = self.duration_s
        for i, fault in enumerate(self.faults.thrusters):
            check(fault.t_s < end, f"faults.thrusters[{i}].t_s", f"must be < duration_s ({end})")
        for i, outage in enumerate(self.faults.link_outages):
            check(
                outage.end_s <= end,
                f"faults.link_outages[{i}].end_s",
                f"must be ≤ duration_s ({end}), got {outage.end_s}",
            )
        autonomy = self.vehicle.autonomy
        for key, value in (
            ("operator.arm_at_s", self.operator.arm_at_s),
            ("pilot.start_s", self.pilot.start_s if self.pilot.timed else 0.0),  # else moot
            ("metrics.settle_s", self.metrics.settle_s),
            ("vehicle.autonomy.start_s", 0.0 if autonomy is None else autonomy.start_s),
        ):
            check(value < end, key, f"must be < duration_s ({end}), got {value}")
        self._check_images()
        check(
            self.pilot.kind != "attitude" or self.operator.mode != "manual",
            "operator.mode",
            "the attitude pilot needs 'stabilize' or 'depth_hold', got 'manual'",
        )
        if self.vehicle.arm is None:
            for i, goal in enumerate(self.pilot.goals):
                check(
                    goal.frame != "end_effector",
                    f"pilot.goals[{i}].frame",
                    "an 'end_effector' goal needs an arm on the vehicle (vehicle.arm)",
                )
        if self.pilot.kind == "attitude":  # a held setpoint is no news: it is not sent again
            period, hold = 1.0 / self.pilot.setpoint_rate_hz, self.vehicle.failsafe.hold_after_s
            check(
                period < hold,
                "pilot.setpoint_rate_hz",
                f"a setpoint every {period:g} s is no fresher than vehicle.failsafe.hold_after_s "
                f"({hold:g} s): the failsafe would hold between setpoints (raise one of them)",
            )

    def _check_budget(self) -> None:
        """The run's size is bounded, so every accepted scenario finishes."""
        vehicle = self.vehicle
        steps = self.duration_s / vehicle.physics_dt_s
        check(
            steps <= MAX_PHYSICS_STEPS,
            "duration_s",
            f"{self.duration_s:g} s at vehicle.physics_dt_s = {vehicle.physics_dt_s:g} s is "
            f"{steps:.3g} physics steps, more than the {MAX_PHYSICS_STEPS:.0e} allowed",
        )
        link = self.link
        if link.mac == "token" and link.ipg == "fixed":
            slots = self.duration_s / link.ipg_s
            check(
                slots <= MAX_TOKEN_SLOTS,
                "link.ipg_s",
                f"{link.ipg_s:g} s over duration_s = {self.duration_s:g} s is {slots:.3g} token "
                f"slots, more than the {MAX_TOKEN_SLOTS:.0e} allowed",
            )
        rate = min(self.metrics.sample_rate_hz, vehicle.control_rate_hz)
        rows = self.duration_s * rate
        check(
            rows <= MAX_SERIES_ROWS,
            "metrics.sample_rate_hz",
            f"{rate:g} Hz over duration_s = {self.duration_s:g} s is {rows:.3g} series rows, "
            f"more than the {MAX_SERIES_ROWS:.0e} allowed",
        )

    def _check_images(self) -> None:
        """Images ride on token-passing teleop replies and need the vehicle's camera."""
        images = self.images
        if not images.enabled:
            return
        check(
            self.link.codec == "teleop" and self.link.mac == "token",
            "images.enabled",
            "needs link.codec = 'teleop' and link.mac = 'token' (chunks ride on the replies)",
        )
        camera = self.vehicle.camera
        check(camera.enabled, "images.enabled", "needs vehicle.camera.enabled = true")
        rois: list[tuple[str, tuple[int, ...] | None]] = [("images.roi", images.roi)]
        rois += [(f"images.changes[{i}].roi", c.roi) for i, c in enumerate(images.changes)]
        for key, roi in rois:
            if roi:
                check(
                    roi[2] < camera.width_px and roi[3] < camera.height_px,
                    key,
                    f"must lie inside the {camera.width_px}x{camera.height_px} camera image, "
                    f"got {list(roi)}",
                )
        for i, change in enumerate(images.changes):
            check(
                change.t_s < self.duration_s,
                f"images.changes[{i}].t_s",
                f"must be < duration_s ({self.duration_s}), got {change.t_s}",
            )
