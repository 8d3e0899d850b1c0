"""Resynchronisation after a corrupted length byte: what is guaranteed, and how often it fails.

A Monte-Carlo over streams of back-to-back frames with random payloads of the real sizes (7-B
move orders and 54-B replies, i.e. 13-B / 60-B frames with the 3-byte preamble, 11-B / 58-B with
the 1-byte preamble). In each trial the length byte of one frame *k* is replaced by a random
other value and the stream is fed to a :class:`FrameDecoder` (whole, or in random chunks).

What always holds (asserted on every trial):

* the decoder never raises, and every frame it delivers is a byte string that really is in the
  received stream with a matching CRC (it never fabricates);
* frame *k* itself is never delivered (it is always lost);
* every *other* intact frame that is lost lies under the span of a delivered false frame, i.e.
  under a mis-framed candidate whose CRC-16 matched by chance (a collision);
* with :meth:`FrameDecoder.flush` at each packet boundary (as ``LinkPort._receive`` does at the
  end of each transmission), frames in other packets are never lost.

What holds only with high probability: in a back-to-back stream, frames behind *k* are lost at
the rate :func:`derived_rates` computes (about 2^-16 per mis-framed candidate that overhangs
the next start byte, times the frames it covers). The default run checks the measured count
against a binomial bound at 1e-6; the ``slow`` run repeats that with 200,000 trials per case.
Benchmark with figures and a Clopper–Pearson interval: ``benchmarks/test_resync_bench.py``.
"""

from __future__ import annotations

import binascii
import functools
import itertools
import math
from dataclasses import dataclass

import numpy as np
import pytest
from scipy import stats

from testbed.protocol import MAX_PAYLOAD, START_BYTE, Frame, FrameDecoder, encode_frame

ORDER_PAYLOAD = 7
"""Move order payload [B]: a 13-B frame with the 3-byte preamble."""
REPLY_PAYLOAD = 54
"""Reply payload with a 40-B image chunk [B]: a 60-B frame with the 3-byte preamble."""

CASES = [(3, ORDER_PAYLOAD), (3, REPLY_PAYLOAD), (1, ORDER_PAYLOAD), (1, REPLY_PAYLOAD)]
"""(preamble_len, payload length) pairs measured."""

_CASE_IDS = [f"preamble{p}-payload{n}" for p, n in CASES]


def frame_len(preamble_len: int, payload_len: int) -> int:
    """Frame size [B]: preamble, length byte, payload, 2-byte CRC."""
    return preamble_len + 1 + payload_len + 2


# --- the derivation -----------------------------------------------------------------------


def _span_insert(basis: list[int], v: int) -> bool:
    """Add ``v`` to a GF(2) xor-basis of 16-bit vectors (kept reduced); True if it grew."""
    for b in basis:
        v = min(v, v ^ b)
    if v:
        basis.append(v)
        basis.sort(reverse=True)
        return True
    return False


def _in_span(basis: list[int], v: int) -> bool:
    for b in basis:
        v = min(v, v ^ b)
    return v == 0


@functools.cache
def collision_probability(preamble_len: int, payload_len: int, new_length: int) -> float:
    """Exact probability that the mis-framed candidate of a corrupted length byte passes CRC.

    Frame *k* (``payload_len`` bytes, followed back to back by frames of the same size with
    uniformly random payloads) has its length byte changed to ``new_length``, so the candidate
    at its start is ``frame_len(preamble_len, new_length)`` bytes long: inside frame *k* for a
    smaller length, reaching ``new_length - payload_len`` bytes into the frames behind for a
    larger one. CRC-16/XMODEM is linear with a zero initial value, so the candidate passes iff
    ``crc(the intact bytes under it) == crc(the error pattern)``. The left side is affine in the
    random payload bits: the probability is ``2**-rank`` if the right side lies in the affine
    span, else 0. It is 0 when the candidate ends on a frame boundary (an intact frame leaves a
    zero register) and, as this computes, also whenever it ends inside a header or with fewer
    than two random bytes under its last byte; 2^-16 everywhere else.
    """
    if not 0 <= new_length <= MAX_PAYLOAD or new_length == payload_len:
        raise ValueError(f"new_length must differ from {payload_len} and be at most 255")
    flen = frame_len(preamble_len, payload_len)
    cand_len = frame_len(preamble_len, new_length)
    error = bytearray(cand_len)
    error[preamble_len] = payload_len ^ new_length
    target = binascii.crc_hqx(bytes(error), 0)
    frames_touched = math.ceil(cand_len / flen)
    zero_frame = encode_frame(bytes(payload_len), preamble_len)
    c0 = binascii.crc_hqx((zero_frame * frames_touched)[:cand_len], 0)
    basis: list[int] = []
    # Bits of the last (partially covered) frame first: they fill the rank fastest.
    for f in reversed(range(frames_touched)):
        for byte in range(payload_len):
            if f * flen + preamble_len + 1 + byte >= cand_len:
                break
            for bit in range(8):
                payload = bytearray(payload_len)
                payload[byte] = 1 << bit
                diff = bytes(
                    a ^ b
                    for a, b in zip(encode_frame(payload, preamble_len), zero_frame, strict=True)
                )
                window = (bytes(f * flen) + diff + bytes(cand_len))[:cand_len]
                _span_insert(basis, binascii.crc_hqx(window, 0))
                if len(basis) == 16:
                    return 2.0**-16  # the span is everything
    return 2.0 ** -len(basis) if _in_span(basis, target ^ c0) else 0.0


@dataclass(frozen=True)
class Derived:
    """Derived loss rates per corrupted length byte, back-to-back stream, no flush.

    Attributes:
        p_event: probability that at least one intact frame other than *k* is lost.
        lost_per_error: expected number of intact frames lost other than *k*.
        main_event: the part of ``p_event`` due to the mis-framed candidate at frame *k*'s
            start (exact); the rest is false candidates started by 0x55 runs inside frame *k*
            (first-order estimate, 2^-16 each).
        false_per_error: expected number of false frames delivered (never sent, CRC matching
            by chance) from the candidate at frame *k*'s start, either direction (exact).
    """

    p_event: float
    lost_per_error: float
    main_event: float
    false_per_error: float


@functools.cache
def derived_rates(preamble_len: int, payload_len: int) -> Derived:
    """Expected intact-frame loss per corrupted length byte (new value uniform, ≠ old).

    Frame *k* is always lost. Another frame is lost only if a candidate that starts inside
    frame *k* and extends past its end passes CRC (a collision): the candidate at *k*'s start
    with the corrupted length (exact, :func:`collision_probability`), or a later candidate the
    hunt finds at a run of ``preamble_len`` 0x55 bytes inside frame *k* after the failed one
    (first order: 2^-16). A passing candidate that overhangs by ``m`` bytes swallows
    ``ceil(m / frame_len)`` frames. Second-order terms (two collisions) are ignored.
    """
    flen = frame_len(preamble_len, payload_len)
    n_values = MAX_PAYLOAD  # new value uniform over the 255 values other than the old one
    main_event = 0.0
    lost = 0.0
    false = 0.0
    for new in range(MAX_PAYLOAD + 1):
        if new == payload_len:
            continue
        p = collision_probability(preamble_len, payload_len, new) / n_values
        false += p
        if new > payload_len:
            main_event += p
            lost += p * math.ceil((new - payload_len) / flen)
    event = main_event
    p_len55 = 0.0 if payload_len == START_BYTE else 1.0 / n_values

    def p55(q: int) -> float:
        """Probability that byte ``q`` of the stream (0 = frame k's first byte) is 0x55."""
        if q < preamble_len:
            return 1.0
        if q == preamble_len:
            return p_len55
        if q < flen:
            return 1.0 / 256
        return p55(q - flen) if q - flen <= preamble_len else 1.0 / 256

    for j in range(1, flen):
        p_start = math.prod(p55(j + t) for t in range(preamble_len))
        if p_start == 0.0:
            continue
        q = j + preamble_len  # the false candidate's length byte
        if q >= flen and q - flen < preamble_len:
            lengths = {START_BYTE: 1.0}
        elif q - flen == preamble_len:
            lengths = {payload_len: 1.0}
        else:
            lengths = {v: 1.0 / 256 for v in range(256)}
        for value, p_value in lengths.items():
            m = j + frame_len(preamble_len, value) - flen
            if m > 0:
                p = p_start * p_value * 2.0**-16
                event += p
                lost += p * math.ceil(m / flen)
    return Derived(event, lost, main_event, false)


# --- the measurement ----------------------------------------------------------------------


@dataclass
class Tally:
    """Monte-Carlo counts.

    Attributes:
        trials: corrupted length bytes tried.
        events: trials in which at least one intact frame other than *k* was lost.
        lost: intact frames lost other than *k*.
        false_frames: frames delivered that were never sent (CRC collisions).
        unexplained: lost intact frames not covered by a delivered false frame (must be 0).
        fabricated: delivered frames whose bytes are not in the stream (must be 0).
        corrupted_delivered: trials where frame *k*'s payload was delivered (must be 0).
        cross_packet: intact frames lost in another packet than *k*'s (must be 0 with flushes).
    """

    trials: int = 0
    events: int = 0
    lost: int = 0
    false_frames: int = 0
    unexplained: int = 0
    fabricated: int = 0
    corrupted_delivered: int = 0
    cross_packet: int = 0


def run_trials(
    rng: np.random.Generator,
    trials: int,
    preamble_len: int,
    payload_len: int,
    *,
    chunked: bool = False,
    frames_per_packet: int | None = None,
) -> Tally:
    """Corrupt one length byte per trial and count what the decoder loses.

    Args:
        rng: the random source (seeded by the caller).
        trials: number of streams.
        preamble_len: 1 or 3.
        payload_len: payload of every frame [B].
        chunked: feed each packet in random chunks instead of whole.
        frames_per_packet: ``None``: the whole stream is one packet (back-to-back frames on a
            modem's byte stream). Otherwise the stream is cut at frame boundaries into packets
            of this many frames (the first one shorter by a random amount) and the decoder is
            flushed after each packet, as the simulated link does.
    """
    flen = frame_len(preamble_len, payload_len)
    # Enough frames behind k to hold the longest candidate (length byte 255).
    tail = math.ceil((MAX_PAYLOAD - payload_len) / flen) + 1
    tally = Tally()
    for _ in range(trials):
        lead = int(rng.integers(0, 3))
        n = lead + 1 + tail
        payloads = [rng.bytes(payload_len) for _ in range(n)]
        k = lead
        stream = bytearray(b"".join(encode_frame(p, preamble_len) for p in payloads))
        new = int(rng.integers(0, MAX_PAYLOAD))
        stream[k * flen + preamble_len] = new + (new >= payload_len)
        if frames_per_packet is None:
            bounds = [0, n]
        else:
            first = int(rng.integers(1, frames_per_packet + 1))
            bounds = [0, *range(first, n, frames_per_packet), n]
        packet_of = np.searchsorted(np.asarray(bounds), np.arange(n), side="right") - 1

        decoder = FrameDecoder(preamble_len)
        delivered: list[bytes] = []
        for a, b in itertools.pairwise(bounds):
            data = bytes(stream[a * flen : b * flen])
            if chunked:
                cuts = np.sort(rng.integers(0, len(data) + 1, size=int(rng.integers(1, 8))))
                pieces = [data[x:y] for x, y in zip([0, *cuts], [*cuts, len(data)], strict=True)]
            else:
                pieces = [data]
            events = [e for piece in pieces for e in decoder.feed(piece)]
            events += decoder.flush()
            delivered += [e.payload for e in events if isinstance(e, Frame)]

        tally.trials += 1
        sent = {p: j for j, p in enumerate(payloads)}
        got = set(delivered)
        if payloads[k] in got:
            tally.corrupted_delivered += 1
        spans = []
        raw = bytes(stream)
        for p in delivered:
            if p in sent:
                continue
            tally.false_frames += 1
            wire = encode_frame(p, preamble_len)
            start = raw.find(wire)
            if start < 0:
                tally.fabricated += 1
            else:
                spans.append((start, start + len(wire)))
        lost = [j for j in range(n) if j != k and payloads[j] not in got]
        if lost:
            tally.events += 1
            tally.lost += len(lost)
        for j in lost:
            if not any(s <= j * flen < e for s, e in spans):
                tally.unexplained += 1
            if packet_of[j] != packet_of[k]:
                tally.cross_packet += 1
    return tally


def assert_invariants(tally: Tally) -> None:
    """What holds on every trial, collision or not."""
    assert tally.fabricated == 0
    assert tally.corrupted_delivered == 0
    assert tally.unexplained == 0
    assert tally.cross_packet == 0


def upper_bound(trials: int, p: float, alpha: float = 1e-6) -> int:
    """Smallest count c with P(X > c) < alpha for X ~ Binomial(trials, p)."""
    return int(stats.binom.isf(alpha, trials, p)) + 1


# --- tests --------------------------------------------------------------------------------


def test_derivation_of_the_main_term() -> None:
    """The exact pass probabilities are 2^-16 except on structural edges, never 2^-8 or 1."""
    for preamble_len, payload_len in CASES:
        flen = frame_len(preamble_len, payload_len)
        probs = {
            new: collision_probability(preamble_len, payload_len, new)
            for new in range(MAX_PAYLOAD + 1)
            if new != payload_len
        }
        assert set(probs.values()) <= {0.0, 2.0**-16}
        for new, p in probs.items():
            if new > payload_len and (new - payload_len) % flen == 0:
                assert p == 0.0  # ends on a frame boundary: the register there is zero
        d = derived_rates(preamble_len, payload_len)
        assert 0 < d.main_event <= d.p_event <= d.lost_per_error


@pytest.mark.parametrize("new_length", [8, 11, 12, 19, 20])
def test_structural_zeros_never_pass(new_length: int) -> None:
    """13-B orders: candidates ending in the next header (8, 11), after its first payload byte
    (12), after its first CRC byte (19) or on its end (20) never pass (2^-8 would give ~16)."""
    assert collision_probability(3, ORDER_PAYLOAD, new_length) == 0.0
    rng = np.random.default_rng(new_length)
    cand_len = frame_len(3, new_length)
    for _ in range(4096):
        stream = bytearray(b"".join(encode_frame(rng.bytes(ORDER_PAYLOAD)) for _ in range(3)))
        stream[3] = new_length
        assert binascii.crc_hqx(bytes(stream[:cand_len]), 0) != 0


@pytest.mark.parametrize(("preamble_len", "payload_len"), CASES, ids=_CASE_IDS)
@pytest.mark.parametrize("chunked", [False, True], ids=["whole", "chunked"])
def test_loss_rate_matches_derivation(preamble_len: int, payload_len: int, chunked: bool) -> None:
    rng = np.random.default_rng([20261201, preamble_len, payload_len, chunked])
    tally = run_trials(rng, 2_500, preamble_len, payload_len, chunked=chunked)
    assert_invariants(tally)
    d = derived_rates(preamble_len, payload_len)
    assert tally.events <= upper_bound(tally.trials, d.p_event)
    assert tally.lost <= tally.events * math.ceil(MAX_PAYLOAD / frame_len(preamble_len, 0))


@pytest.mark.parametrize(("preamble_len", "payload_len"), CASES, ids=_CASE_IDS)
@pytest.mark.parametrize("frames_per_packet", [1, 3])
def test_flush_at_packet_boundary_protects_other_packets(
    preamble_len: int, payload_len: int, frames_per_packet: int
) -> None:
    """One frame per transmission (the simulated link): nothing but frame k is ever lost."""
    rng = np.random.default_rng([20261202, preamble_len, payload_len, frames_per_packet])
    tally = run_trials(
        rng, 400, preamble_len, payload_len, chunked=True, frames_per_packet=frames_per_packet
    )
    assert_invariants(tally)
    if frames_per_packet == 1:
        assert tally.lost == 0


@pytest.mark.slow
@pytest.mark.parametrize(("preamble_len", "payload_len"), CASES, ids=_CASE_IDS)
def test_loss_rate_matches_derivation_200k(preamble_len: int, payload_len: int) -> None:
    rng = np.random.default_rng([20261203, preamble_len, payload_len])
    tally = run_trials(rng, 200_000, preamble_len, payload_len)
    assert_invariants(tally)
    d = derived_rates(preamble_len, payload_len)
    assert tally.events <= upper_bound(tally.trials, d.p_event)
    assert stats.binom.cdf(tally.events, tally.trials, d.p_event) > 1e-6  # not far too few
