"""testbed.channel.medium: timing, FIFO, duplex, collisions and range against closed forms.

The timing model under test (dccomms_ros, REFERENCE §2.1): a transmission of L bytes starting at
t0 occupies its sender for intrinsic + 8L/R; a receiver at distance d has it on the air from
t0 + intrinsic + prop(d) to t0 + intrinsic + 8L/R + prop(d), prop(d) = fixed + d/speed, and gets it
at the end. Queued transmissions start ``queue_gap_s`` after the previous one ends.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pytest
import simpy

from testbed.channel.config import LinkConfig, Propagation, load_link_config
from testbed.channel.delivery import Delivery
from testbed.channel.medium import Medium, Modem, Position
from testbed.channel.trace import EventKind, Trace
from testbed.protocol import Frame, FrameDecoder, encode_frame

S100 = load_link_config("s100", ["ber=0"])
I_S = S100.intrinsic_delay_s
R_BPS = S100.bitrate_bps
GAP_S = S100.queue_gap_s


def airtime(n_bytes: int, bitrate_bps: float = R_BPS) -> float:
    return 8.0 * n_bytes / bitrate_bps


def build(
    config: LinkConfig,
    names: Sequence[str] = ("a", "b"),
    positions: Sequence[Position | None] | None = None,
    seed: int = 0,
) -> tuple[simpy.Environment, Medium, Trace, list[Modem]]:
    env = simpy.Environment()
    trace = Trace()
    medium = Medium(env, config, np.random.default_rng(seed), trace)
    positions = positions or [None] * len(names)
    modems = [medium.attach(n, p) for n, p in zip(names, positions, strict=True)]
    return env, medium, trace, modems


def send_at(env: simpy.Environment, modem: Modem, t_s: float, data: bytes) -> None:
    def go(_: simpy.Event) -> None:
        modem.send(data)

    env.timeout(t_s).callbacks.append(go)


def at(x_m: float) -> Position:
    return lambda: (x_m, 0.0, 0.0)


# -- latency ---------------------------------------------------------------------------------


@pytest.mark.parametrize("size", [13, 20, 60])
def test_unloaded_latency_is_intrinsic_plus_airtime_plus_propagation(size: int) -> None:
    env, _, _, (a, b) = build(S100, positions=[None, at(12.0)])
    frame = bytes(range(size))
    send_at(env, a, 2.0, frame)
    env.run()
    (d,) = b.drain()
    expected = I_S + airtime(size) + 12.0 / 3.0e8
    assert d.t_delivered_s - 2.0 == pytest.approx(expected, abs=1e-12)
    assert d.t_tx_start_s == 2.0
    assert (d.data, d.src, d.frame_id, d.part, d.parts, d.bit_errors) == (frame, "a", 0, 0, 1, 0)


def test_latency_matches_the_papers_worked_numbers() -> None:
    # REFERENCE §1.8: 20 B → 169.5 ms, 60 B → 337.9 ms at 1.9 kbps + 85.28 ms.
    for size, ms in [(20, 169.5), (60, 337.9)]:
        env, _, _, (a, b) = build(S100)
        a.send(bytes(size))
        env.run()
        assert b.drain()[0].t_delivered_s * 1e3 == pytest.approx(ms, abs=0.05)


def test_propagation_follows_the_position_callables_at_transmit_time() -> None:
    acoustic = LinkConfig(
        bitrate_bps=1000.0, intrinsic_delay_s=0.05, propagation=Propagation(0.01, 1500.0)
    )
    env = simpy.Environment()
    medium = Medium(env, acoustic, np.random.default_rng(0))
    a = medium.attach("a", lambda: (0.0, 0.0, 10.0))
    b = medium.attach("b", lambda: (3.0 * env.now, 4.0 * env.now, 10.0))  # 5 m/s away from a
    send_at(env, a, 20.0, bytes(25))  # distance 100 m at transmit time
    env.run()
    (d,) = b.drain()
    expected = 0.05 + airtime(25, 1000.0) + 0.01 + 100.0 / 1500.0
    assert d.t_delivered_s - 20.0 == pytest.approx(expected, abs=1e-12)


def test_m64_packets_each_take_their_own_airtime() -> None:
    m64 = load_link_config("m64")
    env, _, trace, (a, b) = build(m64, positions=[None, at(150.0)])
    frame = encode_frame(bytes(range(14)))  # 20 B → 3 packets of 8 B, 4 B of padding
    assert len(frame) == 20
    a.send(frame)
    env.run()
    got = b.drain()
    per_packet = m64.intrinsic_delay_s + airtime(8, 64.0)  # 1 s
    prop = 150.0 / 1500.0
    assert [d.part for d in got] == [0, 1, 2] and {d.parts for d in got} == {3}
    for k, d in enumerate(got):
        gap = m64.queue_gap_s
        assert d.t_delivered_s == pytest.approx((k + 1) * per_packet + k * gap + prop, abs=1e-12)
        assert len(d.data) == 8
    stream = b"".join(d.data for d in got)
    assert stream == frame + bytes(4)
    assert [type(e) for e in FrameDecoder().feed(stream)] == [Frame]
    assert [e.size_bytes for e in trace.of_kind(EventKind.ENQUEUE)] == [24]


def test_queued_frames_leave_queue_gap_apart() -> None:
    env, _, trace, (a, b) = build(S100)
    assert a.send(bytes(30)) and a.send(bytes(40))
    env.run()
    first, second = b.drain()
    assert first.t_delivered_s == pytest.approx(I_S + airtime(30), abs=1e-12)
    busy1 = I_S + airtime(30)
    assert second.t_tx_start_s == pytest.approx(busy1 + GAP_S, abs=1e-12)
    assert second.t_delivered_s == pytest.approx(busy1 + GAP_S + I_S + airtime(40), abs=1e-12)
    starts = [e.t_s for e in trace.of_kind(EventKind.TX_START)]
    ends = [e.t_s for e in trace.of_kind(EventKind.TX_END)]
    assert starts[0] == 0.0 and ends[0] == pytest.approx(busy1)
    assert starts[1] == pytest.approx(busy1 + GAP_S)


# -- buffer ----------------------------------------------------------------------------------


def test_tail_drop_when_the_fifo_would_overflow() -> None:
    config = LinkConfig(bitrate_bps=1000.0, tx_buffer_bytes=100)
    env, _, trace, (a, b) = build(config)
    results = [a.send(bytes(30)) for _ in range(5)]
    # The first leaves the FIFO at once; 30+30+30 = 90 B fit, a fourth queued one would not.
    assert results == [True, True, True, True, False]
    assert a.queued_bytes == 90
    assert a.counters.frames_dropped == 1 and a.counters.frames_offered == 5
    assert not a.send(bytes(101))  # larger than the whole FIFO
    env.run()
    assert len(b.drain()) == 4
    assert [e.frame_id for e in trace.of_kind(EventKind.DROP)] == [4, 5]


@pytest.mark.parametrize("load", [0.95, 1.05])
def test_drops_appear_once_offered_load_exceeds_the_bitrate(load: float) -> None:
    """Frames of 50 B at 1000 bps (0.4 s each, no intrinsic delay or gap) every 0.4/load s.

    Below the bitrate the FIFO never fills. Above it the backlog grows by (load - 1) frames per
    arrival until the 500-B FIFO holds 10 frames; from then on the server is never idle, so by
    the last arrival at (N - 1)·T the frames accepted are the ⌊(N - 1)·T / 0.4 s⌋ + 1 whose
    transmission has started plus the 10 in the FIFO (to within one, by phase): drops = N minus
    that.
    """
    config = LinkConfig(bitrate_bps=1000.0, queue_gap_s=0.0, tx_buffer_bytes=500)
    env, _, _, (a, b) = build(config)
    n, interval = 2000, 0.4 / load
    for k in range(n):
        send_at(env, a, k * interval, bytes(50))
    env.run()
    drops = a.counters.frames_dropped
    if load < 1.0:
        assert drops == 0
        assert len(b.drain()) == n
    else:
        accepted = int((n - 1) * interval / 0.4) + 1 + 10
        assert drops == pytest.approx(n - accepted, abs=1)
        assert len(b.drain()) == n - drops


# -- duplex and collisions -------------------------------------------------------------------


@pytest.mark.parametrize("duplex", ["half", "full"])
def test_simultaneous_sends(duplex: str) -> None:
    config = load_link_config("s100", ["ber=0", f"duplex={duplex}"])
    env, _, _, (a, b) = build(config)
    a.send(bytes(20))
    b.send(bytes(30))
    env.run()
    if duplex == "half":  # each is transmitting while the other's frame arrives
        assert a.drain() == [] and b.drain() == []
        assert a.counters.rx_collided == 1 and b.counters.rx_collided == 1
    else:
        assert [len(d.data) for d in a.drain()] == [30]
        assert [len(d.data) for d in b.drain()] == [20]


@pytest.mark.parametrize("duplex", ["half", "full"])
def test_intrinsic_delay_counts_as_transmitting(duplex: str) -> None:
    config = load_link_config("s100", ["ber=0", f"duplex={duplex}"])
    env, _, trace, (a, b) = build(config)
    b.send(bytes(20))  # on the air at a from I_S to I_S + airtime
    send_at(env, a, I_S / 2, bytes(20))  # a is still idle and not yet receiving: it starts
    env.run()
    lost = duplex == "half"
    assert (a.counters.rx_collided, b.counters.rx_collided) == ((1, 1) if lost else (0, 0))
    # two nodes: a copy can only be lost to its receiver's own transmission (deaf), never to
    # another copy, which needs a third sender
    assert (a.counters.rx_deaf, b.counters.rx_deaf) == ((1, 1) if lost else (0, 0))
    assert len(trace.of_kind(EventKind.DEAF)) == (2 if lost else 0)
    assert trace.of_kind(EventKind.COLLIDE) == []


def test_half_duplex_defers_a_send_while_receiving() -> None:
    env, _, trace, (a, b) = build(S100)
    b.send(bytes(60))
    rx_end = I_S + airtime(60)
    send_at(env, a, I_S + airtime(60) / 2, bytes(13))  # mid-reception
    env.run()
    a_start = [e.t_s for e in trace.of_kind(EventKind.TX_START) if e.src == "a"]
    assert a_start == [pytest.approx(rx_end + GAP_S, abs=1e-12)]
    assert len(a.drain()) == 1 and len(b.drain()) == 1
    assert a.counters.rx_collided == b.counters.rx_collided == 0


def test_full_duplex_does_not_defer() -> None:
    config = load_link_config("s100", ["ber=0", "duplex=full"])
    env, _, trace, (a, b) = build(config)
    b.send(bytes(60))
    t_send = I_S + airtime(60) / 2
    send_at(env, a, t_send, bytes(13))
    env.run()
    assert [e.t_s for e in trace.of_kind(EventKind.TX_START) if e.src == "a"] == [t_send]
    assert len(a.drain()) == 1 and len(b.drain()) == 1


@pytest.mark.parametrize(
    ("offset_airtimes", "collide"), [(0.0, True), (0.5, True), (0.99, True), (1.01, False)]
)
def test_overlapping_receptions_destroy_all(offset_airtimes: float, collide: bool) -> None:
    """Receptions at c last one airtime each; they overlap iff the starts differ by less."""
    config = load_link_config("s100", ["ber=0", "duplex=full"])
    env, _, trace, (a, b, c) = build(config, names=("a", "b", "c"))
    a.send(bytes(40))
    send_at(env, b, offset_airtimes * airtime(40), bytes(40))
    env.run()
    at_c = c.drain()
    if collide:
        assert at_c == [] and c.counters.rx_collided == 2
        assert c.counters.rx_deaf == 0  # lost to each other, c never transmitted
        assert {e.src for e in trace.of_kind(EventKind.COLLIDE)} == {"a", "b"}
    else:
        assert [d.src for d in at_c] == ["a", "b"]
    # a and b each hear the other alone (full duplex): never collided.
    assert len(a.drain()) == len(b.drain()) == 1


def test_a_copy_overlapping_another_and_the_receivers_transmission_is_a_collision() -> None:
    """Half duplex, three nodes: c starts sending while a's copy is arriving (deaf), then b's
    copy overlaps a's: a's copy was lost to another copy as well, so it counts as a collision,
    not deafness; b's, overlapping both, too."""
    env, _, trace, (a, b, c) = build(S100, names=("a", "b", "c"))
    a.send(bytes(40))
    send_at(env, c, I_S + 0.2 * airtime(40), bytes(13))  # c deaf to a's copy from here
    send_at(env, b, 0.5 * airtime(40), bytes(40))  # and b's overlaps a's at c
    env.run()
    assert c.counters.rx_collided == 2 and c.counters.rx_deaf == 0
    at_c = [e.kind for e in trace.in_time_order() if e.dst == "c" and e.kind != EventKind.TX_END]
    assert at_c == [EventKind.COLLIDE, EventKind.COLLIDE]


def test_a_third_overlapping_frame_destroys_the_whole_chain() -> None:
    config = load_link_config("s100", ["ber=0", "duplex=full"])
    env, _, _, (a, b, c, d) = build(config, names=("a", "b", "c", "d"))
    a.send(bytes(40))
    send_at(env, b, 0.9 * airtime(40), bytes(40))  # overlaps a's at d
    send_at(env, c, 1.8 * airtime(40), bytes(40))  # overlaps b's only
    env.run()
    assert d.drain() == [] and d.counters.rx_collided == 3


# -- range and broadcast ---------------------------------------------------------------------


def test_range_cut_off() -> None:
    env, _, trace, (a, near, far) = build(
        S100, names=("a", "near", "far"), positions=[None, at(14.9), at(15.1)]
    )
    a.send(bytes(20))
    env.run()
    assert len(near.drain()) == 1
    assert far.drain() == [] and far.counters.rx_out_of_range == 1
    (event,) = trace.of_kind(EventKind.OUT_OF_RANGE)
    assert (event.src, event.dst, event.t_s) == ("a", "far", 0.0)


def test_out_of_range_nodes_do_not_interfere() -> None:
    env, _, _, (a, b, c) = build(
        S100, names=("a", "b", "c"), positions=[at(0.0), at(10.0), at(30.0)]
    )
    a.send(bytes(20))
    c.send(bytes(20))  # 20 m from b, 30 m from a: heard by nobody
    env.run()
    assert [d.src for d in b.drain()] == ["a"]
    assert a.drain() == [] and c.drain() == []


def test_broadcast_copies_get_independent_errors() -> None:
    config = load_link_config("s100", ["ber=0.05"])
    env, _, _, (a, b, c) = build(config, names=("a", "b", "c"))
    a.send(bytes(200))
    env.run()
    (db,), (dc,) = b.drain(), c.drain()
    assert db.bit_errors > 0 and dc.bit_errors > 0 and db.data != dc.data
    for d in (db, dc):  # bit_errors is the true number of flipped bits
        assert sum(bin(x).count("1") for x in d.data) == d.bit_errors


# -- receiving API and trace -----------------------------------------------------------------


def test_wait_drain_and_on_receive() -> None:
    env, _, _, (a, b, c) = build(S100, names=("a", "b", "c"))
    woken: list[tuple[float, list[Delivery]]] = []

    def reader() -> simpy.events.ProcessGenerator:
        while True:
            yield b.wait()
            woken.append((env.now, b.drain()))

    env.process(reader())
    seen: list[Delivery] = []
    c.on_receive = seen.append
    a.send(b"one")
    a.send(b"two")
    env.run()
    assert [[d.data for d in batch] for _, batch in woken] == [[b"one"], [b"two"]]
    assert [t for t, _ in woken] == [batch[0].t_delivered_s for _, batch in woken]
    assert [d.data for d in seen] == [b"one", b"two"] and c.drain() == []


def test_wait_fires_at_once_when_the_inbox_is_not_empty() -> None:
    env, _, _, (a, b) = build(S100)
    pending = b.wait()
    assert not pending.triggered
    a.send(b"x")
    env.run()
    assert pending.triggered
    assert b.wait().triggered  # the delivery is still in the inbox
    assert [d.data for d in b.drain()] == [b"x"]
    assert not b.wait().triggered


def test_every_copy_ends_in_exactly_one_terminal_event() -> None:
    config = load_link_config("s100", ["ber=2e-3"])
    env, _, trace, modems = build(
        config, names=("a", "b", "c"), positions=[at(0.0), at(5.0), at(16.0)]
    )
    rng = np.random.default_rng(1)
    for k in range(300):
        send_at(env, modems[k % 3], float(rng.uniform(0, 100)), bytes(int(rng.integers(5, 80))))
    env.run()
    starts = trace.of_kind(EventKind.TX_START)
    terminal = trace.of_kind(
        EventKind.DELIVER,
        EventKind.CORRUPT,
        EventKind.COLLIDE,
        EventKind.DEAF,
        EventKind.OUT_OF_RANGE,
    )
    assert len(terminal) == 2 * len(starts)  # one copy per other node
    assert {e.kind for e in terminal} == {
        EventKind.DELIVER,
        EventKind.CORRUPT,
        EventKind.COLLIDE,
        EventKind.DEAF,
        EventKind.OUT_OF_RANGE,
    }
    deaf = sum(m.counters.rx_deaf for m in modems)
    assert len(trace.of_kind(EventKind.DEAF)) == deaf
    assert len(starts) + len(trace.of_kind(EventKind.DROP)) == 300
    counted = sum(
        m.counters.rx_delivered
        + m.counters.rx_corrupted
        + m.counters.rx_collided
        + m.counters.rx_out_of_range
        for m in modems
    )
    assert counted == len(terminal)
    times = [e.t_s for e in trace.in_time_order()]
    assert times == sorted(times)


def _scenario(seed: int) -> tuple[list[object], list[bytes]]:
    config = load_link_config("s100", ["ber=1e-3", "burst.p_good_to_bad=1e-3", "burst.ber_bad=0.3"])
    env, _, trace, modems = build(config, names=("a", "b", "c"), seed=seed)
    for k in range(200):
        send_at(env, modems[k % 3], 0.37 * k, bytes(range(k % 50 + 10)))
    env.run()
    return list(trace.events), [d.data for m in modems for d in m.drain()]


def test_same_seed_same_run_and_seeds_matter() -> None:
    assert _scenario(7) == _scenario(7)
    assert _scenario(7)[1] != _scenario(8)[1]


def test_local_misuse_raises() -> None:
    _, medium, _, (a, _) = build(S100)
    with pytest.raises(ValueError, match="empty"):
        a.send(b"")
    with pytest.raises(ValueError, match="already attached"):
        medium.attach("a")


# -- outages ---------------------------------------------------------------------------------


def test_outage_loses_every_copy_that_overlaps_the_window_both_ways() -> None:
    """A frame sent at t0 is on the air at the receiver over [t0 + I, t0 + I + 8L/R] (zero
    distance); with an outage over [10, 20) s exactly the copies whose on-air interval overlaps
    the window are lost, in either direction (full duplex, so the directions do not interact)."""
    env, medium, trace, (a, b) = build(load_link_config("s100", ["ber=0", "duplex=full"]))
    medium.add_outage(10.0, 20.0)
    frame = encode_frame(bytes(54))
    on_air_end = I_S + airtime(len(frame))
    starts = [1.0, 9.0, 10.0 - on_air_end + 1e-3, 10.0 - on_air_end - 1e-3, 15.0]
    starts += [20.0 - I_S - 1e-3, 20.0 - I_S + 1e-3, 25.0]
    for t in starts:
        send_at(env, a, t, frame)
        send_at(env, b, t + 0.4, frame)

    def lost(t0: float) -> bool:
        return t0 + I_S < 20.0 and t0 + on_air_end > 10.0

    env.run(40.0)
    expected = sum(lost(t) for t in starts) + sum(lost(t + 0.4) for t in starts)
    assert len(trace.of_kind(EventKind.OUTAGE)) == expected == 6
    assert len(trace.of_kind(EventKind.DELIVER)) == 2 * len(starts) - expected
    assert a.counters.rx_outage + b.counters.rx_outage == expected


def test_outage_window_must_be_ordered() -> None:
    _, medium, _, _ = build(S100)
    with pytest.raises(ValueError, match="outage window"):
        medium.add_outage(5.0, 5.0)
