"""Image transfer state machines: chunking, image CRC, selective repeat and paper-mode streaming.

Independent truth: chunk counts by ceiling division, the CRC by a bit-by-bit reference, round
trips under random loss against the geometric / negative-binomial closed forms (each chunk needs
a geometric number of round trips with success (1 − p_up)(1 − p_down), and a geometric number of
replies with success 1 − p_down), and paper-mode completions against Binomial(M, (1 − p)^n).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from testbed.protocol import (
    DEFAULT_CHUNK_SIZE,
    MAX_CHUNKS,
    AssemblyEvent,
    ImageAssembler,
    ImageSender,
    Mode,
    NoOrder,
    OperatorMessage,
    OutgoingChunk,
    VehicleMessage,
    VehicleState,
    decode_operator_message,
    decode_vehicle_message,
    max_image_bytes,
)
from tests.strategies import crc16_bitwise

Corrupt = Callable[[OutgoingChunk, int], OutgoingChunk]
STATE = VehicleState(True, False, False, False, False, Mode.MANUAL, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def chunks_for(size: int, chunk_bytes: int = DEFAULT_CHUNK_SIZE) -> int:
    return math.ceil((size + 2) / chunk_bytes)


def deliver(assembler: ImageAssembler, out: OutgoingChunk) -> AssemblyEvent:
    return assembler.on_chunk(
        out.first, out.last, out.image_seq_bit, out.cancel, out.index, out.data
    )


@dataclass
class Run:
    """What a simulated exchange did."""

    cycles: int = 0  # orders sent
    replies: int = 0  # replies sent (each carried a chunk)
    completed: list[bytes] = field(default_factory=list)
    events: list[AssemblyEvent] = field(default_factory=list)
    sent: list[OutgoingChunk] = field(default_factory=list)


def exchange(
    sender: ImageSender,
    assembler: ImageAssembler,
    images: list[bytes],
    *,
    rng: np.random.Generator | None = None,
    p_up: float = 0.0,
    p_down: float = 0.0,
    until: Callable[[Run], bool] | None = None,
    max_cycles: int = 100_000,
    corrupt: Corrupt | None = None,
    wire: bool = False,
) -> Run:
    """Token passing: order (lost with p_up) → vehicle reply (lost with p_down) → operator.

    Runs until every image has completed (or ``until`` says so). With ``wire`` the fields go
    through encoded OperatorMessage / VehicleMessage payloads and back.
    """
    queue = deque(images)
    run = Run()
    done = until or (lambda r: len(r.completed) == len(images))
    while not done(run):
        assert run.cycles < max_cycles, "exchange did not finish"
        run.cycles += 1
        seq_bit, cancel, first_missing = assembler.request()
        if rng is not None and rng.random() < p_up:
            continue
        if wire:
            order = OperatorMessage(seq_bit, cancel, first_missing, False, False, NoOrder())
            got = decode_operator_message(order.encode())
            assert isinstance(got, OperatorMessage)
            seq_bit, cancel, first_missing = (
                got.image_seq_bit, got.cancel_image, got.first_missing_chunk
            )  # fmt: skip
        sender.on_request(seq_bit, cancel, first_missing)
        if sender.wants_image and queue:
            sender.load(queue.popleft())
        out = sender.next_chunk()
        assert out is not None
        run.replies += 1
        run.sent.append(out)
        if corrupt is not None:
            out = corrupt(out, run.replies)
        if rng is not None and rng.random() < p_down:
            continue
        if wire:
            reply = VehicleMessage(
                out.first, out.last, STATE, out.image_seq_bit, out.cancel, out.index, out.data
            )
            msg = decode_vehicle_message(reply.encode())
            assert isinstance(msg, VehicleMessage)
            out = OutgoingChunk(
                msg.first_chunk, msg.last_chunk, msg.image_seq_bit, msg.cancel_image,
                msg.chunk_index, msg.chunk,
            )  # fmt: skip
        event = deliver(assembler, out)
        run.events.append(event)
        if event is AssemblyEvent.COMPLETED:
            assert assembler.last_image is not None
            run.completed.append(assembler.last_image)
    return run


def random_images(rng: np.random.Generator, count: int, low: int, high: int) -> list[bytes]:
    return [rng.bytes(int(n)) for n in rng.integers(low, high + 1, size=count)]


# --- chunking and limits ----------------------------------------------------------------------


@pytest.mark.parametrize("chunk_bytes", [1, 2, 39, 40, 41, 150])
def test_max_image_bytes_is_64_chunks_less_the_crc(chunk_bytes: int) -> None:
    assert max_image_bytes(chunk_bytes) == 64 * chunk_bytes - 2
    assert max_image_bytes() == 2558  # REFERENCE §1.5: 64 × 40 B incl. CRC


@pytest.mark.parametrize("chunk_bytes", [0, 151, -1, True, 40.0, "40"])
def test_chunk_bytes_out_of_range_is_local_misuse(chunk_bytes: object) -> None:
    with pytest.raises(ValueError, match="chunk_bytes"):
        ImageSender(chunk_bytes)  # type: ignore[arg-type]  # deliberately wrong types
    with pytest.raises(ValueError, match="chunk_bytes"):
        ImageAssembler(chunk_bytes)  # type: ignore[arg-type]  # deliberately wrong types
    with pytest.raises(ValueError, match="chunk_bytes"):
        max_image_bytes(chunk_bytes)  # type: ignore[arg-type]  # deliberately wrong types


@pytest.mark.parametrize("chunk_bytes", [1, 2, 3, 40, 150])
def test_64_chunk_limit(chunk_bytes: int) -> None:
    sender = ImageSender(chunk_bytes)
    limit = max_image_bytes(chunk_bytes)
    with pytest.raises(ValueError, match="at most"):
        sender.load(bytes(limit + 1))
    assert sender.wants_image
    image = bytes(range(256)) * (limit // 256) + bytes(range(limit % 256))
    sender.load(image)
    assert sender.chunk_count == MAX_CHUNKS
    sender.on_request(False, False, 63)
    out = sender.next_chunk()
    assert out is not None and out.last and out.index == 63
    run = exchange(ImageSender(chunk_bytes), ImageAssembler(chunk_bytes), [image])
    assert run.completed == [image]
    assert run.replies == MAX_CHUNKS


def test_chunks_carry_image_then_big_endian_crc() -> None:
    sender = ImageSender(4)
    image = b"123456789"
    sender.load(image)
    data = b""
    for index in range(sender.chunk_count):
        sender.on_request(False, False, index)
        out = sender.next_chunk()
        assert out is not None
        assert (out.first, out.last, out.index) == (index == 0, index == 2, index)
        data += out.data
    assert data == image + (0x31C3).to_bytes(2, "big")  # the CRC-16/XMODEM check value
    assert crc16_bitwise(data) == 0


def test_load_while_an_image_is_held_is_local_misuse() -> None:
    sender = ImageSender()
    sender.load(b"a")
    with pytest.raises(RuntimeError, match="wants_image"):
        sender.load(b"b")


# --- lossless ---------------------------------------------------------------------------------


@pytest.mark.parametrize("chunk_bytes", [1, 7, 40, 150])
def test_lossless_takes_ceil_n_plus_2_over_chunk_replies(chunk_bytes: int) -> None:
    limit = max_image_bytes(chunk_bytes)
    sizes = sorted({0, 1, chunk_bytes - 2, chunk_bytes - 1, chunk_bytes, 3 * chunk_bytes, limit})
    sizes = [n for n in sizes if 0 <= n <= limit]
    rng = np.random.default_rng(6)
    for size in sizes:
        image = rng.bytes(size)
        run = exchange(ImageSender(chunk_bytes), ImageAssembler(chunk_bytes), [image], wire=True)
        assert run.completed == [image]
        assert run.replies == run.cycles == chunks_for(size, chunk_bytes)


def test_images_follow_each_other_without_a_wasted_cycle_and_the_bit_alternates() -> None:
    rng = np.random.default_rng(1)
    images = random_images(rng, 7, 0, 500)
    sender, assembler = ImageSender(), ImageAssembler()
    run = exchange(sender, assembler, images, wire=True)
    assert run.completed == images
    assert run.replies == sum(chunks_for(len(image)) for image in images)
    firsts = [out.image_seq_bit for out in run.sent if out.first]
    assert firsts == [False, True, False, True, False, True, False]
    counters = assembler.counters
    assert counters.images_completed == 7
    assert counters.bytes_completed == sum(map(len, images))
    assert counters.duplicates == counters.crc_failures == counters.inconsistent == 0
    # The seventh image is acknowledged by the next request, not yet sent.
    assert sender.counters.images_done == 6
    sender.on_request(*assembler.request())
    assert sender.wants_image and sender.counters.images_done == 7


# --- selective repeat under loss --------------------------------------------------------------


def test_selective_repeat_under_loss_matches_the_negative_binomial() -> None:
    rng = np.random.default_rng(20240611)
    p_up, p_down = 0.1, 0.2
    images = random_images(rng, 40, 0, 600)
    n_chunks = sum(chunks_for(len(image)) for image in images)
    run = exchange(ImageSender(), ImageAssembler(), images, rng=rng, p_up=p_up, p_down=p_down)
    assert run.completed == images
    # Every chunk takes a geometric number of round trips and of replies: sums of n_chunks such
    # draws are n_chunks + NegBin(n_chunks, success) failures.
    q_cycle = (1 - p_up) * (1 - p_down)
    low, high = stats.nbinom.interval(0.999, n_chunks, q_cycle)
    assert n_chunks + low <= run.cycles <= n_chunks + high
    low, high = stats.nbinom.interval(0.999, n_chunks, 1 - p_down)
    assert n_chunks + low <= run.replies <= n_chunks + high


def test_sequence_bit_wraps_many_times_under_heavy_loss() -> None:
    rng = np.random.default_rng(3)
    images = random_images(rng, 25, 0, 200)
    assembler = ImageAssembler(16)
    run = exchange(ImageSender(16), assembler, images, rng=rng, p_up=0.4, p_down=0.4)
    assert run.completed == images
    assert assembler.counters.crc_failures == assembler.counters.inconsistent == 0


def test_lost_reply_after_an_acknowledgement_does_not_acknowledge_the_next_image() -> None:
    sender, assembler = ImageSender(), ImageAssembler()
    a, b = b"A" * 50, b"B" * 50
    sender.load(a)
    for _ in range(2):
        sender.on_request(*assembler.request())
        out = sender.next_chunk()
        assert out is not None
        deliver(assembler, out)
    assert assembler.last_image == a and assembler.request() == (True, False, 0)
    sender.on_request(*assembler.request())  # acknowledges A
    assert sender.wants_image
    sender.load(b)
    assert sender.image_seq_bit is True
    lost = sender.next_chunk()  # B0, lost
    assert lost is not None and lost.index == 0
    sender.on_request(*assembler.request())  # the same request again
    assert not sender.wants_image and sender.counters.images_done == 1
    out = sender.next_chunk()
    assert out == lost


# --- paper mode -------------------------------------------------------------------------------


def paper_exchange(
    images: list[bytes], rng: np.random.Generator, p_up: float, p_down: float
) -> tuple[Run, ImageSender, ImageAssembler]:
    sender = ImageSender(selective_repeat=False)
    assembler = ImageAssembler(selective_repeat=False)

    def streamed(_: Run) -> bool:
        return sender.counters.images_done == len(images)

    run = exchange(sender, assembler, images, rng=rng, p_up=p_up, p_down=p_down, until=streamed)
    # One more image's first chunk tells the operator whether the last one lost its tail.
    sender.on_request(*assembler.request())
    sender.load(b"next")
    out = sender.next_chunk()
    assert out is not None and out.first
    deliver(assembler, out)
    return run, sender, assembler


def test_paper_mode_streams_whatever_is_asked() -> None:
    sender = ImageSender(4, selective_repeat=False)
    sender.load(b"0123456789")  # 12 B with the CRC: 3 chunks
    indices = []
    for request in [(False, False, 0), (True, False, 0), (False, False, 63)]:
        sender.on_request(*request)
        out = sender.next_chunk()
        assert out is not None and out.image_seq_bit is False
        indices.append(out.index)
    assert indices == [0, 1, 2]
    assert sender.wants_image and sender.counters.images_done == 1
    sender.load(b"x")
    assert sender.image_seq_bit is True


def test_paper_mode_lossless_completes_everything() -> None:
    rng = np.random.default_rng(8)
    images = random_images(rng, 10, 0, 300)
    run, _, assembler = paper_exchange(images, rng, 0.0, 0.0)
    assert run.completed == images
    assert assembler.counters.spoiled == 0


def test_paper_mode_spoils_at_one_minus_survival_and_selective_repeat_completes_all() -> None:
    rng = np.random.default_rng(77)
    p_up, p_down = 0.1, 0.1
    size, n_chunks, count = 318, 8, 300
    assert chunks_for(size) == n_chunks
    images = [rng.bytes(size) for _ in range(count)]

    run, sender, assembler = paper_exchange(images, rng, p_up, p_down)
    survival = (1 - p_down) ** n_chunks  # lost orders only delay the stream
    low, high = stats.binom.interval(0.999, count, survival)
    completed = len(run.completed)
    assert low <= completed <= high
    assert completed + assembler.counters.spoiled == count
    assert run.replies == count * n_chunks  # one reply per chunk, no repeats
    assert sender.counters.images_loaded == count + 1
    position = 0  # completed images are the sent ones, in order, byte for byte
    for image in run.completed:
        position = images.index(image, position) + 1

    sr = exchange(ImageSender(), ImageAssembler(), images, rng=rng, p_up=p_up, p_down=p_down)
    assert sr.completed == images
    assert count > 1.5 * completed


# --- corruption that passes the frame CRC -----------------------------------------------------


def test_image_crc_catches_a_corrupted_chunk_and_the_image_is_retried() -> None:
    image = bytes(range(200))  # 202 B: 6 chunks
    n_chunks = chunks_for(len(image))

    def flip(out: OutgoingChunk, reply: int) -> OutgoingChunk:
        if reply != 3:
            return out
        data = bytes([out.data[0] ^ 0x10]) + out.data[1:]
        return OutgoingChunk(out.first, out.last, out.image_seq_bit, False, out.index, data)

    assembler = ImageAssembler()
    run = exchange(ImageSender(), assembler, [image], corrupt=flip)
    assert run.completed == [image]
    assert run.replies == 2 * n_chunks
    assert run.events.count(AssemblyEvent.CRC_FAILED) == 1
    assert assembler.counters.crc_failures == 1


def test_a_chunk_of_the_wrong_length_is_dropped_and_asked_again() -> None:
    image = bytes(range(100))  # 3 chunks

    def truncate(out: OutgoingChunk, reply: int) -> OutgoingChunk:
        if reply != 2:
            return out
        return OutgoingChunk(out.first, out.last, out.image_seq_bit, False, 1, out.data[:-1])

    assembler = ImageAssembler()
    run = exchange(ImageSender(), assembler, [image], corrupt=truncate)
    assert run.completed == [image]
    assert run.replies == chunks_for(len(image)) + 1
    assert assembler.counters.inconsistent == 1


def test_stale_chunk_of_an_older_image_with_the_same_bit_is_caught_by_the_image_crc() -> None:
    # Image A (bit F) leaves a chunk in flight; it lands while C (bit F again) is assembled.
    a, b, c = b"a" * 100, b"b" * 30, b"c" * 100
    sender, assembler = ImageSender(), ImageAssembler()
    run = exchange(sender, assembler, [a, b])
    stale = next(out for out in run.sent if out.index == 1 and out.image_seq_bit is False)
    sender.on_request(*assembler.request())
    sender.load(c)
    out = sender.next_chunk()
    assert out is not None and out.image_seq_bit is False
    assert deliver(assembler, out) is AssemblyEvent.PROGRESS
    assert deliver(assembler, stale) is AssemblyEvent.PROGRESS  # same bit, index 1: looks fine
    rest = exchange(sender, assembler, [], until=lambda r: len(r.completed) == 1)
    assert rest.completed == [c]
    assert rest.events[0] is AssemblyEvent.CRC_FAILED
    assert rest.replies == 1 + chunks_for(len(c))


# --- out-of-range requests, cancel ------------------------------------------------------------


def test_request_beyond_the_last_chunk_gets_the_last_chunk() -> None:
    sender = ImageSender()
    sender.load(bytes(100))  # 3 chunks
    for index in (3, 17, 63, 1000):
        sender.on_request(False, False, index)
        out = sender.next_chunk()
        assert out is not None and out.index == 2 and out.last
    assert sender.counters.requests_beyond_end == 4


def test_replies_without_a_fresh_request_continue_with_the_next_chunk() -> None:
    # Hold-channel streaming: the vehicle replies several times to one order.
    sender = ImageSender(4)
    sender.load(bytes(10))  # 12 B with the CRC: 3 chunks
    sender.on_request(False, False, 1)
    outs = [sender.next_chunk() for _ in range(5)]
    assert [out.index for out in outs if out is not None] == [1, 2, 0, 1, 2]


def test_operator_holding_a_longer_image_makes_progress() -> None:
    # The operator holds chunks 0..4 of another image with the bit it expects (say the vehicle
    # rebooted); the vehicle's image has 3 chunks.
    assembler = ImageAssembler(4)
    for index in range(5):
        assert deliver(
            assembler, OutgoingChunk(index == 0, False, False, False, index, b"zzzz")
        ) is (AssemblyEvent.PROGRESS)
    assert assembler.request() == (False, False, 5)
    image = b"fresh!!!"  # 10 B with the CRC: 3 chunks of 4
    sender = ImageSender(4)
    run = exchange(sender, assembler, [image])
    assert run.completed == [image]
    assert sender.counters.requests_beyond_end == 1
    assert run.replies <= 2 * chunks_for(len(image), 4) + 1


def test_cancel_drops_the_image_on_both_sides_and_the_bit_is_kept() -> None:
    a, b = bytes(range(120)), bytes(range(7, 207))
    sender, assembler = ImageSender(), ImageAssembler()
    sender.load(a)
    sender.on_request(*assembler.request())
    out = sender.next_chunk()
    assert out is not None
    deliver(assembler, out)
    assert assembler.prefix() == a[:39]
    assembler.cancel()
    assert assembler.prefix() == b""
    assert assembler.request() == (False, True, 0)
    sender.on_request(*assembler.request())
    assert sender.wants_image and sender.counters.images_cancelled == 1
    sender.load(b)  # loaded at once; the reply is still the cancel notice
    notice = sender.next_chunk()
    assert notice == OutgoingChunk(False, False, False, True, 0, b"")
    # The notice is lost: the repeated cancel drops b too.
    sender.on_request(*assembler.request())
    assert sender.wants_image and sender.counters.images_cancelled == 2
    notice = sender.next_chunk()
    assert notice is not None and notice.cancel
    # A data chunk arriving while cancelling is ignored; the notice ends the cancel.
    stale = OutgoingChunk(False, False, False, False, 1, a[40:80])
    assert deliver(assembler, stale) is AssemblyEvent.IGNORED
    assert deliver(assembler, notice) is AssemblyEvent.CANCELLED
    assert assembler.request() == (False, False, 0)
    run = exchange(sender, assembler, [b])
    assert run.completed == [b]
    assert run.replies == chunks_for(len(b))
    assert assembler.counters.cancelled == 1
    assert sender.counters.cancels_sent == 2


def test_paper_mode_cancel() -> None:
    sender = ImageSender(selective_repeat=False)
    assembler = ImageAssembler(selective_repeat=False)
    sender.load(bytes(100))
    sender.on_request(*assembler.request())
    out = sender.next_chunk()
    assert out is not None and deliver(assembler, out) is AssemblyEvent.PROGRESS
    assembler.cancel()
    sender.on_request(*assembler.request())
    notice = sender.next_chunk()
    assert notice is not None and notice.cancel
    assert deliver(assembler, notice) is AssemblyEvent.CANCELLED
    image = b"after the cancel"
    run = exchange(sender, assembler, [image])
    assert run.completed == [image]
    assert assembler.counters.spoiled == 0


# --- malformed chunks, duplicates, prefix -----------------------------------------------------


@pytest.mark.parametrize(
    ("first", "last", "index", "size"),
    [
        (False, False, 1, 3),  # non-last chunk shorter than the others
        (False, False, 1, 5),  # longer
        (True, False, 1, 4),  # first flag on index 1
        (False, False, 0, 4),  # index 0 without the first flag
        (True, True, 0, 1),  # a whole "image" shorter than its CRC
        (False, True, 1, 5),  # last chunk longer than a chunk
        (False, False, 63, 4),  # a 65th chunk would follow
        (False, False, 64, 4),  # index beyond 6 bits
        (False, True, -1, 4),
    ],
)
def test_malformed_chunks_are_counted_values(
    first: bool, last: bool, index: int, size: int
) -> None:
    assembler = ImageAssembler(4)
    assert assembler.on_chunk(first, last, False, False, index, bytes(size)) is (
        AssemblyEvent.INCONSISTENT
    )
    assert assembler.counters.inconsistent == 1
    assert assembler.request() == (False, False, 0)


def test_duplicates_and_other_bits_and_empty_chunks() -> None:
    assembler = ImageAssembler(4)
    assert assembler.on_chunk(True, False, False, False, 0, b"abcd") is AssemblyEvent.PROGRESS
    assert assembler.on_chunk(True, False, False, False, 0, b"abcd") is AssemblyEvent.DUPLICATE
    assert assembler.on_chunk(False, False, True, False, 1, b"efgh") is AssemblyEvent.IGNORED
    assert assembler.on_chunk(False, False, False, False, 0, b"") is AssemblyEvent.IGNORED
    assert assembler.on_chunk(False, False, True, True, 0, b"") is AssemblyEvent.IGNORED
    # Other bytes at a held index: the vehicle changed image; restart from the new chunk.
    assert assembler.on_chunk(True, False, False, False, 0, b"ABCD") is AssemblyEvent.INCONSISTENT
    assert assembler.prefix() == b"ABC"
    counters = assembler.counters
    assert (counters.duplicates, counters.inconsistent, counters.chunks_received) == (1, 1, 6)


def test_a_last_chunk_shorter_than_chunks_held_beyond_it_restarts_the_image() -> None:
    assembler = ImageAssembler(4)
    for index in (0, 1, 3):
        assembler.on_chunk(index == 0, False, False, False, index, b"wxyz")
    assert assembler.on_chunk(False, True, False, False, 2, b"q") is AssemblyEvent.INCONSISTENT
    assert assembler.request() == (False, False, 0)


def test_prefix_is_always_a_prefix_of_the_image_under_loss() -> None:
    rng = np.random.default_rng(12)
    chunk_bytes = 5
    images = random_images(rng, 30, 0, 60)
    sender, assembler = ImageSender(chunk_bytes), ImageAssembler(chunk_bytes)
    queue = deque(images)
    completed: list[bytes] = []
    longest = [0] * len(images)
    while len(completed) < len(images):
        current = len(completed)
        prefix = assembler.prefix()
        assert images[current].startswith(prefix)
        longest[current] = max(longest[current], len(prefix))
        request = assembler.request()
        if rng.random() < 0.3:
            continue
        sender.on_request(*request)
        if sender.wants_image and queue:
            sender.load(queue.popleft())
        out = sender.next_chunk()
        assert out is not None
        if rng.random() < 0.3:
            continue
        if deliver(assembler, out) is AssemblyEvent.COMPLETED:
            assert assembler.last_image is not None
            completed.append(assembler.last_image)
    assert completed == images
    # Chunks are asked for in order, so before the last one arrives the prefix holds every
    # chunk but the last, less the byte held back.
    expected = [max(0, (chunks_for(len(i), chunk_bytes) - 1) * chunk_bytes - 1) for i in images]
    assert longest == expected


def test_prefix_holds_back_one_byte_until_the_length_is_known() -> None:
    # 7-byte image + CRC = 9 B in chunks of 4: chunk 1 ends with the first CRC byte.
    image = b"abcdefg"
    sender, assembler = ImageSender(4), ImageAssembler(4)
    sender.load(image)
    outs = []
    for index in range(3):
        sender.on_request(False, False, index)
        out = sender.next_chunk()
        assert out is not None
        outs.append(out)
    deliver(assembler, outs[0])
    assert assembler.prefix() == b"abc"
    deliver(assembler, outs[1])
    assert assembler.prefix() == b"abcdefg"  # one held back: here it is the CRC byte
    assert deliver(assembler, outs[2]) is AssemblyEvent.COMPLETED
    assert assembler.prefix() == b""
    # Out of order: last chunk first, then chunk 0; the length is known, nothing held back.
    other = ImageAssembler(4)
    deliver(other, outs[2])
    deliver(other, outs[0])
    assert other.prefix() == b"abcd"


# --- garbage never raises ---------------------------------------------------------------------

request_st = st.tuples(st.booleans(), st.booleans(), st.integers(-10, 300))
chunk_st = st.tuples(
    st.booleans(),
    st.booleans(),
    st.booleans(),
    st.booleans(),
    st.integers(-3, 70),
    st.binary(max_size=12),
)


def check_outgoing(out: OutgoingChunk | None, chunk_bytes: int) -> None:
    if out is None:
        return  # no image held
    assert 0 <= out.index < MAX_CHUNKS
    if out.cancel:
        assert out.data == b""
    else:
        assert 1 <= len(out.data) <= chunk_bytes
        assert out.first == (out.index == 0)


@settings(max_examples=60, deadline=None)
@given(
    ops=st.lists(
        st.one_of(
            st.tuples(st.just("request"), request_st),
            st.tuples(st.just("next"), st.none()),
            st.tuples(st.just("load"), st.binary(max_size=40)),
        ),
        max_size=40,
    ),
    selective_repeat=st.booleans(),
)
def test_sender_never_raises_on_any_request(
    ops: list[tuple[str, object]], selective_repeat: bool
) -> None:
    sender = ImageSender(3, selective_repeat=selective_repeat)
    for kind, arg in ops:
        if kind == "request":
            assert isinstance(arg, tuple)
            sender.on_request(*arg)
        elif kind == "next":
            check_outgoing(sender.next_chunk(), 3)
        elif sender.wants_image:
            assert isinstance(arg, bytes)
            sender.load(arg)
    counters = sender.counters
    assert counters.images_loaded >= counters.images_done + counters.images_cancelled


@settings(max_examples=60, deadline=None)
@given(chunks=st.lists(chunk_st, max_size=40), selective_repeat=st.booleans())
def test_assembler_never_raises_on_any_chunk_stream(
    chunks: list[tuple[bool, bool, bool, bool, int, bytes]], selective_repeat: bool
) -> None:
    assembler = ImageAssembler(4, selective_repeat=selective_repeat)
    for chunk in chunks:
        assert isinstance(assembler.on_chunk(*chunk), AssemblyEvent)
        seq_bit, cancel, first_missing = assembler.request()
        assert isinstance(seq_bit, bool) and isinstance(cancel, bool)
        assert 0 <= first_missing < MAX_CHUNKS
        assert isinstance(assembler.prefix(), bytes)
    assert assembler.counters.chunks_received == len(chunks)


@settings(max_examples=40, deadline=None)
@given(
    requests=st.lists(request_st, max_size=10),
    chunks=st.lists(chunk_st, max_size=20),
    seed=st.integers(0, 2**32 - 1),
)
def test_after_garbage_a_clean_link_delivers_the_next_images(
    requests: list[tuple[bool, bool, int]],
    chunks: list[tuple[bool, bool, bool, bool, int, bytes]],
    seed: int,
) -> None:
    sender, assembler = ImageSender(4), ImageAssembler(4)
    for request in requests:
        sender.on_request(*request)
    for chunk in chunks:
        assembler.on_chunk(*chunk)
    rng = np.random.default_rng(seed)
    images = random_images(rng, 3, 0, 30)
    total = sum(chunks_for(len(image), 4) for image in images)

    # Garbage held by the operator can, once in 2^16, pass the CRC together with the first
    # image's chunks; once that image is settled either way, the next ones arrive clean.
    def arrived(r: Run) -> bool:
        return r.completed[-2:] == images[1:]

    assert arrived(exchange(sender, assembler, images, until=arrived, max_cycles=3 * total + 20))
