"""Frame codec and stream decoder.

Independent truth: a bit-by-bit CRC and a deliberately naive reference decoder that walks the
whole stream one position at a time (no buffering, no ``find``, no chunking), written straight
from the rules in the framing module docstring.
"""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from testbed.protocol import (
    DEFAULT_PREAMBLE_LEN,
    MAX_PAYLOAD,
    START_BYTE,
    CorruptFrame,
    CorruptReason,
    Frame,
    FrameDecoder,
    MalformedPayload,
    decode_operator_message,
    decode_vehicle_message,
    encode_frame,
    frame_overhead,
)
from tests.strategies import crc16_bitwise, cut_lists, split_at

Event = Frame | CorruptFrame
MAX_FRAME = 3 + 1 + MAX_PAYLOAD + 2


def reference_decode(
    stream: bytes, preamble_len: int = 3, max_payload: int = 255, max_buffer: int = 4096
) -> tuple[list[Event], int]:
    """Events and garbage count for the whole ``stream`` followed by ``close()``."""
    events: list[Event] = []
    garbage = 0
    preamble = bytes([0x55]) * preamble_len
    i, n = 0, len(stream)
    while i < n:
        if stream[i : i + preamble_len] != preamble:
            garbage += 1
            i += 1
            continue
        if i + preamble_len == n:
            events.append(CorruptFrame(CorruptReason.TRUNCATED, n - i))
            break
        length = stream[i + preamble_len]
        size = preamble_len + 1 + length + 2
        if length > max_payload:
            events.append(CorruptFrame(CorruptReason.OVERSIZE, 1))
            i += 1
        elif size > max_buffer:
            events.append(CorruptFrame(CorruptReason.OVERFLOW, 1))
            i += 1
        elif i + size > n:
            events.append(CorruptFrame(CorruptReason.TRUNCATED, n - i))
            break
        elif crc16_bitwise(stream[i : i + size]) == 0:
            events.append(Frame(stream[i + preamble_len + 1 : i + size - 2]))
            i += size
        else:
            events.append(CorruptFrame(CorruptReason.BAD_CRC, 1))
            i += 1
    return events, garbage


def decode_in_chunks(decoder: FrameDecoder, stream: bytes, cuts: list[int]) -> list[Event]:
    """Feed ``stream`` split at ``cuts`` (positions, any order), then close."""
    events: list[Event] = []
    for piece in split_at(stream, cuts):
        events += decoder.feed(piece)
    events += decoder.close()
    return events


def payloads(events: list[Event]) -> list[bytes]:
    return [e.payload for e in events if isinstance(e, Frame)]


def assert_accounting(decoder: FrameDecoder, events: list[Event]) -> None:
    """Every byte fed is in a frame, garbage, a corrupt event's skipped bytes, or pending."""
    overhead = frame_overhead(decoder.preamble_len)
    framed = sum(len(e.payload) + overhead for e in events if isinstance(e, Frame))
    skipped = sum(e.skipped_bytes for e in events if isinstance(e, CorruptFrame))
    assert decoder.bytes_fed == framed + decoder.garbage_bytes + skipped + decoder.pending_bytes
    assert decoder.frames == sum(isinstance(e, Frame) for e in events)
    assert decoder.corrupt == sum(isinstance(e, CorruptFrame) for e in events)


# --- encoding ---------------------------------------------------------------------------------


@pytest.mark.parametrize("preamble_len", [1, 3])
def test_frame_layout_by_hand(preamble_len: int) -> None:
    head = bytes([0x55] * preamble_len + [3])
    expected = head + b"\x0a\x0b\x0c" + crc16_bitwise(head + b"\x0a\x0b\x0c").to_bytes(2, "big")
    assert encode_frame(b"\x0a\x0b\x0c", preamble_len) == expected


def test_crc_covers_the_length_byte() -> None:
    frame = bytearray(encode_frame(b"abc"))
    frame[3] ^= 0x01  # corrupt the length byte only; the payload-only CRC would not notice
    assert crc16_bitwise(bytes(frame[4:-2])) == crc16_bitwise(b"abc")
    assert crc16_bitwise(bytes(frame)) != 0


def test_defaults_and_overhead() -> None:
    assert START_BYTE == 0x55 and MAX_PAYLOAD == 255 and DEFAULT_PREAMBLE_LEN == 3
    assert frame_overhead(3) == 6 and frame_overhead(1) == 4 and frame_overhead() == 6
    assert len(encode_frame(b"")) == 6


@given(st.binary(max_size=255), st.sampled_from([1, 3]))
def test_frame_size_and_residue(payload: bytes, preamble_len: int) -> None:
    frame = encode_frame(payload, preamble_len)
    assert len(frame) == len(payload) + frame_overhead(preamble_len)
    assert frame.startswith(bytes([0x55]) * preamble_len)
    assert frame[preamble_len] == len(payload)
    assert crc16_bitwise(frame) == 0


def test_encode_rejects_local_misuse() -> None:
    with pytest.raises(ValueError, match="255"):
        encode_frame(bytes(256))
    for bad in (0, 2, 4):
        with pytest.raises(ValueError, match="preamble_len"):
            encode_frame(b"x", bad)
        with pytest.raises(ValueError, match="preamble_len"):
            frame_overhead(bad)


def test_decoder_rejects_local_misuse() -> None:
    with pytest.raises(ValueError, match="preamble_len"):
        FrameDecoder(preamble_len=2)
    with pytest.raises(ValueError, match="max_payload"):
        FrameDecoder(max_payload=256)
    with pytest.raises(ValueError, match="max_buffer"):
        FrameDecoder(max_buffer=5)
    assert FrameDecoder(max_buffer=6).max_buffer == 6


# --- clean streams --------------------------------------------------------------------------

no_start_bytes = st.binary(max_size=30).map(lambda g: g.replace(b"U", b""))
payload_lists = st.lists(st.binary(max_size=255), max_size=8)


@given(payload_lists, st.sampled_from([1, 3]), cut_lists(12))
def test_whole_bytewise_and_chunked_give_the_same_frames(
    items: list[bytes], preamble_len: int, cuts: list[int]
) -> None:
    stream = b"".join(encode_frame(p, preamble_len) for p in items)
    whole = FrameDecoder(preamble_len)
    assert whole.feed(stream) + whole.close() == [Frame(p) for p in items]
    bytewise = FrameDecoder(preamble_len)
    events = [e for k in range(len(stream)) for e in bytewise.feed(stream[k : k + 1])]
    assert events + bytewise.close() == [Frame(p) for p in items]
    chunked = FrameDecoder(preamble_len)
    assert decode_in_chunks(chunked, stream, cuts) == [Frame(p) for p in items]
    assert whole.garbage_bytes == bytewise.garbage_bytes == chunked.garbage_bytes == 0


@given(
    st.lists(
        st.tuples(st.binary(max_size=120), no_start_bytes),
        max_size=6,
    ),
    st.sampled_from([1, 3]),
    cut_lists(6),
)
def test_garbage_without_start_bytes_is_counted_not_reported(
    items: list[tuple[bytes, bytes]], preamble_len: int, cuts: list[int]
) -> None:
    stream = b"".join(garbage + encode_frame(p, preamble_len) for p, garbage in items)
    decoder = FrameDecoder(preamble_len)
    assert decode_in_chunks(decoder, stream, cuts) == [Frame(p) for p, _ in items]
    assert decoder.garbage_bytes == sum(len(g) for _, g in items)


@given(
    st.lists(st.tuples(st.binary(max_size=120), st.binary(max_size=30)), min_size=1, max_size=6),
    st.sampled_from([1, 3]),
    cut_lists(6),
)
def test_all_frames_recovered_in_order_through_arbitrary_garbage(
    items: list[tuple[bytes, bytes]], preamble_len: int, cuts: list[int]
) -> None:
    """Garbage may hold start bytes and fake candidates; the idle tail lets them all resolve."""
    idle = bytes(MAX_FRAME)  # the link keeps carrying idle (zero) bytes
    stream = b"".join(g + encode_frame(p, preamble_len) for p, g in items) + idle
    got = iter(payloads(decode_in_chunks(FrameDecoder(preamble_len), stream, cuts)))
    assert all(any(p == q for q in got) for p, _ in items)  # an in-order subsequence


# --- the reference decoder ------------------------------------------------------------------


@st.composite
def damaged_streams(draw: st.DrawFn) -> tuple[bytes, int]:
    preamble_len = draw(st.sampled_from([1, 3]))
    parts = []
    for payload in draw(st.lists(st.binary(max_size=80), max_size=5)):
        parts.append(draw(st.sampled_from([b"", b"U", b"UU", b"UUU", b"\x00U"])))
        parts.append(encode_frame(payload, preamble_len))
    stream = bytearray(b"".join(parts))
    for _ in range(draw(st.integers(0, 3))):
        if stream:
            bit = draw(st.integers(0, 8 * len(stream) - 1))
            stream[bit // 8] ^= 0x80 >> (bit % 8)
    cut = draw(st.integers(0, len(stream)))
    return bytes(stream[:cut] if draw(st.booleans()) else stream), preamble_len


@settings(max_examples=300)
@given(
    damaged_streams(),
    st.sampled_from([255, 60, 10]),
    st.sampled_from([4096, 261, 40, 8]),
    cut_lists(8),
)
def test_matches_reference_decoder(
    damaged: tuple[bytes, int], max_payload: int, max_buffer: int, cuts: list[int]
) -> None:
    stream, preamble_len = damaged
    decoder = FrameDecoder(preamble_len, max_payload, max_buffer)
    events = decode_in_chunks(decoder, stream, cuts)
    assert (events, decoder.garbage_bytes) == reference_decode(
        stream, preamble_len, max_payload, max_buffer
    )
    assert_accounting(decoder, events)


# --- resynchronisation after damage ---------------------------------------------------------


def frame_train(preamble_len: int, count: int = 12) -> list[bytes]:
    """Reply-sized payloads that never contain a start byte (so no fake candidates)."""
    return [bytes([(17 * k + j) % 85 for j in range(54)]) for k in range(count)]


@pytest.mark.parametrize("preamble_len", [1, 3])
@pytest.mark.parametrize("bit", range(8))
def test_flipped_length_byte_loses_only_its_frame(preamble_len: int, bit: int) -> None:
    items = frame_train(preamble_len)
    frames = [bytearray(encode_frame(p, preamble_len)) for p in items]
    frames[1][preamble_len] ^= 1 << bit
    decoder = FrameDecoder(preamble_len)
    events = decode_in_chunks(decoder, b"".join(frames), [])
    assert payloads(events) == items[:1] + items[2:]
    assert CorruptFrame(CorruptReason.BAD_CRC, 1) in events
    assert_accounting(decoder, events)


@pytest.mark.parametrize("preamble_len", [1, 3])
def test_every_single_bit_flip_loses_only_the_damaged_frame(preamble_len: int) -> None:
    items = frame_train(preamble_len, count=8)
    clean = [encode_frame(p, preamble_len) for p in items]
    for bit in range(8 * len(clean[2])):
        damaged = bytearray(clean[2])
        damaged[bit // 8] ^= 0x80 >> (bit % 8)
        stream = b"".join(clean[:2]) + bytes(damaged) + b"".join(clean[3:])
        decoder = FrameDecoder(preamble_len)
        events = decode_in_chunks(decoder, stream, [len(stream) // 3])
        assert payloads(events) == items[:2] + items[3:], f"bit {bit}"
        assert_accounting(decoder, events)


def test_flipped_crc_and_payload_bits_report_bad_crc() -> None:
    items = frame_train(3, count=4)
    for where in (-1, -2, 10):  # both CRC bytes and a payload byte
        frames = [bytearray(encode_frame(p)) for p in items]
        frames[0][where] ^= 0x04
        events = decode_in_chunks(FrameDecoder(), b"".join(frames), [])
        assert events[0] == CorruptFrame(CorruptReason.BAD_CRC, 1)
        assert payloads(events) == items[1:]


def test_bogus_long_length_delays_but_flush_recovers_without_more_input() -> None:
    items = [b"order-1", b"order-2"]
    first = bytearray(encode_frame(b"lost"))
    first[3] = 200  # claims 206 bytes; only ~30 follow
    stream = bytes(first) + b"".join(encode_frame(p) for p in items)
    decoder = FrameDecoder()
    assert decoder.feed(stream) == []  # still waiting for the claimed 206 bytes
    events = decoder.flush()
    assert events == [CorruptFrame(CorruptReason.TRUNCATED, 1), *(Frame(p) for p in items)]
    assert decoder.pending_bytes == 0
    assert_accounting(decoder, events)
    assert decoder.feed(encode_frame(b"next")) == [Frame(b"next")]  # still usable


def test_flush_reports_each_fake_candidate_then_the_real_frame() -> None:
    decoder = FrameDecoder()
    events = decoder.feed(b"UU" + encode_frame(b"x"))  # fake candidates claim 85 B
    assert events == []
    events = decoder.flush()
    assert events == [CorruptFrame(CorruptReason.TRUNCATED, 1)] * 2 + [Frame(b"x")]
    assert decoder.flush() == [] and decoder.close() == []


@pytest.mark.parametrize("preamble_len", [1, 3])
def test_truncated_tail_is_reported_by_close(preamble_len: int) -> None:
    whole = encode_frame(b"complete", preamble_len)
    tail = encode_frame(b"cut short", preamble_len)
    for keep in range(1, len(tail)):
        decoder = FrameDecoder(preamble_len)
        assert decoder.feed(whole + tail[:keep]) == [Frame(b"complete")]
        closed = decoder.close()
        if keep >= preamble_len:
            assert closed == [CorruptFrame(CorruptReason.TRUNCATED, keep)]
            assert decoder.garbage_bytes == 0
        else:  # a partial preamble cannot be told from noise
            assert closed == []
            assert decoder.garbage_bytes == keep
        assert decoder.pending_bytes == 0
        assert decoder.feed(whole) == [Frame(b"complete")]  # usable after close


def test_oversize_claim_resumes_after_the_start_byte() -> None:
    decoder = FrameDecoder(max_payload=40)
    stream = encode_frame(bytes(41)) + encode_frame(bytes(40))
    events = decoder.feed(stream) + decoder.close()
    assert events == [CorruptFrame(CorruptReason.OVERSIZE, 1), Frame(bytes(40))]
    assert decoder.garbage_bytes == len(encode_frame(bytes(41))) - 1


@given(st.binary(min_size=1, max_size=3000), st.integers(6, 80))
def test_buffer_bound_holds_after_every_feed(data: bytes, max_buffer: int) -> None:
    decoder = FrameDecoder(max_buffer=max_buffer)
    events: list[Event] = []
    for k in range(0, len(data), 97):
        events += decoder.feed(data[k : k + 97])
        assert decoder.pending_bytes < max_buffer
    assert_accounting(decoder, events)


def test_one_large_feed_never_holds_more_than_max_buffer() -> None:
    noise = bytes(range(85)) * 12_000  # ~1 MB without a start byte
    decoder = FrameDecoder(max_buffer=64)
    tracemalloc.start()
    try:
        events = decoder.feed(noise)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert events == [] and decoder.garbage_bytes == len(noise)
    assert peak < len(noise) // 10  # consumed in max_buffer slices, never copied whole


def test_frame_longer_than_the_buffer_is_overflow_and_does_not_block() -> None:
    decoder = FrameDecoder(max_buffer=64)
    fits, too_long = encode_frame(bytes(58)), encode_frame(bytes(59))
    assert len(fits) == 64
    events = decoder.feed(too_long + fits) + decoder.close()
    assert events == [CorruptFrame(CorruptReason.OVERFLOW, 1), Frame(bytes(58))]


def test_huge_feed_equals_bytewise_feed_with_small_buffer() -> None:
    rng = np.random.default_rng(7)
    items = [rng.bytes(int(n)) for n in rng.integers(0, 50, size=400)]
    stream = b"".join(rng.bytes(int(rng.integers(0, 8))) + encode_frame(p) for p in items)
    one_shot = FrameDecoder(max_buffer=64)
    events = one_shot.feed(stream)
    assert one_shot.pending_bytes < 64
    bytewise = FrameDecoder(max_buffer=64)
    assert [e for k in range(len(stream)) for e in bytewise.feed(stream[k : k + 1])] == events
    assert events == reference_decode(stream, max_buffer=64)[0]


@given(st.lists(st.binary(max_size=100), max_size=5), st.integers(6, 300))
def test_bytes_bytearray_and_memoryview_input_decode_alike(
    items: list[bytes], max_buffer: int
) -> None:
    stream = b"U" + b"".join(encode_frame(p) for p in items)
    results = []
    for data in (stream, bytearray(stream), memoryview(stream)):
        decoder = FrameDecoder(max_buffer=max_buffer)
        results.append((decoder.feed(data) + decoder.flush(), decoder.garbage_bytes))
    assert results[0] == results[1] == results[2]


def test_counters_count() -> None:
    decoder = FrameDecoder()
    bad = bytearray(encode_frame(b"bad"))
    bad[-1] ^= 1
    decoder.feed(b"noise" + encode_frame(b"a") + bytes(bad) + encode_frame(b"b"))
    assert (decoder.frames, decoder.corrupt) == (2, 1)
    assert decoder.bytes_fed == 5 + 7 + 9 + 7
    assert decoder.garbage_bytes == 5 + len(bad) - 1


# --- fuzz -----------------------------------------------------------------------------------


class Draws:
    """Small ints from a pre-drawn row of a numpy Generator (keeps the fuzz loop cheap)."""

    def __init__(self, row: list[int]) -> None:
        self.row = row
        self.k = 0

    def __call__(self, n: int) -> int:
        value = self.row[self.k % len(self.row)] % n
        self.k += 1
        return value


def fuzz_stream(draw: Draws, pool: bytes, preamble_len: int) -> bytes:
    def noise(n: int) -> bytes:
        at = draw(len(pool) - n)
        return pool[at : at + n]

    kind = draw(4)
    if kind == 0:
        return noise(draw(120))
    if kind == 1:  # noise sprinkled with preambles and length bytes
        return b"".join(noise(draw(20)) + b"U" * draw(5) + bytes([draw(256)]) for _ in range(3))
    stream = bytearray()
    for _ in range(1 + draw(4)):
        if kind == 3:
            stream += noise(draw(10))
        stream += encode_frame(noise(draw(256) if draw(8) == 0 else draw(60)), preamble_len)
    for _ in range(draw(4)):
        op, at = draw(5), draw(len(stream) + 1)
        if op == 0 and stream:  # bit flip
            stream[min(at, len(stream) - 1)] ^= 1 << draw(8)
        elif op == 1:  # insertion
            stream[at:at] = noise(1 + draw(6))
        elif op == 2:  # deletion
            del stream[at : at + 1 + draw(6)]
        elif op == 3:  # duplicated preamble
            stream[at:at] = b"U" * (1 + draw(4))
        else:  # truncation
            del stream[at:]
    return bytes(stream)


def test_fuzz_100k_inputs_never_raise_and_keep_invariants() -> None:
    rng = np.random.default_rng(20240521)
    count = 100_000
    pool = rng.bytes(1 << 16)
    rows = rng.integers(0, 1 << 30, size=(count, 40)).tolist()
    configs = [(p, mp, mb) for p in (1, 3) for mp in (255, 255, 60) for mb in (4096, 4096, 48)]
    frames_seen = 0
    reasons: set[CorruptReason] = set()
    for n, row in enumerate(rows):
        draw = Draws(row)
        preamble_len, max_payload, max_buffer = configs[draw(len(configs))]
        stream = fuzz_stream(draw, pool, preamble_len)
        decoder = FrameDecoder(preamble_len, max_payload, max_buffer)
        cuts = [draw(len(stream) + 1) for _ in range(draw(4))]
        events = decode_in_chunks(decoder, stream, cuts)
        assert decoder.pending_bytes == 0
        assert_accounting(decoder, events)
        for event in events:
            if isinstance(event, Frame):
                frames_seen += 1
                assert len(event.payload) <= max_payload
                assert encode_frame(event.payload, preamble_len) in stream  # CRC checked
                for parsed in (
                    decode_operator_message(event.payload),
                    decode_vehicle_message(event.payload),
                ):
                    assert isinstance(parsed, MalformedPayload) or parsed.encode() == event.payload
            else:
                assert event.skipped_bytes >= 1
                reasons.add(event.reason)
        if n % 25 == 0:
            expected = reference_decode(stream, preamble_len, max_payload, max_buffer)
            assert (events, decoder.garbage_bytes) == expected
    assert frames_seen > count // 4  # the mutated streams still carried plenty of good frames
    assert reasons == set(CorruptReason)  # every rejection path was exercised


def test_packet_end_gives_up_a_candidate_whose_length_byte_was_corrupted() -> None:
    good = encode_frame(b"next order")
    bad = bytearray(encode_frame(b"order"))
    bad[DEFAULT_PREAMBLE_LEN] = 200  # claims 200 B: would swallow what follows
    for packet_end, expected in ((False, []), (True, [Frame(b"next order")])):
        decoder = FrameDecoder()
        events = decoder.feed_packet(bytes(bad) + good, packet_end=packet_end)
        assert [e for e in events if isinstance(e, Frame)] == expected
    # a packet that ends cleanly leaves nothing to give up
    decoder = FrameDecoder()
    assert decoder.feed_packet(good, packet_end=True) == [Frame(b"next order")]
    assert decoder.pending_bytes == 0 and decoder.corrupt == 0
