"""The HIL round trip at the operator (``hil.round_trip_s``): which reply answers which order.

Truth: hand-made traces whose pairing is known by construction: every order gets its reply a
fixed 0.33 s later (the emulated S100 link's two crossings), then the same with one reply held
past the next order's slot, and with one reply lost. A round trip shorter than the link's is
never counted, and the known pairs all are.
"""

from __future__ import annotations

import pytest

from testbed.channel import EventKind, Trace
from testbed.run.hil_metrics import _round_trips

GAP_S = 0.6  # orders' spacing
LINK_S = 0.33  # a reply's delay after its order: both crossings


def _trace(events: list[tuple[float, str]]) -> Trace:
    trace = Trace()
    for frame_id, (t_s, what) in enumerate(sorted(events)):
        if what == "order":
            trace.record(t_s, EventKind.ENQUEUE, "operator", "medium", frame_id, 0, 15)
        else:
            trace.record(t_s, EventKind.DELIVER, "vehicle", "operator", frame_id, 0, 40)
    return trace


def test_every_answered_order_gives_the_link_round_trip() -> None:
    events = [(k * GAP_S, "order") for k in range(10)]
    events += [(k * GAP_S + LINK_S, "reply") for k in range(10)]
    assert _round_trips(_trace(events)) == pytest.approx([LINK_S] * 10)


def test_a_reply_held_past_the_next_order_is_not_paired_with_it() -> None:
    late = 4  # its reply comes 0.1 s after the next order went out
    events = [(k * GAP_S, "order") for k in range(10)]
    events += [(k * GAP_S + LINK_S, "reply") for k in range(10) if k != late]
    events.append(((late + 1) * GAP_S + 0.1, "reply"))
    trips = _round_trips(_trace(events))
    assert min(trips) >= LINK_S - 1e-9  # pairing it with the newer order would give 0.1 s
    # every order before the late one and after the next one is paired
    assert trips == pytest.approx([LINK_S] * 8)


def test_a_lost_reply_costs_its_pair_and_the_next_only() -> None:
    lost = 6
    events = [(k * GAP_S, "order") for k in range(10)]
    events += [(k * GAP_S + LINK_S, "reply") for k in range(10) if k != lost]
    assert _round_trips(_trace(events)) == pytest.approx([LINK_S] * 8)
