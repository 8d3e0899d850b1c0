"""testbed.channel.mac: token passing and free access against the link's timing model.

Timing on a half-duplex link with intrinsic delay i, propagation p and queue gap g: an order of
airtime a_o sent at s reaches the slave at s + i + a_o + p; the slave answers at once, its
reply leaving once its half-duplex modem has turned round (the queue gap g after the order's
reception), so the reply (airtime a_r) is on the air at the master from s + 2i + a_o + g + 2p
until s + RTT, RTT = 2i + a_o + a_r + g + 2p.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import simpy

from testbed.channel.config import LinkConfig, load_link_config
from testbed.channel.mac import (
    TELEROBOTICS_2018,
    TELEROBOTICS_2019,
    TELEROBOTICS_2021,
    Fixed,
    FromFrameSize,
    IpgPolicy,
    TokenSlave,
    run_periodic_sender,
    run_token_master,
    run_token_slave,
)
from testbed.channel.medium import Medium, Modem
from testbed.channel.trace import EventKind, Trace
from testbed.protocol import FrameDecoder, encode_frame

S100 = load_link_config("s100", ["ber=0"])
I_S = S100.intrinsic_delay_s
GAP_S = S100.queue_gap_s
ORDER = encode_frame(bytes(7))  # 13 B: a move order (REFERENCE §1.6)
REPLY = encode_frame(bytes(54))  # 60 B: state + 40-B image chunk
A_O = 8 * len(ORDER) / S100.bitrate_bps
A_R = 8 * len(REPLY) / S100.bitrate_bps
# positions coincide: no propagation
RTT = 2 * I_S + A_O + A_R + GAP_S


def test_ipg_policies_match_the_telerobotics_versions() -> None:
    # REFERENCE §1.7: 13 B → 2.08 s (2019), 0.594 s (2021); 800 ms fixed (2018).
    assert TELEROBOTICS_2018.gap_for(ORDER) == 0.8
    assert TELEROBOTICS_2019.gap_for(ORDER) == pytest.approx(2.08)
    assert TELEROBOTICS_2021.gap_for(ORDER) == pytest.approx(0.594, abs=5e-4)
    assert TELEROBOTICS_2021.gap_for(bytes(5)) == TELEROBOTICS_2021.gap_for(ORDER)
    assert TELEROBOTICS_2021.gap_for(bytes(60)) == pytest.approx(60 * 8 / 175)
    for bad in (lambda: Fixed(0.0), lambda: FromFrameSize(-1.0), lambda: FromFrameSize(1, -1)):
        with pytest.raises(ValueError):
            bad()


def token_run(
    config: LinkConfig, ipg: IpgPolicy, cycles: int, seed: int = 0
) -> tuple[Trace, Modem, Modem, list[bytes]]:
    env = simpy.Environment()
    trace = Trace()
    medium = Medium(env, config, np.random.default_rng(seed), trace)
    op, rov = medium.attach("op"), medium.attach("rov")
    answered: list[bytes] = []

    def reply(payload: bytes) -> bytes:
        answered.append(payload)
        return REPLY

    def send_order() -> int:
        op.send(ORDER)
        return len(ORDER)

    env.process(run_token_master(env, send_order, ipg, count=cycles))
    env.process(run_token_slave(env, rov, reply, FrameDecoder()))
    env.run()
    return trace, op, rov, answered


def test_round_trip_fits_the_2021_gap() -> None:
    # REFERENCE §1.8: the 13 B + 60 B exchange takes ≈ 0.48 s < 0.594 s.
    round_trip_s = RTT
    assert round_trip_s == pytest.approx(0.478, abs=1e-3)
    assert round_trip_s < TELEROBOTICS_2021.gap_for(ORDER)


@pytest.mark.parametrize("ipg", [TELEROBOTICS_2021, Fixed(1.01 * RTT), Fixed(2.0)])
def test_token_passing_goodput_is_one_reply_per_gap(ipg: IpgPolicy) -> None:
    cycles = 200
    trace, op, _, answered = token_run(S100, ipg, cycles)
    gap = ipg.gap_for(ORDER)
    replies = op.drain()
    assert trace.of_kind(EventKind.COLLIDE, EventKind.DEAF) == []
    assert len(replies) == len(answered) == cycles
    # Every reply is in before the next order: bytes received over N gaps = one reply per gap.
    assert all(d.t_delivered_s == pytest.approx(k * gap + RTT) for k, d in enumerate(replies))
    goodput_bytes_per_s = sum(len(d.data) for d in replies) / (cycles * gap)
    assert goodput_bytes_per_s == pytest.approx(len(REPLY) / gap)
    if ipg is TELEROBOTICS_2021:  # REFERENCE §1.8: one 40-B chunk per cycle ≈ 67 B/s
        assert 40 * len(replies) / (cycles * gap) == pytest.approx(67.0, abs=0.5)


def first_collision_order(gap: float) -> int:
    """Index of the first order that collides when gap < RTT (derivation).

    While gap < RTT, order k is due while reply k-1 is still in flight. If the master is then
    already receiving that reply, half duplex defers the order to the reply's end + g, so the
    orders start at s_k = k·(RTT + g), drifting later than k·gap by (RTT - gap + g) per cycle.
    Order m instead goes out at once (and collides with reply m-1, which is then on its way)
    as soon as m·gap falls before reply m-1 reaches the master, at s_{m-1} + RTT - a_r:
    the first m with m·(RTT - gap) + (m - 1)·g > a_r.
    """
    return math.floor((A_R + GAP_S) / (RTT - gap + GAP_S)) + 1


def test_collision_onset_at_the_round_trip() -> None:
    cycles = 400
    above = Fixed(1.001 * RTT)
    trace, op, _, _ = token_run(S100, above, cycles)
    assert trace.of_kind(EventKind.COLLIDE, EventKind.DEAF) == [] and len(op.drain()) == cycles

    gap = 0.99 * RTT
    m = first_collision_order(gap)
    assert 10 < m < cycles
    trace, _, _, _ = token_run(S100, Fixed(gap), cycles)
    order_start = {e.frame_id: e.t_s for e in trace.of_kind(EventKind.TX_START) if e.src == "op"}
    # two nodes: a lost copy met its receiver transmitting (deaf), never another copy
    assert trace.of_kind(EventKind.COLLIDE) == []
    collided_orders = sorted(
        order_start[e.frame_id] for e in trace.of_kind(EventKind.DEAF) if e.src == "op"
    )
    assert collided_orders, "orders faster than the round trip must collide"
    assert collided_orders[0] == pytest.approx(m * gap)
    # Before order m every order was answered and every reply got through.
    early = [e for e in trace.of_kind(EventKind.DELIVER) if e.src == "rov" and e.t_s < m * gap]
    assert len(early) == m - 1


def test_slave_answers_only_valid_frames() -> None:
    noisy = load_link_config("s100", ["ber=3e-3"])
    trace, _, rov, answered = token_run(noisy, TELEROBOTICS_2021, 400, seed=4)
    clean_orders = rov.counters.rx_delivered
    assert rov.counters.rx_corrupted > 0 and 0 < clean_orders < 400
    assert len(answered) == clean_orders
    assert set(answered) == {bytes(7)}
    assert len([e for e in trace.of_kind(EventKind.TX_START) if e.src == "rov"]) == clean_orders


@pytest.mark.parametrize(
    ("offset_s", "collisions"),
    [(0.0, True), (0.5 * I_S, True), (1.5 * I_S, False), (1.0, False)],
)
def test_free_access_collides_unless_the_second_sender_hears_the_first(
    offset_s: float, collisions: bool
) -> None:
    """Two periodic senders, b starting ``offset_s`` after a. a's frame is on the air at b from
    i to i + airtime: before i, b does not hear it and transmits into it (both lost); after i,
    half duplex defers b until a's frame is over (nothing lost)."""
    env = simpy.Environment()
    medium = Medium(env, S100, np.random.default_rng(0))
    a, b = medium.attach("a"), medium.attach("b")
    n, period = 50, 2.0
    env.process(run_periodic_sender(env, lambda: a.send(bytes(30)), period, count=n))
    env.process(
        run_periodic_sender(env, lambda: b.send(bytes(30)), period, count=n, start_s=offset_s)
    )
    env.run()
    lost = a.counters.rx_collided + b.counters.rx_collided
    assert lost == (2 * n if collisions else 0)
    assert len(a.drain()) + len(b.drain()) == 2 * n - lost


def test_periodic_sender_timing_and_misuse() -> None:
    env = simpy.Environment()
    medium = Medium(env, S100, np.random.default_rng(0))
    a, b = medium.attach("a"), medium.attach("b")
    env.process(run_periodic_sender(env, lambda: a.send(b"x"), 3.0, count=4, start_s=1.0))
    env.run()
    assert [d.t_tx_start_s for d in b.drain()] == [1.0, 4.0, 7.0, 10.0]
    with pytest.raises(ValueError):
        next(run_periodic_sender(env, lambda: a.send(b"x"), 0.0))


def test_token_slave_answers_each_valid_frame_at_once_and_only_those() -> None:
    sent: list[bytes] = []

    def reply(payload: bytes) -> bytes | None:
        return None if payload == b"quiet" else b"re:" + payload

    slave = TokenSlave(reply, sent.append)
    for payload in (b"a", b"quiet", b"b"):
        slave.on_frame(payload)
    assert sent == [b"re:a", b"re:b"]


def test_master_sizes_each_gap_on_the_slot_it_just_used() -> None:
    env = simpy.Environment()
    sizes = iter([13, 60, 5])
    starts: list[float] = []

    def slot() -> int:
        starts.append(env.now)
        return next(sizes)

    env.process(run_token_master(env, slot, TELEROBOTICS_2021, count=3))
    env.run()
    # max(L, 13)·8/175 after each slot: 13 B → 0.594 s, then 60 B → 2.743 s
    assert starts == pytest.approx([0.0, 13 * 8 / 175, 13 * 8 / 175 + 60 * 8 / 175])
