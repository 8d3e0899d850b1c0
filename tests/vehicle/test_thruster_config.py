"""testbed.vehicle.thruster_config: thruster geometry, frame conversion and the packaged layouts."""

from __future__ import annotations

import dataclasses
import tomllib
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from testbed.config import ConfigError, FieldError
from testbed.vehicle.thruster_config import (
    ThrusterConfig,
    ThrusterSpec,
    known_thruster_configs,
    load_thruster_config,
    mate_rov_to_frd,
    read_thruster_config,
)

ALL = ("bluerov2", "bluerov2-heavy", "ecs-2h", "ecs-3h", "ecs-4h", "ecs-6dof")
X, Y, Z, K, M, N = range(6)


def raw_toml(name: str) -> dict:  # type: ignore[type-arg]
    text = resources.files("testbed.vehicle").joinpath("data", "thrusters", f"{name}.toml")
    return tomllib.loads(text.read_text())


def mate_frame_matrix(name: str) -> np.ndarray:
    """T computed directly in mate-rov's frame from the raw file (no conversion)."""
    data = raw_toml(name)
    assert data["frame"] == "mate-rov"
    com = np.array(data["center_of_mass_m"])
    cols = []
    for t in data["thrusters"]:
        d = np.array(t["direction"]) / np.linalg.norm(t["direction"])
        cols.append(np.concatenate([d, np.cross(np.array(t["position_m"]) - com, d)]))
    return np.array(cols).T


def rank(matrix: np.ndarray) -> int:
    s = np.linalg.svd(matrix, compute_uv=False)
    return int(np.sum(s > 1e-5 * s[0]))


def test_known_configs() -> None:
    assert known_thruster_configs() == ALL


def test_unknown_config_lists_the_known_ones() -> None:
    with pytest.raises(ConfigError, match="unknown thruster configuration 'bluerov9'") as err:
        load_thruster_config("bluerov9")
    for name in ALL:
        assert name in str(err.value)


def test_mate_rov_conversion_is_the_explicit_proper_rotation() -> None:
    assert mate_rov_to_frd((1.0, 0.0, 0.0)) == (0.0, 1.0, -0.0)  # right -> +y
    assert mate_rov_to_frd((0.0, 1.0, 0.0)) == (1.0, 0.0, -0.0)  # forward -> +x
    assert mate_rov_to_frd((0.0, 0.0, 1.0)) == (0.0, 0.0, -1.0)  # up -> -z
    r = np.array([mate_rov_to_frd(tuple(row)) for row in np.eye(3)]).T
    assert np.linalg.det(r) == pytest.approx(1.0)


@pytest.mark.parametrize("name", ["bluerov2", "ecs-6dof", "ecs-2h"])
def test_converted_matrix_is_the_rotated_mate_rov_matrix(name: str) -> None:
    r = np.array([mate_rov_to_frd(tuple(row)) for row in np.eye(3)]).T
    block = np.block([[r, np.zeros((3, 3))], [np.zeros((3, 3)), r]])
    assert load_thruster_config(name).matrix == pytest.approx(block @ mate_frame_matrix(name))


def test_bluerov2_behaves_physically_in_frd() -> None:
    cfg = load_thruster_config("bluerov2")
    t = cfg.matrix
    pinv = np.linalg.pinv(t, rcond=1e-5)
    directions = np.array([s.direction for s in cfg.thrusters])
    positions = np.array([s.position_m for s in cfg.thrusters])
    lateral = [cfg.index_of(n) for n in cfg.names if n.startswith("Lateral")]
    vertical = [cfg.index_of(n) for n in cfg.names if n.startswith("Vertical")]
    # Surge: every lateral pushes forward; verticals idle (up to the small pitch correction).
    f = pinv @ np.array([10.0, 0, 0, 0, 0, 0])
    assert all(f[i] * directions[i, 0] > 0 for i in lateral)
    # Sway right: every lateral pushes right.
    f = pinv @ np.array([0, 10.0, 0, 0, 0, 0])
    assert all(f[i] * directions[i, 1] > 0 for i in lateral)
    # Heave down (+z in FRD): both verticals push down.
    f = pinv @ np.array([0, 0, 10.0, 0, 0, 0])
    assert all(f[i] * directions[i, 2] > 0 for i in vertical)
    # Yaw clockwise seen from above (+N): front laterals push right, back ones left.
    f = pinv @ np.array([0, 0, 0, 0, 0, 1.0])
    for i in lateral:
        assert np.sign(f[i] * directions[i, 1]) == np.sign(positions[i, 0])
    # Roll right (+K, starboard down): the right vertical pushes down, the left one up.
    f = pinv @ np.array([0, 0, 0, 1.0, 0, 0])
    for i in vertical:
        assert np.sign(f[i] * directions[i, 2]) == np.sign(positions[i, 1])
    # Layout: laterals 7 cm below the CoM (z down), verticals on the centre plane.
    assert positions[lateral, 2] == pytest.approx([0.07] * 4)
    assert positions[vertical, 2] == pytest.approx([0.0, 0.0])


@pytest.mark.parametrize(
    ("name", "expected"),
    [
        ("bluerov2", 5),
        ("ecs-4h", 5),
        ("ecs-3h", 5),
        ("ecs-2h", 4),
        ("ecs-6dof", 6),
        ("bluerov2-heavy", 6),
    ],
)
def test_ranks(name: str, expected: int) -> None:
    assert rank(load_thruster_config(name).matrix) == expected


def test_pitch_is_outside_the_standard_range_only() -> None:
    for name, controllable in (("bluerov2", False), ("ecs-6dof", True), ("bluerov2-heavy", True)):
        t = load_thruster_config(name).matrix
        pitch = np.zeros(6)
        pitch[M] = 1.0
        achieved = t @ np.linalg.pinv(t, rcond=1e-5) @ pitch
        assert bool(abs(achieved[M] - 1.0) < 1e-9) is controllable


def test_ecs_variants_are_the_standard_vehicle_with_thrusters_removed() -> None:
    base = {s.name: s for s in load_thruster_config("bluerov2").thrusters}
    assert load_thruster_config("ecs-4h").thrusters == load_thruster_config("bluerov2").thrusters
    expected_missing = {
        "ecs-3h": {"LateralBackLeft"},
        "ecs-2h": {"LateralBackLeft", "LateralFrontRight"},
    }
    for name, missing in expected_missing.items():
        cfg = load_thruster_config(name)
        assert set(base) - set(cfg.names) == missing
        assert all(spec == base[spec.name] for spec in cfg.thrusters)
    six = load_thruster_config("ecs-6dof")
    assert set(base) - set(six.names) == {"LateralBackLeft"}
    moved = six.thrusters[six.index_of("VerticalBackLeft")]
    assert moved.position_m == pytest.approx(
        (-0.120, -0.218, -0.004)
    )  # from (-0.218, -0.120, 0.004)
    assert moved.direction == pytest.approx((0.0, 0.0, -1.0))  # up
    assert moved.handedness == "ccw"
    assert moved.pwm_channel == base["LateralBackLeft"].pwm_channel


def test_ecs_2h_keeps_pure_yaw_but_couples_surge_with_sway() -> None:
    t = load_thruster_config("ecs-2h").matrix
    project = t @ np.linalg.pinv(t, rcond=1e-5)
    assert project @ np.eye(6)[N] == pytest.approx(np.eye(6)[N])
    surge = project @ np.eye(6)[X]
    assert surge[X] == pytest.approx(0.5, abs=0.01)
    assert surge[Y] == pytest.approx(0.5, abs=0.01)


# Wu 2018 / OsloMet BlueROV2 Heavy TCM, REFERENCE §3.3 (rounded to the printed digits).
WU_HEAVY_TCM = np.array(
    [
        [0.707, 0.707, -0.707, -0.707, 0, 0, 0, 0],
        [-0.707, 0.707, -0.707, 0.707, 0, 0, 0, 0],
        [0, 0, 0, 0, -1, 1, 1, -1],
        [0.06, -0.06, 0.06, -0.06, -0.218, -0.218, 0.218, 0.218],
        [0.06, 0.06, -0.06, -0.06, 0.12, -0.12, 0.12, -0.12],
        [-0.1888, 0.1888, 0.1888, -0.1888, 0, 0, 0, 0],
    ]
)


def test_heavy_matches_the_wu_tcm_up_to_vertical_direction_signs() -> None:
    packaged = load_thruster_config("bluerov2-heavy")
    # Wu's TCM takes moments about von Benzon's origin; the packaged file puts the CoM 8.5 cm
    # lower, in the horizontals' plane (its comment gives why).
    source = dataclasses.replace(packaged, center_of_mass_m=(0.0, 0.0, 0.0))
    t = source.matrix
    # Wu points T6 and T7 down; here every vertical points up, so those columns flip.
    signs = np.array([1, 1, 1, 1, 1, -1, -1, 1])
    assert t == pytest.approx(WU_HEAVY_TCM * signs, abs=6e-4)
    assert np.linalg.cond(t) == pytest.approx(8.4, abs=0.05)  # REFERENCE §4.8
    # Moving the CoM by c changes only the moments: (p - c) x d = p x d - c x d.
    shift = np.cross(np.asarray(packaged.center_of_mass_m), t[:3].T).T
    assert packaged.matrix == pytest.approx(np.vstack([t[:3], t[3:] - shift]), abs=1e-12)
    # with the CoM in their plane the horizontals give no roll or pitch (ArduSub's mixer)
    assert packaged.matrix[3:5, :4] == pytest.approx(0.0, abs=1e-12)


def test_heavy_numbering_follows_ardusub_servo_order() -> None:
    cfg = load_thruster_config("bluerov2-heavy")
    assert [s.pwm_channel for s in cfg.thrusters] == list(range(8))
    positions = np.array([s.position_m for s in cfg.thrusters])
    # M1 front-right, M2 front-left, M3 back-right, M4 back-left; M5-M8 the same for verticals.
    quadrant_signs = [(1, 1), (1, -1), (-1, 1), (-1, -1)] * 2
    assert [(int(np.sign(p[0])), int(np.sign(p[1]))) for p in positions] == quadrant_signs


def test_spec_normalises_direction_and_rejects_non_unit() -> None:
    spec = ThrusterSpec("a", (0.0, 0.0, 0.0), (0.707, 0.707, 0.0), "cw", 0)
    assert np.linalg.norm(spec.direction) == pytest.approx(1.0, abs=1e-15)
    with pytest.raises(FieldError, match="direction"):
        ThrusterSpec("a", (0.0, 0.0, 0.0), (7.07, 7.07, 0.0), "cw", 0)
    with pytest.raises(FieldError, match="pwm_channel"):
        ThrusterSpec("a", (0.0, 0.0, 0.0), (1.0, 0.0, 0.0), "cw", -1)


def test_config_rejects_duplicates_and_bad_limits() -> None:
    a = ThrusterSpec("a", (0.1, 0.0, 0.0), (1.0, 0.0, 0.0), "cw", 0)
    b = ThrusterSpec("b", (-0.1, 0.0, 0.0), (1.0, 0.0, 0.0), "cw", 1)
    with pytest.raises(FieldError, match="duplicate thruster names"):
        ThrusterConfig("x", (a, a))
    with pytest.raises(FieldError, match="duplicate pwm channels"):
        ThrusterConfig("x", (a, ThrusterSpec("b", (0, 0, 0), (0, 1, 0), "cw", 0)))
    with pytest.raises(FieldError, match="current_budget_a"):
        ThrusterConfig("x", (a, b), current_budget_a=0.0)
    with pytest.raises(FieldError, match="thrusters"):
        ThrusterConfig("x", ())
    with pytest.raises(KeyError, match="no thruster 'c'"):
        ThrusterConfig("x", (a, b)).index_of("c")


def test_matrix_column_is_direction_and_moment_about_the_com() -> None:
    spec = ThrusterSpec("a", (0.3, 0.2, 0.1), (0.0, 1.0, 0.0), "cw", 0)
    cfg = ThrusterConfig("x", (spec,), center_of_mass_m=(0.1, 0.0, 0.0))
    # r = (0.2, 0.2, 0.1), d = y: r x d = (-0.1, 0, 0.2).
    assert cfg.matrix[:, 0] == pytest.approx([0.0, 1.0, 0.0, -0.1, 0.0, 0.2])


def test_bad_files_name_file_and_key(tmp_path: Path) -> None:
    text = (
        resources.files("testbed.vehicle")
        .joinpath("data", "thrusters", "bluerov2.toml")
        .read_text()
    )
    bad_key = tmp_path / "bad_key.toml"
    bad_key.write_text(text.replace("pwm_channel = 5", "pwm_channel = 5\nthrust_n = 3"))
    with pytest.raises(ConfigError, match=r"bad_key.toml: thrusters\[5\].thrust_n: unknown key"):
        read_thruster_config(bad_key)
    bad_hand = tmp_path / "bad_hand.toml"
    bad_hand.write_text(text.replace('handedness = "cw"', 'handedness = "left"', 1))
    with pytest.raises(ConfigError, match=r"handedness: expected one of"):
        read_thruster_config(bad_hand)
    duplicate = tmp_path / "duplicate.toml"
    duplicate.write_text(text.replace("pwm_channel = 5", "pwm_channel = 4"))
    with pytest.raises(ConfigError, match=r"duplicate.toml: thrusters: duplicate pwm channels"):
        read_thruster_config(duplicate)


def test_the_ardusub_table_names_the_layouts_thrusters(tmp_path: Path) -> None:
    text = (
        resources.files("testbed.vehicle")
        .joinpath("data", "thrusters", "bluerov2.toml")
        .read_text()
    )
    cfg = load_thruster_config("bluerov2")
    assert cfg.ardusub is not None and cfg.ardusub.frame_config == 1
    assert [cfg.names[c] for c in cfg.ardusub_motor_columns] == list(cfg.ardusub.motors)
    assert load_thruster_config("ecs-4h").ardusub is None  # no ArduSub frame: ()
    assert load_thruster_config("ecs-4h").ardusub_motor_columns == ()
    last = '    "VerticalLeft",\n]'
    cases = {
        "unknown": (last, '    "VerticalLeft",\n    "Nowhere",\n]'),
        "twice": (last, '    "VerticalRight",\n]'),
        "frame": ("frame_config = 1", "frame_config = 9"),
    }
    messages = {
        "unknown": r"unknown.toml: ardusub.motors: no thruster called \['Nowhere'\]",
        "twice": r"twice.toml: ardusub.motors: names a thruster twice: \['VerticalRight'\]",
        "frame": r"frame.toml: ardusub.frame_config: must be an ArduSub FRAME_CONFIG 0..7",
    }
    for name, (old, new) in cases.items():
        assert old in text
        path = tmp_path / f"{name}.toml"
        path.write_text(text.replace(old, new))
        with pytest.raises(ConfigError, match=messages[name]):
            read_thruster_config(path)
