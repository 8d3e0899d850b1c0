"""Thruster geometry: where each thruster sits, which way it pushes, and the matrix T they form.

A :class:`ThrusterConfig` lists :class:`ThrusterSpec` s in body FRD (x forward, y right, z down,
metres, relative to the body origin) and gives the (6, n) configuration matrix ``T`` whose
column i is ``[d_i ; (p_i - c) x d_i]`` (rows X Y Z K M N, moments about the centre of mass c),
so that the body wrench of thruster forces f is ``T @ f`` (ECS paper, eq. 1).

The packaged layouts live in ``testbed/vehicle/data/thrusters/*.toml`` and are read with
:func:`load_thruster_config`. A file may give its geometry in mate-rov's frame (+X right,
+Y forward, +Z up, as its sources print it); the loader converts explicitly with
:func:`mate_rov_to_frd` (x_frd = Y, y_frd = X, z_frd = -Z, a proper rotation, so moments map
the same way). ``direction`` is the way the thruster pushes the vehicle for a *positive*
force, i.e. the T200's stronger ("forward") thrust; handedness only changes the PWM mapping.
A layout that is one of ArduSub's frames says so in an optional ``[ardusub]`` table
(:class:`ArduSubFrame`: its FRAME_CONFIG and which thruster is ArduSub's motor 1, 2, …), so a
MAVLink endpoint reports the thrusters in ArduSub's numbering.

Pure geometry: no thruster curves (``thrusters.py``) and no allocation (``allocation.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from importlib import resources
from importlib.resources.abc import Traversable
from pathlib import Path
from typing import Literal

import numpy as np

from testbed.config import (
    ConfigError,
    FieldError,
    build,
    built_from_text,
    check,
    load_toml,
    user_file,
)

__all__ = [
    "ArduSubFrame",
    "Handedness",
    "ThrusterConfig",
    "ThrusterSpec",
    "known_thruster_configs",
    "load_thruster_config",
    "mate_rov_to_frd",
    "read_thruster_config",
]

Handedness = Literal["cw", "ccw"]
Vector3 = tuple[float, float, float]

_DIRECTION_NORM_TOLERANCE = 0.01  # sources print 0.707 for sqrt(1/2); catch typos, not rounding


def mate_rov_to_frd(vector: Vector3) -> Vector3:
    """Convert a vector from mate-rov's frame (+X right, +Y forward, +Z up) to body FRD.

    Args:
        vector: (x, y, z) in mate-rov's frame (a position [m] or a direction).

    Returns:
        The same vector in body FRD: (Y, X, -Z). The map is a proper rotation (det +1), so
        cross products, and hence moments, convert the same way.
    """
    x, y, z = vector
    return (float(y), float(x), -float(z))


@dataclass(frozen=True, slots=True)
class ThrusterSpec:
    """One thruster, in body FRD.

    Attributes:
        name: unique within its configuration, e.g. ``"LateralFrontLeft"``.
        position_m: (3,) position of the propeller centre [m], body FRD, from the body origin.
        direction: (3,) unit vector, body FRD, of the force on the vehicle for a positive
            (forward-thrust) command. Normalised on construction (sources print 0.707).
        handedness: ``"cw"`` or ``"ccw"`` propeller; a CCW propeller's PWM is mirrored about
            1500 µs (pwm -> 3000 - pwm) to give the same force.
        pwm_channel: output channel (0-based) of the PWM driver / autopilot.
    """

    name: str
    position_m: Vector3
    direction: Vector3
    handedness: Handedness
    pwm_channel: int

    def __post_init__(self) -> None:
        check(bool(self.name), "name", "must not be empty")
        check(all(math.isfinite(v) for v in self.position_m), "position_m", "must be finite")
        norm = math.sqrt(sum(v * v for v in self.direction))
        check(
            abs(norm - 1.0) <= _DIRECTION_NORM_TOLERANCE,
            "direction",
            f"must be a unit vector (norm within {_DIRECTION_NORM_TOLERANCE}), got norm {norm:.4f}",
        )
        unit = tuple(float(v) / norm for v in self.direction)
        object.__setattr__(self, "direction", unit)
        check(self.pwm_channel >= 0, "pwm_channel", f"must be >= 0, got {self.pwm_channel}")


@dataclass(frozen=True, slots=True)
class ArduSubFrame:
    """The ArduSub frame a layout is, and ArduSub's numbering of its thrusters.

    Attributes:
        frame_config: ArduSub's FRAME_CONFIG (``AP_Motors6DOF::sub_frame_t``: 1 Vectored,
            2 Vectored_6DOF, …; 0–7).
        motors: thruster names in ArduSub's motor order: entry k is motor k + 1 (SERVO k + 1),
            as ``AP_Motors6DOF::setup_motors`` places that frame's motors.
    """

    frame_config: int
    motors: tuple[str, ...]

    def __post_init__(self) -> None:
        check(
            0 <= self.frame_config <= 7,
            "frame_config",
            f"must be an ArduSub FRAME_CONFIG 0..7, got {self.frame_config}",
        )
        repeated = sorted({m for m in self.motors if self.motors.count(m) > 1})
        check(bool(self.motors), "motors", "must name at least one thruster")
        check(not repeated, "motors", f"names a thruster twice: {repeated}")


@dataclass(frozen=True, slots=True)
class ThrusterConfig:
    """A vehicle's thruster layout, in body FRD.

    Attributes:
        name: configuration id, e.g. ``"bluerov2"``.
        thrusters: the thrusters, in allocation order (column order of :attr:`matrix`).
        center_of_mass_m: (3,) centre of mass [m], body FRD; moments are taken about it.
        current_budget_a: total thruster current the allocator may draw [A].
        slew_limit_n_per_s: per-thruster force rate limit [N/s].
        source: where the figures come from (free text).
        ardusub: the ArduSub frame the layout is, with ArduSub's motor numbering (None: not
            one of ArduSub's frames).
    """

    name: str
    thrusters: tuple[ThrusterSpec, ...]
    center_of_mass_m: Vector3 = (0.0, 0.0, 0.0)
    current_budget_a: float = 50.0
    slew_limit_n_per_s: float = 100.0
    source: str = ""
    ardusub: ArduSubFrame | None = None

    def __post_init__(self) -> None:
        check(len(self.thrusters) > 0, "thrusters", "needs at least one thruster")
        check(
            all(math.isfinite(v) for v in self.center_of_mass_m),
            "center_of_mass_m",
            f"must be finite, got {list(self.center_of_mass_m)} (body FRD)",
        )
        names = [t.name for t in self.thrusters]
        duplicate = sorted({n for n in names if names.count(n) > 1})
        check(not duplicate, "thrusters", f"duplicate thruster names {duplicate}")
        channels = [t.pwm_channel for t in self.thrusters]
        repeated = sorted({c for c in channels if channels.count(c) > 1})
        check(not repeated, "thrusters", f"duplicate pwm channels {repeated}")
        check(
            self.current_budget_a > 0,
            "current_budget_a",
            f"must be > 0, got {self.current_budget_a}",
        )
        check(
            self.slew_limit_n_per_s > 0,
            "slew_limit_n_per_s",
            f"must be > 0, got {self.slew_limit_n_per_s}",
        )
        if self.ardusub is not None:
            unknown = [m for m in self.ardusub.motors if m not in names]
            check(
                not unknown,
                "ardusub.motors",
                f"no thruster called {unknown} (thrusters: {', '.join(names)}; a layout that "
                "is not ArduSub's frame has no [ardusub] table)",
            )

    @property
    def n_thrusters(self) -> int:
        """Number of thrusters n."""
        return len(self.thrusters)

    @property
    def names(self) -> tuple[str, ...]:
        """Thruster names in column order."""
        return tuple(t.name for t in self.thrusters)

    @property
    def ccw_mask(self) -> np.ndarray:
        """(n,) bool, True where the propeller is counter-clockwise."""
        return np.array([t.handedness == "ccw" for t in self.thrusters], dtype=bool)

    @property
    def matrix(self) -> np.ndarray:
        """(6, n) configuration matrix T, rows X Y Z K M N [N, N·m per N], body FRD.

        Column i is ``[d_i ; (p_i - c) x d_i]``: the body wrench of a unit force of thruster i.
        """
        positions = np.array([t.position_m for t in self.thrusters], dtype=np.float64)
        directions = np.array([t.direction for t in self.thrusters], dtype=np.float64)
        arms = positions - np.asarray(self.center_of_mass_m, dtype=np.float64)
        return np.vstack([directions.T, np.cross(arms, directions).T])

    @property
    def ardusub_motor_columns(self) -> tuple[int, ...]:
        """Column index of ArduSub's motor 1, 2, … (empty without an ``ardusub`` frame)."""
        if self.ardusub is None:
            return ()
        return tuple(self.index_of(name) for name in self.ardusub.motors)

    def index_of(self, name: str) -> int:
        """Column index of the thruster called ``name``.

        Raises:
            KeyError: no thruster has that name (message lists the names).
        """
        for i, spec in enumerate(self.thrusters):
            if spec.name == name:
                return i
        raise KeyError(
            f"no thruster {name!r} in {self.name!r} (thrusters: {', '.join(self.names)})"
        )


@dataclass(frozen=True, slots=True)
class _ThrusterFile:
    """Schema of a thruster TOML file: a ThrusterConfig plus the frame its vectors are in."""

    name: str
    frame: Literal["frd", "mate-rov"]
    source: str
    current_budget_a: float
    slew_limit_n_per_s: float
    thrusters: tuple[ThrusterSpec, ...]
    center_of_mass_m: Vector3 = (0.0, 0.0, 0.0)
    ardusub: ArduSubFrame | None = None

    def __post_init__(self) -> None:
        check(  # in the file's own frame, as the user wrote it
            all(math.isfinite(v) for v in self.center_of_mass_m),
            "center_of_mass_m",
            f"must be finite, got {list(self.center_of_mass_m)}",
        )


def _data_dir() -> Traversable:
    return resources.files("testbed.vehicle").joinpath("data", "thrusters")


def known_thruster_configs() -> tuple[str, ...]:
    """Names of the packaged thruster configurations (file stems), sorted."""
    return tuple(
        sorted(
            entry.name.removesuffix(".toml")
            for entry in _data_dir().iterdir()
            if entry.name.endswith(".toml")
        )
    )


def load_thruster_config(name: str) -> ThrusterConfig:
    """Load a thruster configuration: a packaged one by name (e.g. ``"bluerov2"``), or the
    user's own TOML file (:func:`read_thruster_config`'s layout) at the path ``name``.

    Raises:
        ConfigError: neither a packaged name nor a file (the message lists the packaged ones),
            or a bad file (the message names the file and the key).
    """
    own = user_file(name, known_thruster_configs(), "thruster configuration")
    if own is not None:
        return read_thruster_config(own)
    with resources.as_file(_data_dir().joinpath(f"{name}.toml")) as path:
        return read_thruster_config(path)


def read_thruster_config(path: str | Path) -> ThrusterConfig:
    """Read a thruster configuration TOML file and convert it to body FRD.

    Args:
        path: the TOML file. Keys: ``name``, ``frame`` (``"frd"`` or
            ``"mate-rov"``), ``source``, ``current_budget_a``, ``slew_limit_n_per_s``,
            optional ``center_of_mass_m``, ``[[thrusters]]`` tables with ``name``,
            ``position_m``, ``direction``, ``handedness``, ``pwm_channel``, and an optional
            ``[ardusub]`` table (``frame_config``, ``motors``: :class:`ArduSubFrame`).

    Raises:
        ConfigError: unreadable file, unknown or missing key, bad value (names file and key).
    """
    return built_from_text("thrusters", path, lambda: _read_layout(path))


def _read_layout(path: str | Path) -> ThrusterConfig:
    """:func:`read_thruster_config` of the file at ``path``, read and checked now."""
    source = str(path)
    raw = build(_ThrusterFile, load_toml(path), source=source)
    convert = mate_rov_to_frd if raw.frame == "mate-rov" else _as_vector
    thrusters = tuple(
        ThrusterSpec(
            name=spec.name,
            position_m=convert(spec.position_m),
            direction=convert(spec.direction),
            handedness=spec.handedness,
            pwm_channel=spec.pwm_channel,
        )
        for spec in raw.thrusters
    )
    try:
        return ThrusterConfig(
            name=raw.name,
            thrusters=thrusters,
            center_of_mass_m=convert(raw.center_of_mass_m),
            current_budget_a=raw.current_budget_a,
            slew_limit_n_per_s=raw.slew_limit_n_per_s,
            source=raw.source,
            ardusub=raw.ardusub,
        )
    except FieldError as err:
        raise ConfigError(f"{source}: {err.key}: {err.message}") from None


def _as_vector(vector: Vector3) -> Vector3:
    x, y, z = vector
    return (float(x), float(y), float(z))
