"""testbed.run.scenario: packaged scenarios, --set overrides and one-line errors naming
file and key."""

from __future__ import annotations

import dataclasses
import hashlib
import importlib.metadata
import math
import tomllib
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from testbed.channel import TELEROBOTICS_2021, Fixed, load_link_config
from testbed.config import ConfigError
from testbed.run.metrics import SIGNAL_LAG_WINDOW_S
from testbed.run.runner import run_scenario
from testbed.run.scenario import load_scenario
from testbed.run.scenario_files import scenario_names
from testbed.run.sections import LinkOutage, PilotSection, SineTerm, ThrusterFault
from testbed.vehicle.thruster_config import load_thruster_config
from testbed.vehicle.vehicle_config import VehicleConfig
from testbed.vehicle.water_current import WaterCurrent

PACKAGED = [
    "ecs-rollpitch-6dof-v1",
    "ecs-yaw-2h-v1",
    "ecs-yaw-3h-v1",
    "ecs-yaw-4h-v1",
    "heavy-station-keeping-v1",
    "heavy-waypoint-v1",
    "m64-teleop-v1",
    "s100-mavlink-hl-v1",
    "s100-mavlink-raw-v1",
    "s100-outage-v1",
    "s100-supervised-v1",
    "s100-teleop-v1",
    "s100-thruster-failure-v1",
    "s100-video-v1",
    "tether-teleop-v1",
    "uvms-station-keeping-v1",
    "uvms-waypoint-v1",
]
TELEOP = ["s100-teleop-v1", "tether-teleop-v1", "m64-teleop-v1", "s100-outage-v1"]
ECS = {
    "ecs-yaw-4h-v1": "ecs-4h",
    "ecs-yaw-3h-v1": "ecs-3h",
    "ecs-yaw-2h-v1": "ecs-2h",
    "ecs-rollpitch-6dof-v1": "ecs-6dof",
}

MINIMAL = """\
schema = 1
id = "t-v1"
description = "test"
duration_s = 20.0
"""


def raw_toml(scenario_id: str) -> dict[str, object]:
    """The packaged file's data, read straight from the package (not through the loader)."""
    text = resources.files("testbed").joinpath("scenarios", f"{scenario_id}.toml").read_text()
    return tomllib.loads(text)


def write(tmp_path: Path, text: str, name: str = "t.toml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def error_of(name: str, overrides: tuple[str, ...] = ()) -> str:
    with pytest.raises(ConfigError) as info:
        load_scenario(name, overrides)
    message = str(info.value)
    assert "\n" not in message
    return message


# --- packaged scenarios ------------------------------------------------------------------------


def test_packaged_ids_are_the_file_names() -> None:
    assert scenario_names() == PACKAGED
    folder = resources.files("testbed").joinpath("scenarios")
    stems = sorted(p.name.removesuffix(".toml") for p in folder.iterdir() if p.is_file())
    assert stems == PACKAGED


@pytest.mark.parametrize("scenario_id", PACKAGED)
def test_every_packaged_scenario_loads(scenario_id: str) -> None:
    scenario = load_scenario(scenario_id)
    assert scenario.id == scenario_id
    assert scenario.source == f"package:{scenario_id}"
    assert scenario.schema == 1
    assert scenario.description
    raw = raw_toml(scenario_id)
    assert scenario.duration_s == raw["duration_s"]
    assert scenario.link.channel.name == scenario.link.preset
    assert scenario.link.channel == load_link_config(scenario.link.preset)  # no channel keys
    names = {t.name for t in load_thruster_config(scenario.vehicle.thrusters).thrusters}
    assert {fault.thruster for fault in scenario.faults.thrusters} <= names
    with pytest.raises(dataclasses.FrozenInstanceError):
        scenario.duration_s = 1.0  # type: ignore[misc]  # checking it is frozen


def test_load_by_path_equals_packaged(tmp_path: Path) -> None:
    text = resources.files("testbed").joinpath("scenarios", "m64-teleop-v1.toml").read_text()
    path = write(tmp_path, text, "copy.toml")
    from_path = load_scenario(str(path))
    assert from_path.source == str(path)
    # the file's digest is recorded (what ran); a packaged scenario records none
    assert from_path.files == ((str(path), hashlib.sha256(text.encode()).hexdigest()),)
    packaged = load_scenario("m64-teleop-v1")
    assert packaged.files == ()
    assert from_path == dataclasses.replace(packaged, source=str(path), files=from_path.files)


def test_a_run_records_what_ran(tmp_path: Path) -> None:
    """metrics.json's inputs: the testbed's version, the source, the --set overrides in order,
    and the digest of each user file (here a thruster layout given by path)."""
    layout = resources.files("testbed.vehicle").joinpath("data", "thrusters", "bluerov2.toml")
    mine = write(tmp_path, layout.read_text(encoding="utf-8"), "mine.toml")
    overrides = ["duration_s=12", "metrics.settle_s=1", f"vehicle.thrusters={mine}"]
    scenario = load_scenario("s100-teleop-v1", overrides)
    inputs = run_scenario(scenario).metrics["inputs"]
    digest = hashlib.sha256(mine.read_bytes()).hexdigest()
    assert inputs == {
        "testbed": importlib.metadata.version("testbed"),
        "source": "package:s100-teleop-v1",
        "overrides": overrides,
        "files": {str(mine): digest},
    }


def test_default_scenario_is_the_papers_setup() -> None:
    s = load_scenario("s100-teleop-v1")
    c = s.link.channel
    assert (c.bitrate_bps, c.ber, round(c.intrinsic_delay_s, 3)) == (1900.0, 7e-6, 0.085)
    assert (s.link.codec, s.link.mac) == ("teleop", "token")
    assert s.link.ipg_policy is TELEROBOTICS_2021
    # telerobotics 2021: max(13, L)·8/175 s, 0.594 s for the 13-byte move order.
    assert s.link.ipg_policy.gap_for(bytes(13)) == pytest.approx(13 * 8 / 175)
    assert (s.vehicle.model, s.vehicle.thrusters) == ("bluerov2", "bluerov2")
    assert s.vehicle.sensors.position is not None
    assert s.vehicle.start_position_ned_m[2] == pytest.approx(1.0)
    distance = math.dist(s.link.operator_position_ned_m, s.vehicle.start_position_ned_m)
    assert distance == pytest.approx(0.5)
    assert (s.operator.mode, s.pilot.kind, s.duration_s) == ("depth_hold", "scripted", 120.0)


@pytest.mark.parametrize("scenario_id", TELEOP)
def test_teleop_scenarios_share_pilot_and_bound_the_sticks(scenario_id: str) -> None:
    s = load_scenario(scenario_id)
    assert s.pilot == load_scenario("s100-teleop-v1").pilot
    # the change-set codec carries a depth setpoint (the vehicle's start depth); the others none
    depth = 1.0 if s.link.codec == "changeset" else None
    assert s.operator == dataclasses.replace(
        load_scenario("s100-teleop-v1").operator, depth_m=depth
    )
    for axis in ("x", "y", "z", "yaw"):
        terms = getattr(s.pilot, axis)
        assert len(terms) >= 2
        assert sum(abs(t.amplitude) for t in terms) <= 0.6 + 1e-12
        assert len({t.period_s for t in terms}) == len(terms)
    assert sum(abs(t.amplitude) for t in s.pilot.x) <= 0.35 + 1e-12  # modest surge
    start = s.pilot.start_s
    no_jump = pytest.approx((0.0, 0.0, 0.0, 0.0), abs=1e-12)
    assert s.pilot.pilot().sticks(start) == no_jump


def test_tether_and_m64_change_only_the_link_and_what_it_needs() -> None:
    base = load_scenario("s100-teleop-v1")
    tether = load_scenario("tether-teleop-v1")
    assert tether.vehicle == base.vehicle
    assert (tether.link.preset, tether.link.codec, tether.link.mac) == (
        "tether",
        "changeset",
        "free",
    )
    assert tether.link.rates_used
    assert tether.link.uplink_rate_hz == tether.link.downlink_rate_hz
    assert tether.link.downlink_rate_hz == tether.vehicle.control_rate_hz
    m64 = load_scenario("m64-teleop-v1")
    assert dataclasses.replace(m64.vehicle, failsafe=base.vehicle.failsafe) == base.vehicle
    assert (m64.link.preset, m64.link.codec, m64.link.mac) == ("m64", "teleop", "token")


def test_signal_lag_window_is_twice_an_order_period_and_delivery() -> None:
    m64 = load_scenario("m64-teleop-v1").link
    c = m64.channel
    # 6-s gap; the 13-B order is 2 packets of 8 B (1 s each), a 0.1-s queue gap apart, then
    # propagation over the 200-m range at 1500 m/s.
    delivery_s = 2 * c.airtime_s(8) + c.queue_gap_s + c.max_range_m / c.propagation.speed_mps
    assert m64.signal_lag_window_s == pytest.approx(2 * (6.0 + delivery_s))
    # The S100 and the tether are well inside the default window.
    assert load_scenario("s100-teleop-v1").link.signal_lag_window_s == SIGNAL_LAG_WINDOW_S
    assert load_scenario("tether-teleop-v1").link.signal_lag_window_s == SIGNAL_LAG_WINDOW_S


def test_m64_gap_fits_a_fragmented_exchange() -> None:
    s = load_scenario("m64-teleop-v1")
    c = s.link.channel
    assert c.packet_bytes == 8
    assert c.airtime_s(8) == pytest.approx(1.0)  # one packet a second at 64 bps
    # A 13 B move order and a 20 B state reply, each cut into 8-byte packets (REFERENCE §1.6).
    packets = math.ceil(13 / 8) + math.ceil(20 / 8)
    exchange_s = packets * c.airtime_s(8) + 2 * c.propagation.delay_s(c.max_range_m)
    assert isinstance(s.link.ipg_policy, Fixed)
    assert s.link.ipg_policy.gap_s > exchange_s
    # The failsafe does not fire between two orders: age peaks at gap + uplink airtime.
    peak_age_s = s.link.ipg_s + math.ceil(13 / 8) * c.airtime_s(8)
    assert s.vehicle.failsafe.hold_after_s > peak_age_s


def test_outage_triggers_hold_but_not_surfacing() -> None:
    s = load_scenario("s100-outage-v1")
    assert s.pilot == load_scenario("s100-teleop-v1").pilot
    (outage,) = s.faults.link_outages
    failsafe = s.vehicle.failsafe
    c = s.link.channel
    delivery_s = c.intrinsic_delay_s + c.airtime_s(13)
    gap_s = s.link.ipg_policy.gap_for(bytes(13))
    assert outage.duration_s > failsafe.hold_after_s
    # Worst case: the last order before the window, a 2 s back-off after it (telerobotics 2021).
    worst_age_s = gap_s + delivery_s + outage.duration_s + 2.0 + delivery_s
    assert worst_age_s < failsafe.surface_after_s
    assert s.metrics.settle_s < outage.start_s


def test_thruster_failure_scenario() -> None:
    s = load_scenario("s100-thruster-failure-v1")
    (fault,) = s.faults.thrusters
    assert (fault.t_s, fault.mode) == (30.0, "dead")
    assert fault.thruster.startswith("Lateral")
    assert s.link.preset == "s100"
    ecs = load_scenario("ecs-yaw-4h-v1")
    assert s.vehicle == ecs.vehicle
    assert s.pilot.pilot().attitude_deg(7.3) == ecs.pilot.pilot().attitude_deg(7.3)


ECS_SETPOINTS_DEG = {  # (amplitude [deg], period [s]) of roll, pitch, yaw (the paper gives none)
    "ecs-4h": ((0.0, 1.0), (0.0, 1.0), (20.0, 25.0)),
    "ecs-3h": ((0.0, 1.0), (0.0, 1.0), (20.0, 25.0)),
    "ecs-2h": ((0.0, 1.0), (0.0, 1.0), (20.0, 25.0)),
    "ecs-6dof": ((15.0, 20.0), (10.0, 30.0), (0.0, 1.0)),
}


@pytest.mark.parametrize(("scenario_id", "layout"), sorted(ECS.items()))
def test_ecs_scenarios_are_the_paper_experiments(scenario_id: str, layout: str) -> None:
    s = load_scenario(scenario_id)
    # depth held at 0.3 m in a 0.1 m/s current, default gains and sensor noise
    assert s.vehicle == VehicleConfig(
        thrusters=layout,
        current=WaterCurrent(velocity_ned_mps=(0.1, 0.0, 0.0)),
        start_position_ned_m=(0.0, 0.0, 0.3),
    )
    assert s.operator.depth_m == 0.3
    assert s.duration_s == 60.0
    assert s.metrics.settle_s == 10.0
    assert 1.0 / s.metrics.sample_rate_hz == pytest.approx(0.05)
    assert 1.0 / s.pilot.setpoint_rate_hz == pytest.approx(0.025)
    assert (s.link.preset, s.link.codec) == ("tether", "changeset")
    for t in np.linspace(0.0, s.duration_s, 241):
        expected = [
            amplitude * math.sin(2.0 * math.pi * float(t) / period)
            for amplitude, period in ECS_SETPOINTS_DEG[layout]
        ]
        assert s.pilot.pilot().attitude_deg(float(t)) == pytest.approx(expected, abs=1e-9)
    assert s.pilot.pilot().sample(30.0).sticks == (0.0,) * 6


# --- pilot ---------------------------------------------------------------------------------------


def test_sticks_match_the_closed_form_of_the_file() -> None:
    raw = raw_toml("s100-teleop-v1")["pilot"]
    assert isinstance(raw, dict)
    pilot = load_scenario("s100-teleop-v1").pilot
    times = np.linspace(0.0, 120.0, 1201)
    tau = times - raw["start_s"]
    expected = []
    for axis in ("x", "y", "z", "yaw"):
        total = np.zeros_like(times)
        for term in raw[axis]:
            phase = term.get("phase_rad", 0.0)
            total += term["amplitude"] * np.sin(2 * np.pi * tau / term["period_s"] + phase)
        expected.append(np.where(times < raw["start_s"], 0.0, np.clip(total, -1.0, 1.0)))
    got = np.array([pilot.pilot().sticks(float(t)) for t in times]).T
    np.testing.assert_allclose(got, np.array(expected), atol=1e-12)


def test_sticks_are_clipped_and_zero_before_start() -> None:
    pilot = PilotSection(
        start_s=2.0,
        x=(SineTerm(0.9, 10.0), SineTerm(0.8, 10.0)),  # peak 1.7 at τ = 2.5 s
        yaw=(SineTerm(-1.0, 4.0, math.pi / 2),),
    )
    assert pilot.pilot().sticks(1.999) == (0.0, 0.0, 0.0, 0.0)
    assert pilot.pilot().sticks(4.5)[0] == 1.0
    assert pilot.pilot().sticks(9.5)[0] == -1.0
    assert pilot.pilot().sticks(2.0 + 1.0)[0] == pytest.approx(1.7 * math.sin(2 * math.pi / 10))
    assert pilot.pilot().sticks(2.0)[3] == pytest.approx(-1.0)  # -sin(π/2)
    assert pilot.pilot().sticks(4.0)[3] == pytest.approx(1.0)


def test_pilot_kinds_reject_each_others_settings() -> None:
    with pytest.raises(ValueError, match="yaw_amplitude_deg"):
        PilotSection(yaw_amplitude_deg=10.0)
    with pytest.raises(ValueError, match="x: only used"):
        PilotSection(kind="attitude", x=(SineTerm(0.1, 10.0),))


# --- overrides -----------------------------------------------------------------------------------


def test_overrides_reach_nested_keys() -> None:
    s = load_scenario(
        "s100-teleop-v1",
        [
            "link.ber=1e-4",
            "link.propagation.speed_mps=1500",
            "vehicle.model=bluerov2-heavy",
            "vehicle.thrusters=bluerov2-heavy",
            "vehicle.gains.yaw.kp=0.4",
            "pilot.x=[{amplitude = 0.2, period_s = 30.0}]",
            "faults.thrusters=[{t_s = 50.0, thruster = 'VerticalBackLeft', mode = 'dead'}]",
            "faults.link_outages=[{start_s = 10.0, end_s = 12.0}]",
            "seed=7",
        ],
    )
    assert s.link.channel.ber == 1e-4
    assert s.link.channel.propagation.speed_mps == 1500.0
    assert s.link.channel.propagation.fixed_s == 0.0  # the rest of the table is kept
    assert (s.vehicle.model, s.vehicle.thrusters) == ("bluerov2-heavy", "bluerov2-heavy")
    assert s.vehicle.gains.yaw.kp == 0.4
    assert s.pilot.x == (SineTerm(0.2, 30.0),)
    assert s.pilot.y == load_scenario("s100-teleop-v1").pilot.y
    assert s.faults.thrusters == (ThrusterFault(50.0, "VerticalBackLeft", "dead"),)
    assert s.faults.link_outages == (LinkOutage(10.0, 12.0),)
    assert s.seed == 7
    assert s.source == "package:s100-teleop-v1"


@pytest.mark.parametrize(
    ("preset", "keys"),
    [
        ("s100", ["ber=1e-3"]),
        ("s100", ["propagation.speed_mps=1500", "max_range_m=40"]),
        ("m64", ["burst.p_good_to_bad=0.01", "burst.ber_bad=0.2", "tx_buffer_bytes=64"]),
        ("tether", ["bitrate_bps=1e6", "duplex='half'"]),
    ],
)
def test_link_channel_equals_load_link_config(preset: str, keys: list[str], tmp_path: Path) -> None:
    expected = load_link_config(preset, keys)
    via_set = load_scenario(
        "s100-teleop-v1", [f"link.preset={preset}", *(f"link.{k}" for k in keys)]
    )
    assert via_set.link.channel == expected
    # The same keys written flat in the file's [link] table (TOML dotted keys for nested ones).
    text = "\n".join([MINIMAL, "[link]", f'preset = "{preset}"', *keys])
    via_file = load_scenario(str(write(tmp_path, text)))
    assert via_file.link.channel == expected


def test_ipg_policies() -> None:
    fixed = load_scenario("s100-teleop-v1", ["link.ipg=fixed", "link.ipg_s=1.25"])
    assert fixed.link.ipg_policy == Fixed(1.25)
    old = load_scenario("s100-teleop-v1", ["link.ipg=telerobotics-2019"])
    assert old.link.ipg_policy.gap_for(bytes(13)) == pytest.approx(2.08)  # REFERENCE §1.7
    # A file's ipg_s is ignored, not an error, when an override switches the policy away.
    m64 = load_scenario("m64-teleop-v1", ["link.ipg=telerobotics-2018"])
    assert m64.link.ipg_policy.gap_for(bytes(60)) == pytest.approx(0.8)


# --- errors --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("override", "fragment"),
    [
        # unknown keys, at every level
        ("bogus=1", "--set: bogus: unknown key"),
        ("source='x'", "--set: source: unknown key"),
        ("link.bogus=1", "--set: link.bogus: unknown key"),
        ("link.channel.ber=0.1", "--set: link.channel: unknown key"),
        ("link.propagation.bogus=1", "--set: link.propagation.bogus: unknown key"),
        ("vehicle.bogus=1", "--set: vehicle.bogus: unknown key"),
        ("vehicle.gains.yaw.bogus=1", "--set: vehicle.gains.yaw.bogus: unknown key"),
        ("operator.bogus=1", "--set: operator.bogus: unknown key"),
        ("pilot.bogus=1", "--set: pilot.bogus: unknown key"),
        ("pilot.x=[{amplitude=0.1, period_s=3, bogus=1}]", "--set: pilot.x[0].bogus: unknown"),
        ("faults.bogus=1", "--set: faults.bogus: unknown key"),
        (
            "faults.thrusters=[{t_s=1, thruster='VerticalLeft', mode='dead', bogus=1}]",
            "--set: faults.thrusters[0].bogus: unknown key",
        ),
        ("faults.link_outages=[{start_s=1, end_s=2, x=1}]", "--set: faults.link_outages[0].x:"),
        ("metrics.bogus=1", "--set: metrics.bogus: unknown key"),
        # wrong types
        ("duration_s=long", "--set: duration_s: expected a number"),
        ("seed=1.5", "--set: seed: expected an integer"),
        ("link.ber=high", "--set: link.ber: expected a number"),
        ("link=3", "--set: link: expected a table"),
        ("link.codec=zip", "--set: link.codec: expected one of"),
        ("operator.precision=1", "--set: operator.precision: expected true or false"),
        ("pilot.x=0.3", "--set: pilot.x: expected an array"),
        ("vehicle.start_position_ned_m=[1, 2]", "--set: vehicle.start_position_ned_m: expected 3"),
        # values out of range
        ("duration_s=-1", "--set: duration_s: must be in (0, 86400] s, got -1"),
        ("link.ber=2", "--set: link.ber: must be in [0, 1]"),
        ("link.ipg_s=0", "--set: link.ipg_s: must be in (0, 60] s, got 0"),
        ("link.ipg_s=2", "--set: link.ipg_s: only used when link.ipg = 'fixed'"),
        ("link.uplink_rate_hz=5", "--set: link.uplink_rate_hz: only used when"),
        (  # the teleop vehicle only answers orders: it would never send under free access
            "link.mac=free",
            "--set: link.mac: 'free' does not work with link.codec = 'teleop'",
        ),
        ("vehicle.control_rate_hz=0", "--set: vehicle.control_rate_hz: must be in [1, 1000] Hz"),
        ("operator.arm_at_s=-1", "--set: operator.arm_at_s: must be in [0, 86400] s"),
        ("operator.arm_at_s=500", "--set: operator.arm_at_s: must be < duration_s"),
        ("pilot.x=[{amplitude=1.5, period_s=3}]", "--set: pilot.x[0].amplitude: must be in"),
        ("pilot.x=[{amplitude=0.5, period_s=0}]", "--set: pilot.x[0].period_s: must be in [0.01,"),
        ("pilot.kind=attitude", "--set: pilot.x: only used when kind = 'scripted'"),
        (  # within the static domain, beyond what a T200 at the scenario's supply can hold
            'faults.thrusters=[{t_s=2.0, thruster="VerticalLeft", mode="stuck", value=90.0}]',
            "--set: faults.thrusters[0].value: a stuck T200 at 14.8 V holds [",
        ),
        ("metrics.sample_rate_hz=0", "--set: metrics.sample_rate_hz: must be in [0.001, 1000] Hz"),
        ("metrics.settle_s=200", "--set: metrics.settle_s: must be < duration_s"),
        ("id=Bad_Id", "--set: id: must match"),
        ('id="evil-v1\\n"', "--set: id: must match"),  # a newline after the version
        (
            "faults.thrusters=[{t_s=200, thruster='VerticalLeft', mode='dead'}]",
            "--set: faults.thrusters[0].t_s: must be < duration_s",
        ),
        (
            "faults.thrusters=[{t_s=1, thruster='VerticalLeft', mode='degraded', value=2}]",
            "--set: faults.thrusters[0].value: must be in [0, 1]",
        ),
        (
            "faults.thrusters=[{t_s=1, thruster='VerticalLeft', mode='melted'}]",
            "--set: faults.thrusters[0].mode: expected one of",
        ),
        (
            "faults.link_outages=[{start_s=100, end_s=130}]",
            "--set: faults.link_outages[0].end_s: must be ≤ duration_s",
        ),
        (
            "faults.link_outages=[{start_s=10, end_s=9}]",
            "--set: faults.link_outages[0].end_s: must be > start_s",
        ),
        (
            "faults.link_outages=[{start_s=10, end_s=20}, {start_s=15, end_s=30}]",
            "--set: faults.link_outages[1].start_s: must be ≥ the previous",
        ),
        # names
        ("link.preset=s999", "--set: link.preset: unknown link preset 's999' (packaged: m64, s100"),
        ("vehicle.model=nautilus", "--set: vehicle.model: unknown vehicle model 'nautilus'"),
        (
            "vehicle.thrusters=octo",
            "--set: vehicle.thrusters: unknown thruster configuration 'octo'",
        ),
        (
            "faults.thrusters=[{t_s=1, thruster='Foo', mode='dead'}]",
            "--set: faults.thrusters[0].thruster: unknown thruster 'Foo' of bluerov2 "
            "(known: LateralFrontLeft",
        ),
        # schema
        ("schema=2", "--set: schema: unsupported schema version 2 (supported: 1)"),
        ("schema=true", "--set: schema: unsupported schema version True"),
        # syntax
        ("link.ber", "--set 'link.ber': expected KEY=VALUE"),
    ],
)
def test_bad_override_names_set_and_key(override: str, fragment: str) -> None:
    message = error_of("s100-teleop-v1", (override,))
    assert message.startswith(fragment.split(":")[0])
    assert fragment in message


@pytest.mark.parametrize(
    ("extra", "key"),
    [
        ("bogus = 1\n", "bogus: unknown key"),
        ("[link]\nbogus = 1\n", "link.bogus: unknown key (known: ber, ber_per_m, bitrate_bps"),
        ("[link.burst]\nbogus = 1\n", "link.burst.bogus: unknown key"),
        ("[vehicle.sensors.imu]\nbogus = 1\n", "vehicle.sensors.imu.bogus: unknown key"),
        ("[operator]\nmode = 'auto'\n", "operator.mode: expected one of"),
        ("[[pilot.y]]\namplitude = 0.1\n", "pilot.y[0].period_s: required key missing"),
        ("[[faults.thrusters]]\nt_s = 1\nthruster = 'X'\nmode = 'dead'\n", "thrusters[0].thruster"),
        ("[metrics]\nsettle_s = -1\n", "metrics.settle_s: must be in [0, 86400] s"),
        ("[link]\nipg_s = 1.0\n", "link.ipg_s: only used when link.ipg = 'fixed'"),
        ("[link]\ndownlink_rate_hz = 5.0\n", "link.downlink_rate_hz: only used when"),
        ("[operator]\nmode = 'manual'\n[pilot]\nkind = 'attitude'\n", "operator.mode: the att"),
    ],
)
def test_bad_file_names_file_and_key(tmp_path: Path, extra: str, key: str) -> None:
    path = write(tmp_path, MINIMAL + extra)
    message = error_of(str(path))
    assert message.startswith(f"{path}: ")
    assert key in message


def test_minimal_file_takes_the_defaults(tmp_path: Path) -> None:
    s = load_scenario(str(write(tmp_path, MINIMAL)))
    assert (s.link.preset, s.link.ipg, s.seed, s.pilot.x) == ("s100", "telerobotics-2021", 0, ())
    assert s.link.channel == load_link_config("s100")
    assert s.operator.depth_m is None


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        (MINIMAL.replace("schema = 1", "schema = 2") + "new_thing = 1\n", "schema: unsupported"),
        (MINIMAL.replace("schema = 1\n", ""), "schema: required key missing"),
        (MINIMAL.replace('description = "test"\n', ""), "description: required key missing"),
        (MINIMAL.replace("duration_s = 20.0", 'duration_s = "20"'), "duration_s: expected a"),
        (MINIMAL + "[link\n", "malformed TOML"),
        (MINIMAL + "duration_s = 5.0\n", "malformed TOML"),  # duplicate key
    ],
)
def test_bad_header_or_syntax(tmp_path: Path, text: str, fragment: str) -> None:
    path = write(tmp_path, text)
    message = error_of(str(path))
    assert message.startswith(f"{path}: ")
    assert fragment in message


def test_file_errors_come_before_override_errors(tmp_path: Path) -> None:
    path = write(tmp_path, MINIMAL + "[pilot]\nbogus = 1\n")
    message = error_of(str(path), ("link.ber=5",))
    assert message.startswith(f"{path}: pilot.bogus")


def test_missing_file_and_unknown_id(tmp_path: Path) -> None:
    missing = tmp_path / "nope.toml"
    assert error_of(str(missing)) == f"{missing}: file not found"
    message = error_of("s200-teleop-v1")
    assert message.startswith("scenario 's200-teleop-v1': unknown scenario id (known: ")
    assert all(name in message for name in PACKAGED)


def test_a_missing_mission_names_the_scenario_and_the_key(tmp_path: Path) -> None:
    # a review: "mission 'triangle.json': no such packaged mission … or file" named neither the
    # scenario file nor the key, unlike the model's error
    message = error_of("heavy-waypoint-v1", ("vehicle.autonomy.mission=triangle.json",))
    here = Path("triangle.json").absolute()
    assert message == f"--set: vehicle.autonomy.mission: mission file not found: {here}"
    text = resources.files("testbed").joinpath("scenarios", "heavy-waypoint-v1.toml").read_text()
    assert text.count('mission = "waypoint"') == 1
    path = write(tmp_path, text.replace('mission = "waypoint"', 'mission = "triangle.json"'))
    message = error_of(str(path))  # looked for beside the scenario file
    missing = tmp_path / "triangle.json"
    assert (
        message == f"{path}: vehicle.autonomy.mission: mission file not found: {missing.absolute()}"
    )
    mission = tmp_path / "tilted.json"
    mission.write_text(
        '{"name": "t", "parent": "map", "child": "base_link", "waypoints": [{"time_from_start": '
        '0, "transform": {"x": 0, "y": 0, "z": 1, "rx": 0.2, "ry": 0, "rz": 0}}]}'
    )
    message = error_of("heavy-waypoint-v1", (f"vehicle.autonomy.mission={mission}",))
    assert message.startswith(
        f"--set: vehicle.autonomy.mission: {mission}: waypoints[0].transform.rx: must be 0"
    )


def test_a_scenario_file_finds_its_files_beside_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A scenario file naming `mine.toml` (a layout kept beside it) loads from any working
    directory; a `--set` path is the working directory's, as on any command line."""
    layout = resources.files("testbed.vehicle").joinpath("data", "thrusters", "bluerov2.toml")
    folder = tmp_path / "study"
    folder.mkdir()
    (folder / "mine.toml").write_text(layout.read_text(encoding="utf-8"), encoding="utf-8")
    text = resources.files("testbed").joinpath("scenarios", "s100-teleop-v1.toml").read_text()
    text = text.replace('thrusters = "bluerov2"', 'thrusters = "mine.toml"')
    assert 'thrusters = "mine.toml"' in text
    scenario_path = folder / "my-scenario.toml"
    scenario_path.write_text(text, encoding="utf-8")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    scenario = load_scenario(str(scenario_path))
    assert Path(scenario.vehicle.thrusters) == folder / "mine.toml"
    assert str(folder / "mine.toml") in dict(scenario.files)
    message = error_of(str(scenario_path), ("vehicle.thrusters=mine.toml",))  # not in elsewhere/
    missing = elsewhere / "mine.toml"
    assert message == f"--set: vehicle.thrusters: thruster configuration file not found: {missing}"


def test_depth_hold_needs_a_layout_that_can_heave(tmp_path: Path) -> None:
    """A layout of four horizontal thrusters cannot push along z: depth hold with it is refused
    in one line (a review's vehicle floated from 1.0 m to the surface in 'depth hold');
    manual flight with it loads."""
    text = resources.files("testbed.vehicle").joinpath("data", "thrusters", "bluerov2.toml")
    blocks = text.read_text(encoding="utf-8").split("[[thrusters]]")
    flat = "[[thrusters]]".join(b for b in blocks if 'name = "Vertical' not in b)
    assert flat.count("[[thrusters]]") == 4
    path = write(tmp_path, flat, "flat.toml")
    message = error_of("s100-teleop-v1", (f"vehicle.thrusters={path}",))
    assert message.startswith("--set: operator.mode: 'depth_hold' needs thrust along")
    assert "\n" not in message
    manual = load_scenario("s100-teleop-v1", [f"vehicle.thrusters={path}", "operator.mode=manual"])
    assert manual.operator.mode == "manual"


def test_a_scenario_loaded_again_sees_an_edit_of_a_file_it_names(tmp_path: Path) -> None:
    """A scenario's own checks are kept per text of the scenario file and of the user files
    it names: renaming the layout's thruster that a fault names makes the same scenario file
    refused at its next load (one line naming the fault's key), though its own text is the
    same."""
    layout = resources.files("testbed.vehicle").joinpath("data", "thrusters", "ecs-4h.toml")
    text = layout.read_text(encoding="utf-8")
    mine = write(tmp_path, text, "mine.toml")
    scenario_text = (
        resources.files("testbed.scenarios")
        .joinpath("s100-thruster-failure-v1.toml")
        .read_text(encoding="utf-8")
    )
    assert 'thruster = "LateralFrontLeft"' in scenario_text
    body = scenario_text.replace('thrusters = "ecs-4h"', 'thrusters = "mine.toml"')
    path = write(tmp_path, body, "failure.toml")
    assert load_scenario(str(path)).vehicle.thrusters == str(mine)
    mine.write_text(text.replace("LateralFrontLeft", "PortBow"), encoding="utf-8")
    with pytest.raises(ConfigError, match=r"failure\.toml: faults\.thrusters\[0\]\.thruster: "):
        load_scenario(str(path))
