"""A vehicle its own failsafe disarmed stays disarmed when the link comes back (as ArduSub:
only the pilot re-arms). A MAVLink user's review found the vehicle arming itself again after
an outage, through the gateway and on m64: the operator's arm flag stayed up because the
reply that would have shown the vehicle armed was lost to the outage.

Truth: the scenario's own timeline (the arm order lands at 11.43 s, the outage starts at
12 s before the reply that shows it armed, the failsafe's HOLD after 1 s and SURFACE after
5 s of silence, a disarm on surfacing) and ArduSub's rule.
"""

from __future__ import annotations

from testbed.run.runner import run_scenario
from testbed.run.scenario import load_scenario


def test_a_failsafe_disarm_lasts_past_the_outage() -> None:
    overrides = [
        "duration_s=40",
        "link.ber=0",
        "operator.arm_at_s=11.2",
        "faults.link_outages=[{start_s = 12.0, end_s = 24.0}]",
    ]
    result = run_scenario(load_scenario("s100-teleop-v1", overrides))
    kinds = [(e.kind, e.t_s) for e in result.recorder.events if e.kind in ("arm", "disarm")]
    assert [kind for kind, _ in kinds] == ["arm", "disarm"]
    armed_s, disarmed_s = (t for _, t in kinds)
    assert 11.2 < armed_s < 12.0 and 16.0 < disarmed_s < 24.0  # on surfacing, in the outage
    series = result.recorder.series()
    back = series["t_s"] > 25.0
    assert (series["armed"][back] == 0.0).all()
